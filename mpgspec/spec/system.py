"""Spec models of systems: analytic (closed-form dynamics) and rigid-body (URDF robots)."""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Discriminator, Field, Tag, model_validator

from .base import ExprText, Strict


class ControlAffine(Strict):
    """xdot = f(x) + g(x) u, with f a list over states and g a states x inputs matrix."""

    f: list[ExprText]
    g: list[list[ExprText]]


class AnalyticSystem(Strict):
    """A system given by closed-form dynamics over named states, inputs and parameters."""

    kind: Literal["analytic"] = "analytic"
    name: str
    states: list[str] = Field(min_length=1)
    inputs: list[str] = Field(default_factory=list)
    parameters: dict[str, float] = Field(default_factory=dict)
    dynamics: ControlAffine | None = None
    xdot: list[ExprText] | None = Field(default=None, description="xdot(x, u) when not control-affine")
    input_bounds: dict[str, tuple[float, float]] = Field(default_factory=dict)
    wrap: dict[str, float] = Field(
        default_factory=dict, description="states measured modulo a period (e.g. angles: 6.283185)"
    )

    @model_validator(mode="after")
    def _one_dynamics(self):
        if (self.dynamics is None) == (self.xdot is None):
            raise ValueError("give exactly one of 'dynamics' (control-affine f, g) or 'xdot'")
        return self


class BaumgarteGains(Strict):
    """Contact drift stabilisation: J a + Jdot v = -2 alpha J v - beta^2 (foot height)."""

    alpha: float = Field(default=10.0, ge=0)
    beta: float = Field(default=10.0, ge=0)


class RigidBodySystem(Strict):
    """A URDF robot: floating base, actuated joints, point-contact feet (Section IV).

    States are q = [base_x, base_y, base_z, base_qx, base_qy, base_qz, base_qw, joints...] and
    v = [base_vx, base_vy, base_vz, base_wx, base_wy, base_wz, <joint>_dot...] (base twist in
    the base frame, as in pinocchio).
    """

    kind: Literal["rigid_body"]
    name: str
    urdf: str = Field(description="path relative to the spec, or 'share:<path>' inside cmeel.prefix/share")
    floating_base: bool = True
    contacts: list[str] = Field(default_factory=list, description="contact frames (feet)")
    torque_limit: float | list[float] | None = Field(default=None, description="U = [-l, l]^m; URDF efforts if omitted")
    friction: float = Field(default=0.7, gt=0)
    baumgarte: BaumgarteGains = BaumgarteGains()
    contact_events: bool = Field(default=False, description="contact flags in the state: touchdown (with "
                                 "a plastic impact) and lift-off as events; a primitive's contacts are its initial set")
    parameters: dict[str, float] = Field(default_factory=dict)


def _system_kind(v):
    return (v.get("kind", "analytic") if isinstance(v, dict) else getattr(v, "kind", None))


System = Annotated[
    Union[Annotated[AnalyticSystem, Tag("analytic")], Annotated[RigidBodySystem, Tag("rigid_body")]],
    Discriminator(_system_kind, custom_error_type="system_kind",
                  custom_error_message="system.kind must be 'analytic' (default) or 'rigid_body'"),
]


# ----------------------------------------------------------------------------- primitive parts
