"""Spec model of a project: system, primitives, oracle settings, assumptions, assertions, sequence."""
from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import Discriminator, Field, Tag, field_validator, model_validator

from .base import Strict
from .crosscheck import CrossCheck
from .primitive import Grid, Primitive, SafetyFunction
from .system import Number, System, Text
from .uncertainty import Uncertainty as UncertaintyModel


class OracleConfig(Strict):
    """Safety oracle settings (Definition 4) for all primitives of a project."""

    horizon: Number = Field(default=5.0, gt=0, description="T, seconds (finite)")
    dt: Number = Field(default=0.01, gt=0, description="fixed integration step, seconds (finite)")
    method: Text = Field(default="rk4", description="verifier backend name")
    accuracy: Literal["low", "medium", "high", "very_high"] = "medium"
    h_tolerance: Number = Field(default=0.0, ge=0, description="h >= -tol counts as safe (finite)")
    error: Literal["local", "doubling"] = Field(
        default="local", description="integration error estimate: local (summed per-step estimates) or doubling "
        "(each rollout runs at dt/2 beside one at dt; their difference is its error: about 2x the cost, "
        "far tighter on long rollouts of contracting closed loops)")

    from_roa: int | None = Field(
        default=None, ge=0, le=1000, description="seeded samples of E_A's boundary every row the executor may "
        "switch through is also checked from (it leaves A from anywhere in E_A); a row with a sample not safe is "
        "not taken. Default 8 for rigid bodies, 0 (off) for other systems")

    @model_validator(mode="after")
    def _step_within_horizon(self):
        if self.dt > self.horizon:
            raise ValueError(f"dt ({self.dt:g}) must not exceed the horizon ({self.horizon:g})")
        return self
    grid: Grid = Grid()


class EdgeRef(Strict):
    from_: Text = Field(alias="from")
    to: Text


class EdgeWithClass(EdgeRef):
    class_: Literal[1, 2] | None = Field(default=None, alias="class")
    evidence: Literal["simulated", "certified"] = Field(
        default="simulated", description="least evidence the edge needs: simulated (any) or certified (every "
        "safe cell of the edge proved)")


class RequireEdge(Strict):
    edge: EdgeWithClass


class ForbidEdge(Strict):
    no_edge: EdgeRef


class PlanRef(Strict):
    from_: Text = Field(alias="from")
    to: Text
    max_cost: Number | None = None
    weight: Literal["duration", "peak_input", "hops", "margin"] = "duration"


class RequirePlan(Strict):
    plan: PlanRef


class RequireReachable(Strict):
    reachable_from: Text


class RequireSimulation(Strict):
    simulation_safe: Literal["graph", "naive"]
    expect: bool = True


class RequireConclusive(Strict):
    """At most this many oracle calls may be inconclusive (a margin within its error bound)."""

    max_inconclusive: int = Field(ge=0)


def node_refs(a) -> list[tuple[str, tuple]] | None:
    """The primitive names an edge, no_edge, plan or reachable_from assertion refers to, each with
    its key path inside the assertion; None for assertions that name no primitive."""
    if isinstance(a, (RequireEdge, ForbidEdge)):
        k, ref = _edge_ref(a)
        return [(ref.from_, (k, "from")), (ref.to, (k, "to"))]
    if isinstance(a, RequirePlan):
        return [(a.plan.from_, ("plan", "from")), (a.plan.to, ("plan", "to"))]
    if isinstance(a, RequireReachable):
        return [(a.reachable_from, ("reachable_from",))]
    return None


def _edge_ref(a: RequireEdge | ForbidEdge) -> tuple[str, EdgeRef]:
    """The key (edge or no_edge) of an edge assertion and the edge it names."""
    k = "edge" if isinstance(a, RequireEdge) else "no_edge"
    return k, getattr(a, k)


def asserted_edges(assertions) -> frozenset:
    """(from, to) of every edge and no_edge assertion: the transitions a verdict of the project rests on."""
    refs = (_edge_ref(a)[1] for a in assertions if isinstance(a, (RequireEdge, ForbidEdge)))
    return frozenset((ref.from_, ref.to) for ref in refs)


ASSERTION_KEYS = {"edge": RequireEdge, "no_edge": ForbidEdge, "plan": RequirePlan,
                  "reachable_from": RequireReachable, "simulation_safe": RequireSimulation,
                  "max_inconclusive": RequireConclusive}


def _assertion_kind(v):
    keys = v.keys() if isinstance(v, dict) else [k for k in ASSERTION_KEYS if getattr(v, k, None) is not None]
    return next((k for k in ASSERTION_KEYS if k in keys), None)


Assertion = Annotated[
    Union[tuple(Annotated[m, Tag(k)] for k, m in ASSERTION_KEYS.items())],
    Discriminator(_assertion_kind, custom_error_type="assertion_kind",
                  custom_error_message="an assertion needs one of the keys " + ", ".join(ASSERTION_KEYS)),
]


class GoalCommand(Strict):
    t: Number = Field(ge=0)
    goal: Text
    reference: list[Text] | None = Field(default=None, description="the primitives a reference run goes through "
                                         "for this goal (e.g. a row of the paper's Table II), shown beside the runs")


class Sequence(Strict):
    """A timed sequence of goal primitives (the paper's Table II), run naive and via the graph."""

    start: Text
    commands: list[GoalCommand] = Field(min_length=1)
    duration: Number = Field(gt=0)
    dt: Number | None = Field(default=None, gt=0, description="step of the sequence runs (s); default: the "
                              "oracle's dt. A run judges h at its samples without error bounds, so a run "
                              "that passes close to a boundary needs a step fine enough to resolve it")
    weight: Literal["duration", "peak_input", "hops", "margin"] = Field(
        default="duration", description="the edge weight of the lookup table the graph run follows (as "
        "`mpgspec plan --weight`): duration, the fewest hops, the least peak input, or margin (1 / each edge's least "
        "normalised safety margin: thin edges avoided)")
    switch: Literal["first", "margin"] = Field(
        default="first", description="when the graph run leaves a primitive along an edge: at the first "
        "verified t_A it meets (first), or only at the t_A whose least normalised safety margin is at least "
        "0.8 of the edge's best (margin: a periodic primitive waits in its cycle for the well-kept switches)")
    reserve: Number | None = Field(
        default=None, gt=0, le=1, description="with it, the graph run also leaves a primitive only through cells "
        "whose peak |u| is at most this share of each input's bound (a torque reserve at every switch it chooses; "
        "a transient hands over at the end of its domain whatever its cell asks)")
    keep: dict[Text, Number] | None = Field(
        default=None, description="with it, the graph run also leaves a primitive only through cells whose least "
        "sampled value of each named safety function family (friction_cone for friction_cone[FR_foot], ...), where "
        "the target has it, is at least the value given in h's units ({friction_cone: 5}: 5 N of friction at every "
        "switch it chooses; a transient hands over at the end of its domain whatever its cell keeps)")

    @field_validator("keep")
    @classmethod
    def _families(cls, v):
        for k, x in (v or {}).items():
            if not k or "[" in k or not math.isfinite(float(x)) or float(x) <= 0:
                raise ValueError(f"keep: {k!r}: {x!r}: expected a safety function family (no index) and a positive "
                                 "finite least value")
        return v

    @field_validator("commands")
    @classmethod
    def _sorted(cls, v):
        if any(b.t < a.t for a, b in zip(v, v[1:])):
            raise ValueError("commands must be in time order")
        return v


class Uncertainty(UncertaintyModel):
    """Uncertainty and disturbances, with assertions on the robust graph (same kinds as the project's)."""

    assertions: list[Assertion] = Field(default_factory=list)


class Baseline(Strict):
    """What `mpgspec verify --baseline DIR` accepts against an earlier report of the project."""

    may_lose: list[EdgeRef] = Field(default_factory=list, description="edges the baseline had that may be "
                                    "lost (an intended change); any other lost edge fails the run")


class Project(Strict):
    """A system, its primitives, oracle settings and the CI assertions over the resulting graph."""

    project: Text
    description: Text = ""
    system: Union[str, System]
    primitives: list[Union[str, Primitive]] = Field(min_length=1)
    safe_sets: dict[str, list[SafetyFunction]] = Field(default_factory=dict)
    oracle: OracleConfig = OracleConfig()
    assumptions: dict[
        Literal["setpoint_dynamics", "setpoint_safe", "roa_in_safe_set", "roa_invariant", "local_stability",
                "roa_size"],
        Literal["fail", "warn", "off"],
    ] = Field(default_factory=dict, description="what a failed assumption check does (default: fail)")
    assertions: list[Assertion] = Field(default_factory=list)
    sequence: Sequence | None = None
    uncertainty: Uncertainty | None = Field(default=None, description="parameter ranges, disturbances and "
                                            "initial-state error the robust graph is checked against")
    baseline: Baseline | None = Field(default=None, description="what `verify --baseline DIR` accepts against "
                                      "an earlier report")
    crosscheck: CrossCheck | None = Field(default=None, description="replay the sequence's runs in an "
                                          "independent simulator (MuJoCo) and compare verdicts and trajectories")
