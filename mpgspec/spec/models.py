"""Pydantic models of the spec language: system, motion primitives (Definition 1) and project.

The models validate structure only; expressions stay text here and are parsed and compiled to
CasADi by later stages. Unknown keys are rejected so a typo never passes silently.
"""
from __future__ import annotations

from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, field_validator, model_validator

ExprText = Union[str, float, int]
"""An expression in the whitelisted grammar (mpgspec.spec.expr) or a number."""


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


# ----------------------------------------------------------------------------- system
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
    interpolation: Literal["linear", "cubic"] = "linear"

    @model_validator(mode="after")
    def _one_form(self):
        if sum(v is not None for v in (self.expr, self.named, self.samples)) != 1:
            raise ValueError("give exactly one of 'expr', 'named' or 'samples' (with 'times')")
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
class OracleConfig(Strict):
    """Safety oracle settings (Definition 4) for all primitives of a project."""

    horizon: float = Field(default=5.0, gt=0, description="T, seconds")
    dt: float = Field(default=0.01, gt=0, description="fixed integration step, seconds")
    method: str = Field(default="rk4", description="verifier backend name")
    accuracy: Literal["low", "medium", "high", "very_high"] = "medium"
    h_tolerance: float = Field(default=0.0, ge=0, description="h >= -tol counts as safe")
    grid: Grid = Grid()


class EdgeRef(Strict):
    from_: str = Field(alias="from")
    to: str


class EdgeWithClass(EdgeRef):
    class_: Literal[1, 2] | None = Field(default=None, alias="class")


class RequireEdge(Strict):
    edge: EdgeWithClass


class ForbidEdge(Strict):
    no_edge: EdgeRef


class PlanRef(Strict):
    from_: str = Field(alias="from")
    to: str
    max_cost: float | None = None
    weight: Literal["duration", "peak_input", "hops"] = "duration"


class RequirePlan(Strict):
    plan: PlanRef


class RequireReachable(Strict):
    reachable_from: str


class RequireSimulation(Strict):
    simulation_safe: Literal["graph", "naive"]
    expect: bool = True


ASSERTION_KEYS = {"edge": RequireEdge, "no_edge": ForbidEdge, "plan": RequirePlan,
                  "reachable_from": RequireReachable, "simulation_safe": RequireSimulation}


def _assertion_kind(v):
    keys = v.keys() if isinstance(v, dict) else [k for k in ASSERTION_KEYS if getattr(v, k, None) is not None]
    return next((k for k in ASSERTION_KEYS if k in keys), None)


Assertion = Annotated[
    Union[tuple(Annotated[m, Tag(k)] for k, m in ASSERTION_KEYS.items())],
    Discriminator(_assertion_kind, custom_error_type="assertion_kind",
                  custom_error_message="an assertion needs one of the keys " + ", ".join(ASSERTION_KEYS)),
]


class GoalCommand(Strict):
    t: float = Field(ge=0)
    goal: str


class Sequence(Strict):
    """A timed sequence of goal primitives (the paper's Table II), run naive and via the graph."""

    start: str
    commands: list[GoalCommand] = Field(min_length=1)
    duration: float = Field(gt=0)

    @field_validator("commands")
    @classmethod
    def _sorted(cls, v):
        if any(b.t < a.t for a, b in zip(v, v[1:])):
            raise ValueError("commands must be in time order")
        return v


class Project(Strict):
    """A system, its primitives, oracle settings and the CI assertions over the resulting graph."""

    project: str
    description: str = ""
    system: Union[str, System]
    primitives: list[Union[str, Primitive]] = Field(min_length=1)
    safe_sets: dict[str, list[SafetyFunction]] = Field(default_factory=dict)
    oracle: OracleConfig = OracleConfig()
    assumptions: dict[
        Literal["setpoint_dynamics", "setpoint_safe", "roa_in_safe_set", "local_stability"],
        Literal["fail", "warn", "off"],
    ] = Field(default_factory=dict, description="what a failed assumption check does (default: fail)")
    assertions: list[Assertion] = Field(default_factory=list)
    sequence: Sequence | None = None
