"""Definition-1 assumption checks of every primitive, counted as the project's severity says."""
from __future__ import annotations

from ..compile.primitive import CompiledPrimitive
from ..oracle.executors import InProcess
from ..oracle.joint import Map, run
from ..oracle.tasks import Failed
from .assumptions import AssumptionCheck, check_primitive, seed_hybrid_orbit
from .region_size import region_size
from .roa_flows import roa_invariant


def primitive_checks(prims: dict[str, CompiledPrimitive], name: str) -> list[dict]:
    """check_primitive of prims[name] and, for a fixed primitive, roa_invariant (flows from E's
    boundary), as dicts: one map item of the executor."""
    p = prims[name]
    checks = check_primitive(p)
    flows = roa_invariant(p)
    if flows is not None:
        checks.insert(3, flows)  # after roa_in_safe_set, in the order of Definition 1
    return [c.to_dict() for c in checks]


def _checks_by_name(prims: dict[str, CompiledPrimitive], memo):
    """Every primitive's checks: from the memo (by content hash) or computed through one map, one
    primitive per item (each primitive's checks depend on it alone, so the results are the same on
    any executor). A primitive whose checks raised raises here, as it would in place."""
    keys = {n: memo.key("assumptions", p.digest()) for n, p in prims.items()} if memo else {}
    known = {n: memo.get(k) for n, k in keys.items()}
    todo = [n for n in prims if known.get(n) is None]
    if todo:
        done = yield Map(primitive_checks, todo, "assumptions (Definition 1)", prims)  # short: last in a merged map
        for n, res in zip(todo, done):
            if isinstance(res, Failed):
                raise RuntimeError(f"the Definition 1 checks of {n}: {res.error}")
            known[n] = res
            if memo:
                memo.put(keys[n], res)
    return known


def check_assumptions(prims: dict[str, CompiledPrimitive], severity: dict, memo=None,
                      roa: dict | None = None, executor=None, progress=None) -> list[AssumptionCheck]:
    """Definition-1 checks of every primitive; a failure counts as the project's severity says
    ('fail', 'warn' or 'off').

    memo (optional) keeps the checks of each primitive by its content hash. roa (optional, name ->
    RoARecord of mpgspec.certify.roa) adds `roa_size` where E is empty (fail) or collapsed (warn).
    executor (optional, in this process when omitted) runs the primitives' checks through its map,
    with progress(label, i, n)."""
    stage = assumptions_stage(prims, severity, memo, roa)
    return run(stage, executor or InProcess(), progress)


def assumptions_stage(prims: dict[str, CompiledPrimitive], severity: dict, memo=None, roa: dict | None = None):
    """check_assumptions as a stage (mpgspec.oracle.joint). A gait's orbit and monodromy are those its
    floquet verifier computed this run, where it ran the same flow (seed_hybrid_orbit), before the
    checks' map starts (workers forked after it inherit them)."""
    for name, rec in (roa or {}).items():
        if name in prims:
            seed_hybrid_orbit(prims[name], rec.evidence)
    known = yield from _checks_by_name(prims, memo)
    out = []
    for p in prims.values():
        checks = [AssumptionCheck(**c) for c in known[p.name]]
        size = region_size(p, roa[p.name], memo) if roa and p.name in roa else None
        for c in checks + ([size] if size else []):
            sev = severity.get(c.name, "fail")
            if sev == "off":
                continue
            if c.status == "fail" and sev == "warn":
                c.status, c.message = "warn", c.message + " (reported as a warning by the project)"
            out.append(c)
    return out
