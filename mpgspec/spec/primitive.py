"""Spec models of a motion primitive (Definition 1): setpoint, control law, safe set, explicit RoA."""
from __future__ import annotations

from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import Field, model_validator

from .base import ExprText, Strict


class PrimitiveClass(str, Enum):
    """Table I of the paper: fixed (box), periodic (circle), transient (diamond)."""

    FIXED = "fixed"
    PERIODIC = "periodic"
    TRANSIENT = "transient"


class Setpoint(Strict):
    """x*(t): constants or expressions of t (`expr`), or tabulated samples (`samples`)."""

    expr: list[ExprText] | None = None
    named: dict[str, ExprText] | None = Field(
        default=None, description="state name -> value; others take the system's default (0; unit quaternion)")
    feet_on_ground: bool = Field(default=False, description="rigid bodies: set base_z so the lowest foot is at z = 0")
    times: list[float] | None = None
    samples: list[list[float]] | None = None
    file: str | None = Field(default=None, description="CSV next to the spec: a header 't,<state>,...' then one "
                                                        "row per sample; unnamed states take the system's default")
    interpolation: Literal["linear", "cubic"] = "linear"

    @model_validator(mode="after")
    def _one_form(self):
        if sum(v is not None for v in (self.expr, self.named, self.samples, self.file)) != 1:
            raise ValueError("give exactly one of 'expr', 'named', 'samples' (with 'times') or 'file'")
        if self.samples is not None:
            if self.times is None or len(self.times) != len(self.samples):
                raise ValueError("'times' must list one time per row of 'samples'")
            if any(b <= a for a, b in zip(self.times, self.times[1:])):
                raise ValueError("'times' must be strictly increasing")
        return self


class MotionProfile(Strict):
    """Cubic motion profile (paper eq. 7) from the output at switch-in to the setpoint over duration."""

    duration: float = Field(gt=0)


class ExpressionController(Strict):
    """u = k(x, t) written out, one expression per input."""

    type: Literal["expression"]
    u: list[ExprText]


class PDController(Strict):
    """u = -Kp (y - y_d) - Kd (ydot - ydot_d) + feedforward, on named outputs y(x) (paper eq. 8)."""

    type: Literal["pd"]
    outputs: list[ExprText] = Field(min_length=1, description="y(x); a state name or an expression")
    kp: list[float]
    kd: list[float]
    input_map: list[list[float]] | Literal["jacobian_transpose"] | None = Field(
        default=None,
        description="inputs x outputs matrix B_y, identity when omitted, or 'jacobian_transpose' for the "
                    "task-space law u = J_y^T (-Kp y - Kd ydot) (J_y: d ydot / d(actuated velocities))",
    )
    feedforward: list[ExprText] | None = None
    gravity_compensation: bool = Field(
        default=False, description="rigid bodies: add the torques that hold the current pose on the contact feet")
    profile: MotionProfile | None = None

    @model_validator(mode="after")
    def _sizes(self):
        n = len(self.outputs)
        if len(self.kp) != n or len(self.kd) != n:
            raise ValueError(f"kp and kd need one gain per output ({n})")
        return self


class LQRController(Strict):
    """u = u* - K (x - x*) with K from the linearisation at a fixed setpoint (continuous ARE)."""

    type: Literal["lqr"]
    Q: list[float] | list[list[float]]
    R: list[float] | list[list[float]]
    u_eq: list[ExprText] | None = Field(default=None, description="equilibrium input; solved when omitted")


class IDQPController(Strict):
    """The ID-QP of the paper's Stand: CoM task with a cubic profile, posture task, friction cone."""

    type: Literal["id_qp"]
    kp: list[float] = Field(default=[100.0, 100.0, 100.0], min_length=3, max_length=3)
    kd: list[float] = Field(default=[20.0, 20.0, 20.0], min_length=3, max_length=3)
    profile_duration: float = Field(default=1.0, gt=0)
    posture_kp: float = Field(default=50.0, ge=0)
    posture_kd: float = Field(default=5.0, ge=0)
    posture_weight: float = Field(default=0.01, ge=0)
    regularization: float = Field(default=1e-8, gt=0)
    max_iter: int = Field(default=100, ge=1)


Controller = Annotated[
    Union[ExpressionController, PDController, LQRController, IDQPController], Field(discriminator="type")
]


class SafetyFunction(Strict):
    """One h(x, t) >= 0 (`h`) or |g(x, t)| <= tol (`eq`), optionally active only for t in `when`."""

    name: str | None = None
    h: ExprText | None = None
    eq: ExprText | None = None
    tol: float = Field(default=1e-3, gt=0)
    when: tuple[float, float] | None = None
    use: str | None = Field(default=None, description="name of a reusable safe-set block of the project")

    @model_validator(mode="after")
    def _one_form(self):
        given = [k for k in ("h", "eq", "use") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of 'h', 'eq' or 'use'")
        if self.use is None and not self.name:
            raise ValueError("a safety function needs a 'name'")
        if self.when is not None and self.when[1] <= self.when[0]:
            raise ValueError("'when' must be [start, end) with end > start")
        return self


class ExplicitRoA(Strict):
    """E = {x : ||W^(1/2) (x - x*(t))|| < radius}; weights give a diagonal W, matrix a full one.

    method 'given' takes the radius as written; lyapunov, sos, sampling (fixed primitives) and
    floquet (periodic) compute it, and `require` demands a level of evidence for it.
    """

    radius: float | None = Field(default=None, gt=0)
    weights: list[float] | None = None
    matrix: list[list[float]] | None = None
    method: str = Field(default="given", description="given | lyapunov | sos | sampling | floquet | a plug-in")
    options: dict[str, Any] = Field(default_factory=dict, description="options of the RoA verifier")
    require: Literal["certified", "empirical", "given"] | None = None

    @model_validator(mode="after")
    def _one_metric(self):
        if self.method == "given" and self.radius is None:
            raise ValueError("give 'radius', or a 'method' that computes it")
        if self.weights is not None and self.matrix is not None:
            raise ValueError("give at most one of 'weights' or 'matrix'")
        if self.weights is not None and any(w < 0 for w in self.weights):
            raise ValueError("weights must be >= 0")
        return self


class ContactPhase(Strict):
    """Feet in contact from the previous phase's end (or 0) until `until` on the primitive's clock."""

    until: float = Field(gt=0)
    feet: list[str]


class Grid(Strict):
    """Number of clock samples used for this primitive as t_A (source) and t_B (target)."""

    t_A: int = Field(default=12, ge=1)
    t_B: int = Field(default=12, ge=1)


class Primitive(Strict):
    """Definition 1: setpoint x*, control law k, safe set C, explicit safe RoA E, plus its class."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    class_: PrimitiveClass = Field(alias="class")
    period: ExprText | None = None
    domain: tuple[ExprText, ExprText] | None = None
    next: str | None = None
    arguments: dict[str, list[float] | dict[str, float]] = Field(
        default_factory=dict,
        description="one node per value: a list of numbers, or labels mapped to numbers (Walk(slow))",
    )
    let: dict[str, ExprText] = Field(default_factory=dict, description="derived constants")
    setpoint: Setpoint
    controller: Controller
    safe_set: list[SafetyFunction] = Field(default_factory=list)
    roa: ExplicitRoA
    contacts: list[str] | None = Field(default=None, description="rigid bodies: feet in contact (default: all)")
    contact_schedule: list[ContactPhase] | None = Field(
        default=None, description="rigid bodies with contact_events: the contact set by the clock (gaits); "
                                  "feet joining a phase touch down with a plastic impact")
    horizon: float | None = Field(default=None, gt=0)
    grid: Grid | None = None
    description: str = ""

    @model_validator(mode="after")
    def _class_fields(self):
        c = self.class_
        if c is PrimitiveClass.PERIODIC and self.period is None:
            raise ValueError("a periodic primitive needs 'period' (T_p)")
        if c is PrimitiveClass.TRANSIENT and (self.domain is None or self.next is None):
            raise ValueError("a transient primitive needs 'domain' [t0, tf] and 'next'")
        if c is not PrimitiveClass.PERIODIC and self.period is not None:
            raise ValueError("'period' is only for periodic primitives")
        if c is not PrimitiveClass.TRANSIENT and (self.domain is not None or self.next is not None):
            raise ValueError("'domain' and 'next' are only for transient primitives")
        if len(self.arguments) > 1:
            raise ValueError("a primitive takes at most one argument")
        return self


# ----------------------------------------------------------------------------- project
