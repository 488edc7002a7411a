"""Spec models of the built-in controller kinds (compile/laws): expression, PD (eq. 8), LQR and the
ID-QP of the paper's Stand. Each is the `spec_model` of a ControllerKind registered by entry point."""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .base import Strict
from .system import Expr, Number


def rectangular(rows, what: str) -> None:
    """A matrix written as a list of rows: every row as long as the first."""
    if rows and isinstance(rows[0], list) and any(len(r) != len(rows[0]) for r in rows):
        raise ValueError(f"{what}: every row needs the same number of entries; found rows of lengths "
                         f"{[len(r) for r in rows][:10]}")



class MotionProfile(Strict):
    """Cubic motion profile (paper eq. 7) from the output at switch-in to the setpoint over duration."""

    duration: Number = Field(gt=0)


class ExpressionController(Strict):
    """u = k(x, t) written out, one expression per input."""

    type: Literal["expression"]
    u: list[Expr]


class PDController(Strict):
    """u = -Kp (y - y_d) - Kd (ydot - ydot_d) + feedforward, on named outputs y(x) (paper eq. 8)."""

    type: Literal["pd"]
    outputs: list[Expr] = Field(min_length=1, description="y(x); a state name or an expression")
    kp: list[Number]
    kd: list[Number]
    input_map: list[list[Number]] | Literal["jacobian_transpose"] | None = Field(
        default=None,
        description="inputs x outputs matrix B_y, identity when omitted, or 'jacobian_transpose' for the "
                    "task-space law u = J_y^T (-Kp y - Kd ydot) (J_y: d ydot / d(actuated velocities))",
    )
    feedforward: list[Expr] | None = None
    gravity_compensation: bool = Field(
        default=False, description="rigid bodies: add the torques that hold the current pose on the contact feet")
    limit: Annotated[Number, Field(gt=0)] | list[Annotated[Number, Field(gt=0)]] | None = Field(
        default=None, description="the law asks at most this |u| of each input (one number, or one per input): "
                                  "a design margin below the actuators' limit, e.g. a cushion of bounded torque")
    profile: MotionProfile | None = None
    target: list[Number] | None = Field(
        default=None, description="fixed desired outputs y_d (rates 0) instead of y(x*(t)): a regulator whose law "
                                  "does not read the setpoint, so that x* can be the loop's own flow or rest state")

    @property
    def reads_setpoint(self) -> bool:
        """The law reads x*(t) unless it regulates to a fixed target."""
        return self.target is None

    @field_validator("input_map")
    @classmethod
    def _map_rows(cls, v):
        if isinstance(v, list):
            rectangular(v, "input_map")
        return v

    @model_validator(mode="after")
    def _sizes(self):
        n = len(self.outputs)
        if len(self.kp) != n or len(self.kd) != n:
            raise ValueError(f"kp and kd need one gain per output ({n})")
        if self.target is not None and len(self.target) != n:
            raise ValueError(f"target needs one value per output ({n})")
        if self.target is not None and self.profile is not None:
            raise ValueError("a fixed target has no motion profile to follow")
        return self


class LQRController(Strict):
    """u = u* - K (x - x*) with K from the linearisation at a fixed setpoint (continuous ARE)."""

    type: Literal["lqr"]
    Q: list[Number] | list[list[Number]]
    R: list[Number] | list[list[Number]]
    u_eq: list[Expr] | None = Field(default=None, description="equilibrium input; solved when omitted")

    @field_validator("Q", "R")
    @classmethod
    def _weight_rows(cls, v, info):
        rectangular(v, info.field_name)
        return v


class IDQPController(Strict):
    """The ID-QP of the paper's Stand: CoM task with a cubic profile, posture task, friction cone."""

    type: Literal["id_qp"]
    kp: list[Number] = Field(default=[100.0, 100.0, 100.0], min_length=3, max_length=3)
    kd: list[Number] = Field(default=[20.0, 20.0, 20.0], min_length=3, max_length=3)
    profile_duration: Number = Field(default=1.0, gt=0)
    posture_kp: Number = Field(default=50.0, ge=0)
    posture_kd: Number = Field(default=5.0, ge=0)
    posture_weight: Number = Field(default=0.01, ge=0)
    friction: Number | None = Field(default=None, gt=0, description="friction coefficient the contact forces are "
                                    "designed for (the inner pyramid's); omitted: the system's. Below the plant's, "
                                    "it keeps a friction margin where the QP saturates the pyramid")
    f_min: Number = Field(default=0.0, ge=0, description="least normal force of a held foot (N)")
    posture_profile: bool = Field(default=False, description="the posture task follows a cubic profile from the "
                                  "joints at switch-in (at rest) to the setpoint's over profile_duration, as the CoM "
                                  "task does, so that stiff posture gains do not jerk the legs at a switch")
    regularization: Number = Field(default=1e-8, gt=0)
    max_iter: int = Field(default=100, ge=1)
    rate: Number | None = Field(default=None, gt=0, description="control rate (Hz): the QP is solved every "
                                "1/rate seconds and its torques held in between; 1/rate must be a whole number "
                                "of oracle steps. Omitted: solved at the start of every oracle step")
    warm_start: bool = Field(default=True, description="start each solve from the previous solution and its "
                             "active set")
    ki: list[Number] | None = Field(default=None, min_length=3, max_length=3, description="integral gain of the "
                                    "CoM task per axis (1/s^3): the law adds ki times the integral of the CoM's "
                                    "error to the acceleration it asks, so a mass or motor error settles at the "
                                    "setpoint instead of sagging; needs `rate` (the integral advances once per "
                                    "solve and is carried with the held torques). Omitted: none")
    ki_limit: Number = Field(default=3.0, gt=0, description="largest CoM acceleration (m/s^2) the integral adds per "
                             "axis: the integral is clipped there, so it cannot wind up past what a model error "
                             "asks")
