"""Spec models of systems: analytic (closed-form dynamics) and rigid-body (URDF robots)."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import AllowInfNan, BeforeValidator, Discriminator, Field, Tag, model_validator

from .base import ExprText, Strict


def _describe(value) -> str:
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    return f"a {'list' if isinstance(value, list) else 'mapping' if isinstance(value, dict) else type(value).__name__}"


def _expr(value):
    """Expression fields: text in the expression grammar or a number; never a boolean or NaN."""
    if isinstance(value, bool):
        raise ValueError(f"{str(value).lower()} is a boolean, not a number; expected a number-valued expression")
    if isinstance(value, float) and math.isnan(value):
        raise ValueError("NaN is not a value; expected a number-valued expression")
    if isinstance(value, (list, dict)) or value is None:
        raise ValueError("expected a number-valued expression (text or a number)")
    return value


def _number(value):
    """Number fields: YAML true/false is not a number (pydantic would read it as 1/0)."""
    if isinstance(value, bool):
        raise ValueError(f"{str(value).lower()} is a boolean, not a number")
    if isinstance(value, float) and math.isnan(value):
        raise ValueError("NaN is not a number here; expected a finite number")
    return value


def _text(value):
    """Text fields: a string, not a list, mapping, number or boolean."""
    if not isinstance(value, str):
        raise ValueError(f"expected text (a string), not {_describe(value)}")
    return value


Expr = Annotated[ExprText, BeforeValidator(_expr)]
"""A number-valued expression (mpgspec.spec.expr) or a number; booleans and NaN are rejected."""
Number = Annotated[float, BeforeValidator(_number), AllowInfNan(False)]
"""A finite number (not a boolean, NaN or infinite)."""
Bound = Annotated[float, BeforeValidator(_number)]
"""A number that may be infinite (.inf, -.inf) but not NaN or a boolean: an input bound."""
Text = Annotated[str, BeforeValidator(_text)]
"""A string field; a list or mapping in its place is reported as such."""


class ControlAffine(Strict):
    """xdot = f(x) + g(x) u, with f a list over states and g a states x inputs matrix."""

    f: list[Expr]
    g: list[list[Expr]]


class AnalyticSystem(Strict):
    """A system given by closed-form dynamics over named states, inputs and parameters."""

    kind: Literal["analytic"] = "analytic"
    name: Text
    states: list[Text] = Field(min_length=1)
    inputs: list[Text] = Field(default_factory=list)
    parameters: dict[str, Number] = Field(default_factory=dict)
    dynamics: ControlAffine | None = None
    xdot: list[Expr] | None = Field(default=None, description="xdot(x, u) when not control-affine")
    input_bounds: dict[str, tuple[Bound, Bound]] = Field(
        default_factory=dict, description="[low, high] per input; .inf / -.inf leave a side unbounded")
    wrap: dict[str, Annotated[Number, Field(gt=0)]] = Field(
        default_factory=dict, description="states measured modulo a period (e.g. angles: 6.283185)"
    )

    @model_validator(mode="after")
    def _one_dynamics(self):
        if (self.dynamics is None) == (self.xdot is None):
            raise ValueError("give exactly one of 'dynamics' (control-affine f, g) or 'xdot'")
        return self


class BaumgarteGains(Strict):
    """Contact drift stabilisation: J a + Jdot v = -2 alpha J v - beta^2 (foot height)."""

    alpha: Number = Field(default=10.0, ge=0)
    beta: Number = Field(default=10.0, ge=0)


class LegSpec(Strict):
    """One leg of a legged robot: the contact frame at its tip (its joints come from the kinematic tree)."""

    foot: Text = Field(description="the leg's foot: one of the system's contacts")


class RigidBodySystem(Strict):
    """A URDF robot: floating base, actuated joints, point-contact feet (Section IV).

    States are q = [base_x, base_y, base_z, base_qx, base_qy, base_qz, base_qw, joints...] and
    v = [base_vx, base_vy, base_vz, base_wx, base_wy, base_wz, <joint>_dot...] (base twist in
    the base frame, as in pinocchio).
    """

    kind: Literal["rigid_body"]
    name: Text
    urdf: Text = Field(description="path relative to the spec, or 'share:<path>' inside cmeel.prefix/share")
    floating_base: bool = True
    contacts: list[Text] = Field(default_factory=list, description="contact frames (feet)")
    legs: dict[Text, LegSpec] | None = Field(
        default=None, description="leg name -> {foot: <contact frame>}; a leg's joints are the actuated joints "
        "on the tree's path from the base to its foot. Default: one leg per contact, named by the frame "
        "without a trailing _foot/_FOOT (FL_foot -> FL, LF_FOOT -> LF)")
    torque_limit: Annotated[Number, Field(gt=0)] | list[Annotated[Number, Field(gt=0)]] | None = Field(
        default=None, description="U = [-l, l]^m; URDF efforts if omitted (a WARN when they look like placeholders)")
    friction: Number = Field(default=0.7, gt=0)
    baumgarte: BaumgarteGains = BaumgarteGains()
    contact_events: bool = Field(default=False, description="contact flags in the state: touchdown (with "
                                 "a plastic impact) and lift-off as events; a primitive's contacts are its initial set")
    parameters: dict[str, Number] = Field(default_factory=dict)


def _system_kind(v):
    return (v.get("kind", "analytic") if isinstance(v, dict) else getattr(v, "kind", None))


System = Annotated[
    Union[Annotated[AnalyticSystem, Tag("analytic")], Annotated[RigidBodySystem, Tag("rigid_body")]],
    Discriminator(_system_kind, custom_error_type="system_kind",
                  custom_error_message="system.kind must be 'analytic' (default) or 'rigid_body'"),
]


# ----------------------------------------------------------------------------- primitive parts
