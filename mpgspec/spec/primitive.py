"""Spec models of a motion primitive (Definition 1): setpoint, control law, safe set, explicit RoA."""
from __future__ import annotations

import difflib
from enum import Enum
from typing import Annotated, Any, Literal, Union

from pydantic import BeforeValidator, ConfigDict, Discriminator, Field, Tag, field_validator, model_validator
from pydantic_core import PydanticCustomError

from .base import Strict
from .controllers import rectangular
from .kinds import controller_union
from .system import Expr, Number, Text


class PrimitiveClass(str, Enum):
    """Table I of the paper: fixed (box), periodic (circle), transient (diamond)."""

    FIXED = "fixed"
    PERIODIC = "periodic"
    TRANSIENT = "transient"


class Setpoint(Strict):
    """x*(t): constants or expressions of t (`expr`), or tabulated samples (`samples`)."""

    expr: list[Expr] | None = None
    named: dict[str, Expr] | None = Field(
        default=None, description="state name -> value; others take the system's default (0; unit quaternion)")
    feet_on_ground: bool = Field(default=False, description="rigid bodies: set base_z so the lowest foot is at z = 0")
    times: list[Number] | None = None
    samples: list[list[Number]] | None = None
    file: Text | None = Field(default=None, description="CSV next to the spec: a header 't,<state>,...' then one "
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


Controller = controller_union()
"""The control law k(x, t): the spec model of a registered controller kind (spec/kinds.py)."""


class ContactEvent(str, Enum):
    """Contact events a safe-set window can be anchored on, each at its first time since switch-in
    (Section IV: T_c of Land, T_t of Jump). Detected at step ends, so known to one step."""

    FIRST_TOUCHDOWN = "first_touchdown"  # T_c: a foot out of contact touches the ground
    TAKEOFF = "takeoff"  # T_t: the last foot in contact lifts off, none is left on the ground


def _contact_event(value):
    """An event name; an unknown one is reported with the names there are and the nearest of them."""
    names = [e.value for e in ContactEvent]
    if isinstance(value, str) and value not in names:
        near = difflib.get_close_matches(value, names, n=1, cutoff=0.5)
        raise PydanticCustomError(
            "contact_event", "unknown contact event",
            {"found": repr(value)[:60], "expected": "one of " + ", ".join(names),
             "hint": f"did you mean {near[0]!r}?" if near else ""})
    return value


Event = Annotated[ContactEvent, BeforeValidator(_contact_event)]


class EventWindow(Strict):
    """A window anchored on a contact event E at T_E, its first time since switch-in: `before: E`
    is [0, T_E); `after: E` is [T_E + delay, T_E + delay + for), or from T_E + delay on without
    `for`. Before E happens, `before` windows are active and `after` windows are not."""

    model_config = ConfigDict(json_schema_extra={"oneOf": [{"required": ["before"]}, {"required": ["after"]}]})

    before: Event | None = Field(default=None, description="contact event ending the window: active until it "
                                                            "first happens (first_touchdown | takeoff)")
    after: Event | None = Field(default=None, description="contact event opening the window: active from its "
                                                          "first time on (first_touchdown | takeoff)")
    delay: Number = Field(default=0.0, description="seconds after the event at which an `after` window opens",
                          json_schema_extra={"minimum": 0})
    for_: Number | None = Field(default=None, alias="for", description="length of an `after` window in seconds "
                                "(omitted: to the end of the rollout)", json_schema_extra={"exclusiveMinimum": 0})

    @field_validator("for_")
    @classmethod
    def _positive_length(cls, v):
        if v is not None and v <= 0:
            raise ValueError(f"'for' is the window's length in seconds and must be > 0; got {v:g}")
        return v

    @field_validator("delay")
    @classmethod
    def _later(cls, v):
        if v < 0:
            raise ValueError(f"'delay' must be >= 0: the window opens that long after the event; got {v:g}")
        return v

    @model_validator(mode="after")
    def _one_anchor(self):
        if (self.before is None) == (self.after is None):
            raise ValueError("give exactly one of 'before' or 'after', each naming a contact event")
        if self.before is not None and (self.for_ is not None or self.delay != 0):
            raise ValueError("'for' and 'delay' go with 'after'; a 'before' window ends at the event")
        return self


def _window_kind(v):
    return "event" if isinstance(v, (dict, EventWindow)) else "clock"


Window = Annotated[
    Union[Annotated[tuple[Number, Number], Tag("clock")], Annotated[EventWindow, Tag("event")]],
    Discriminator(_window_kind),
]
"""`when`: a clock window [t0, t1) or a window anchored on a contact event."""


class SafetyFunction(Strict):
    """One h(x, t) >= 0 (`h`) or |g(x, t)| <= tol (`eq`), optionally active only in the window `when`."""

    name: Text | None = None
    h: Expr | None = None
    eq: Expr | None = None
    tol: Number = Field(default=1e-3, gt=0)
    when: Window | None = None
    use: Text | None = Field(default=None, description="name of a reusable safe-set block of the project")

    @model_validator(mode="after")
    def _one_form(self):
        given = [k for k in ("h", "eq", "use") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give exactly one of 'h', 'eq' or 'use'")
        if self.use is None and not self.name:
            raise ValueError("a safety function needs a 'name'")
        if isinstance(self.when, tuple) and self.when[1] <= self.when[0]:
            raise ValueError("'when' must be [start, end) with end > start")
        return self


class NarrowE(Strict):
    """E's radius in the last `window` seconds before each scheduled touchdown (a gait's E(t) narrows there)."""

    window: Number = Field(gt=0, description="seconds before each scheduled touchdown")
    radius: Number = Field(gt=0, description="E's radius there (at most roa.radius)")


class ExplicitRoA(Strict):
    """E = {x : ||W^(1/2) (x - x*(t))|| < radius}; weights give a diagonal W, matrix a full one.

    method 'given' takes the radius as written; lyapunov, sos, sampling (fixed primitives) and
    floquet (periodic) compute it, and `require` demands a level of evidence for it. With
    `before_touchdown` the radius of E(t) is smaller in the last moments before each scheduled
    touchdown, where a landing foot a few millimetres off leaves C, than over the rest of the period.
    """

    radius: Number | None = Field(default=None, gt=0)
    before_touchdown: NarrowE | None = Field(default=None, description="a smaller radius of E(t) in the last "
                                             "`window` seconds before each scheduled touchdown; needs `radius`")
    boundary_samples: int | None = Field(default=None, ge=0, description="samples of E(t_A)'s boundary each switch "
                                         "out of this primitive is checked from; default: the project's "
                                         "oracle.from_roa")
    weights: list[Number] | None = None
    matrix: list[list[Number]] | None = None
    method: Text = Field(default="given", description="given | lyapunov | sos | sampling | floquet | a plug-in")
    options: dict[str, Any] = Field(default_factory=dict, description="options of the RoA verifier")
    require: Literal["certified", "empirical", "given"] | None = None

    @field_validator("matrix")
    @classmethod
    def _matrix_rows(cls, v):
        if v is not None:
            rectangular(v, "matrix")
        return v

    @model_validator(mode="after")
    def _one_metric(self):
        if self.method == "given" and self.radius is None:
            raise ValueError("give 'radius', or a 'method' that computes it")
        if self.before_touchdown is not None and (self.radius is None or self.before_touchdown.radius > self.radius):
            raise ValueError("before_touchdown.radius must be at most 'radius' (give both: E away from the touchdowns "
                             "and just before them)")
        if self.weights is not None and self.matrix is not None:
            raise ValueError("give at most one of 'weights' or 'matrix'")
        if self.weights is not None and any(w < 0 for w in self.weights):
            raise ValueError("weights must be >= 0")
        return self


class ContactPhase(Strict):
    """Feet in contact from the previous phase's end (or 0) until `until` on the primitive's clock."""

    until: Number = Field(gt=0)
    feet: list[Text]


class Grid(Strict):
    """Number of clock samples used for this primitive as t_A (source) and t_B (target)."""

    t_A: int = Field(default=12, ge=1)
    t_B: int = Field(default=12, ge=1)
    phase: Number = Field(default=0.0, ge=0, description="clock of the first sample of a periodic primitive (s): "
                          "the samples are phase + k T / n modulo the period T, so that they can fall where a "
                          "switch is meant to happen (a walk's double support rather than its touchdown instants)")


def node_label(v: float) -> str:
    """The label of the node a numeric argument value makes, as in Swing(2.6)."""
    return f"{v:g}"


class Primitive(Strict):
    """Definition 1: setpoint x*, control law k, safe set C, explicit safe RoA E, plus its class."""

    name: Text = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    class_: PrimitiveClass = Field(alias="class")
    period: Expr | None = None
    domain: tuple[Expr, Expr] | None = None
    next: Text | None = None
    arguments: dict[str, list[Number] | dict[str, Number]] = Field(
        default_factory=dict,
        description="one node per value: a list of numbers, or labels mapped to numbers (Walk(slow))",
    )
    nodes: dict[str, dict[str, Any]] = Field(
        default_factory=dict,
        description="per node (an argument's label, as in Walk(fast)): keys of this primitive that differ for that "
                    "node, e.g. {fast: {controller: {touchdown_height: 0.0007}}}; mappings merge key by key, other "
                    "values replace",
    )
    let: dict[str, Expr] = Field(default_factory=dict, description="derived constants")
    setpoint: Setpoint
    controller: Controller
    safe_set: list[SafetyFunction] = Field(default_factory=list)
    roa: ExplicitRoA
    contacts: list[Text] | None = Field(default=None, description="rigid bodies: feet in contact (default: all)")
    contact_schedule: list[ContactPhase] | None = Field(
        default=None, description="rigid bodies with contact_events: the contact set by the clock (gaits); "
                                  "feet joining a phase touch down with a plastic impact")
    horizon: Number | None = Field(default=None, gt=0)
    grid: Grid | None = None
    description: Text = ""

    @field_validator("nodes", mode="before")
    @classmethod
    def _labels(cls, v):
        """A numeric argument's node is labelled as its name writes it (`2.6:` for Swing(2.6))."""
        if isinstance(v, dict):
            return {(node_label(k) if isinstance(k, (int, float)) and not isinstance(k, bool) else k): e
                    for k, e in v.items()}
        return v

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
        if self.nodes and not self.arguments:
            raise ValueError("'nodes' sets keys per argument value: the primitive needs 'arguments'")
        return self


# ----------------------------------------------------------------------------- project
