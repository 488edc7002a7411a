"""Definition-1 assumption checks of every primitive, counted as the project's severity says."""
from __future__ import annotations

from ..compile.primitive import CompiledPrimitive
from .assumptions import AssumptionCheck, check_primitive
from .region_size import region_size


def check_assumptions(prims: dict[str, CompiledPrimitive], severity: dict, memo=None,
                      roa: dict | None = None) -> list[AssumptionCheck]:
    """Definition-1 checks of every primitive; a failure counts as the project's severity says
    ('fail', 'warn' or 'off').

    memo (optional) keeps the checks of each primitive by its content hash. roa (optional, name ->
    RoARecord of mpgspec.certify.roa) adds `roa_size` where E is empty (fail) or collapsed (warn)."""
    out = []
    for p in prims.values():
        key = memo.key("assumptions", p.digest()) if memo else None
        known = memo.get(key) if memo else None
        checks = [AssumptionCheck(**c) for c in known] if known is not None else check_primitive(p)
        if memo and known is None:
            memo.put(key, [c.to_dict() for c in checks])
        size = region_size(p, roa[p.name], memo) if roa and p.name in roa else None
        for c in checks + ([size] if size else []):
            sev = severity.get(c.name, "fail")
            if sev == "off":
                continue
            if c.status == "fail" and sev == "warn":
                c.status, c.message = "warn", c.message + " (reported as a warning by the project)"
            out.append(c)
    return out
