"""Names in a project's `uncertainty` block refer to the system and the primitives; located errors."""
from __future__ import annotations

import difflib

from ..errors import SpecError, SpecErrors
from .crosscheck import whole_periods
from .loader import ProjectSpec
from .project import RequireEdge, node_refs


def _hint(word: str, choices) -> str:
    close = difflib.get_close_matches(str(word), sorted(choices), n=2)
    return f"did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


VELOCITY_ERRORS = ("velocity_error_x", "velocity_error_y", "velocity_error_z")
"""Sensing errors of a floating base: the laws read its linear velocity (in the base frame, as the
state holds it) with this error (m/s) added on one axis; the plant and every h keep the true state."""


def latency_steps(spec: ProjectSpec, dt: float) -> int:
    """uncertainty.latency in oracle steps of dt; a latency that is not a whole number of them is a
    located spec error."""
    lat = float(spec.project.uncertainty.latency)
    if not whole_periods(lat, 1.0 / dt):
        raise SpecError("the latency must be a whole number of oracle steps", location=spec.locate(("uncertainty", "latency")),
                        key="uncertainty.latency", expected=f"a multiple of the oracle step {dt:g} s",
                        found=f"{lat:g} s ({lat / dt:.3g} steps)", code="MPG104",
                        hint="round the latency to whole steps, or set the oracle's dt to a divisor of it")
    return int(round(lat / dt))


def rigid_nominal(sys) -> dict[str, float]:
    """The uncertain parameters of a rigid-body system (its spec or compiled) and their nominal values:
    every link's mass and inertia times k, mu, every actuator's torque times k_tau (the
    controllers command the nominal torque) and the errors of the base velocity the laws read."""
    return {"mass_scale": 1.0, "friction": float(sys.friction), "torque_scale": 1.0,
            **{name: 0.0 for name in VELOCITY_ERRORS}}


def _err(errors, message, where, key, code, expected="", found="", hint=""):
    errors.append(SpecError(message, location=where, key=f"uncertainty.{key}" if key else "uncertainty",
                            expected=expected, found=found, hint=hint, code=code))


def check_uncertainty(spec: ProjectSpec) -> None:
    """Raise SpecErrors for unknown parameters, inputs, states and primitives, a nominal value that
    is not the system's, what a system kind does not support and assertions the robust graph cannot
    answer (its kinds but for edge, no_edge, plan and reachable_from; certified evidence)."""
    unc = spec.project.uncertainty
    if unc is None:
        return
    errors: list[SpecError] = []
    loc = lambda *k: spec.locate(("uncertainty", *k))  # noqa: E731
    sys = spec.system
    kind = getattr(sys, "kind", "analytic")
    if kind not in ("analytic", "rigid_body"):
        _err(errors, "uncertainty is supported for analytic and rigid-body systems only", loc(), "", "MPG104",
             "an analytic or a rigid-body system", f"a {kind} system")
        raise SpecErrors(errors)
    rigid = kind == "rigid_body"
    if rigid:
        params = rigid_nominal(sys)
    else:
        params = dict(sys.parameters)
    for name, pr in unc.parameters.items():
        if name not in params:
            _err(errors, "unknown parameter", loc("parameters", name), f"parameters.{name}", "MPG107",
                 "one of " + ", ".join(sorted(params)) if params else "no parameters", repr(str(name)[:60]),
                 _hint(name, params))
            continue
        if pr.nominal is not None and pr.nominal != params[name]:
            _err(errors, "nominal differs from the system's value", loc("parameters", name, "nominal"),
                 f"parameters.{name}.nominal", "MPG104", f"{params[name]:g}", f"{pr.nominal:g}")
        elif not pr.range[0] <= params[name] <= pr.range[1]:
            _err(errors, "the system's value lies outside the range", loc("parameters", name, "range"),
                 f"parameters.{name}.range", "MPG104", f"a range containing {params[name]:g}", f"{list(pr.range)}")
        elif name in VELOCITY_ERRORS and rigid and not getattr(sys, "floating_base", True):
            _err(errors, "a velocity error acts on the floating base's velocity, and the robot's base is fixed",
                 loc("parameters", name), f"parameters.{name}", "MPG108", "a floating_base system",
                 "floating_base: false", "sensing errors of a fixed-base robot are not modelled: leave it out")
        elif pr.range[0] <= 0 and rigid and name not in VELOCITY_ERRORS:
            _err(errors, f"{name} must stay positive", loc("parameters", name, "range"),
                 f"parameters.{name}.range", "MPG104", "a range above 0", f"{list(pr.range)}")
    if unc.latency and not rigid:
        _err(errors, "latency is modelled for rigid bodies", loc("latency"), "latency", "MPG104",
             "a rigid_body system (or no latency)", f"a {kind} system")
    elif unc.latency:
        try:
            latency_steps(spec, spec.project.oracle.dt)
        except SpecError as e:
            errors.append(e)
    dist = unc.disturbance
    if dist is not None and dist.force is not None and not rigid:
        _err(errors, "a force disturbance needs a rigid-body system", loc("disturbance", "force"),
             "disturbance.force", "MPG104", "disturbance: {inputs: [...], bound: ...}", "force")
    if dist is not None and dist.inputs is not None:
        if rigid:
            _err(errors, "rigid bodies take a push, not an input disturbance", loc("disturbance", "inputs"),
                 "disturbance.inputs", "MPG104", "disturbance: {force: {frame: ..., bound: [x, y, z]}}", "inputs")
        else:
            for i, u in enumerate(dist.inputs):
                if u not in sys.inputs:
                    _err(errors, "unknown input", loc("disturbance", "inputs", i), f"disturbance.inputs.{i}", "MPG107",
                         "one of " + ", ".join(sys.inputs) if sys.inputs else "no inputs", repr(str(u)[:60]),
                         _hint(u, sys.inputs))
    for name in unc.initial_state if not rigid else ():  # rigid bodies: checked once compiled
        if name not in sys.states:
            _err(errors, "unknown state", loc("initial_state", name), f"initial_state.{name}", "MPG107",
                 "one of " + ", ".join(sys.states), repr(str(name)[:60]), _hint(name, sys.states))
    nodes = {p.name for p in spec.primitives}
    chosen = set(unc.nodes) if unc.nodes is not None else nodes

    def node(n: str, path: tuple, key: str, among: set, what: str = "unknown primitive"):
        if n not in among:
            _err(errors, what, loc(*path), key, "MPG304", "one of " + ", ".join(sorted(among)),
                 repr(str(n)[:60]), _hint(n, among))

    for i, n in enumerate(unc.nodes or ()):
        node(n, ("nodes", i), f"nodes.{i}", nodes)
    for i, a in enumerate(unc.assertions):
        base = ("assertions", i)
        refs = node_refs(a)
        for name, where in refs or ():
            among, what = ((nodes, "unknown primitive") if name not in nodes
                           else (chosen, "primitive not in uncertainty.nodes"))
            node(name, base + where, ".".join(map(str, base + where)), among, what)
        if refs is None:
            _err(errors, "this assertion does not apply to the robust graph", loc(*base), f"assertions.{i}",
                 "MPG104", "edge, no_edge, plan or reachable_from", type(a).__name__)
        elif isinstance(a, RequireEdge) and a.edge.evidence == "certified":
            _err(errors, "the robust graph rests on sampled scenarios, so none of its edges is certified",
                 loc(*base, "edge", "evidence"), f"assertions.{i}.edge.evidence", "MPG104",
                 "evidence: simulated (or no evidence key)", "certified",
                 "require `evidence: certified` in the project's assertions, on the nominal graph")
    n = len(chosen & nodes)
    if unc.rollouts(n) > unc.budget:
        where = ("budget",) if "budget" in unc.model_fields_set else ()
        _err(errors, "the robust stage could run more rollouts than its budget", loc(*where), "budget" if where else "",
             "MPG104", f"at most {unc.budget:,} rollouts (uncertainty.budget)",
             f"up to {unc.rollouts(n):,}: {n * (n - 1)} edges x {unc.cells} cells x scenarios x start states x "
             f"(1 + {unc.search} search rounds)",
             "lower cells, corners, samples, search or start_in_roa.samples, or raise uncertainty.budget")
    if errors:
        raise SpecErrors(errors)


def check_uncertainty_compiled(spec: ProjectSpec, prims: dict) -> None:
    """What only the compiled rigid body knows: the push's frame and the state names."""
    unc = spec.project.uncertainty
    if unc is None or not prims:
        return
    sys = next(iter(prims.values())).system
    if not sys.is_rigid_body:
        return
    errors: list[SpecError] = []
    loc = lambda *k: spec.locate(("uncertainty", *k))  # noqa: E731
    force = unc.disturbance.force if unc.disturbance is not None else None
    if force is not None and force.frame not in sys.base_frames():
        frames = sys.base_frames()
        _err(errors, "the push acts on a frame of the floating base", loc("disturbance", "force", "frame"),
             "disturbance.force.frame", "MPG107", "one of " + ", ".join(frames) if frames else "a floating base",
             repr(str(force.frame)[:60]), _hint(force.frame, frames))
    for name in unc.initial_state:
        if name not in sys.state_names:
            _err(errors, "unknown state", loc("initial_state", name), f"initial_state.{name}", "MPG107",
                 "a state of the system", repr(str(name)[:60]), _hint(name, sys.state_names))
    if errors:
        raise SpecErrors(errors)
