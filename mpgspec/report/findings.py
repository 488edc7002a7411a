"""The warnings of a report, counted alike by the page, the command line and the API: assumption
checks that warn, sequence runs whose replay in an independent simulator reached another verdict
than mpgspec's (the model mpgspec verified is then not the robot's: a finding that can hurt), and a
graph run whose path takes edges that did not withstand the project's uncertainty (nominal only)."""
from __future__ import annotations

SIMULATORS = {"mujoco": "MuJoCo"}
"""How simulator names are written in the report."""


def _num(v, digits: int = 4) -> str:
    return "?" if not isinstance(v, (int, float)) else f"{v:.{digits}g}"


def disagreements(report: dict) -> list[dict]:
    """{mode, text} for each cross-checked run whose verdict differs from mpgspec's, for each variant
    of the graph executor that is unsafe or does not reach every goal (also `variant`: its name), and for
    a graph executor run on the simulator's own state that is unsafe or does not reach every goal."""
    xc = report.get("crosscheck")
    if not isinstance(xc, dict):
        return []
    key = xc.get("simulator")
    sim = SIMULATORS.get(key, str(key or "the simulator"))
    out = []
    for mode, r in (xc.get("runs") or {}).items():
        if not isinstance(r, dict) or r.get("agree", True):
            continue
        theirs, ours = r.get(key) or {}, r.get("mpgspec") or {}
        v = theirs.get("first_violation") or {}
        first = f": {v.get('h')} of {v.get('primitive')} at t = {_num(v.get('t'))} s, {_num(v.get('value'))}" if v else ""
        out.append({"mode": mode, "text": f"{sim} finds the {mode} run {'safe' if theirs.get('safe') else 'unsafe'} "
                                          f"where mpgspec finds it {'safe' if ours.get('safe') else 'unsafe'}{first}"})
    for v in xc.get("variants") or []:
        if not isinstance(v, dict) or v.get("agree", True):
            continue
        what = _executor_trouble(v.get(key) or {}, v.get("goals"), v.get("waiting"))
        out.append({"mode": "graph", "variant": str(v.get("name")),
                    "text": f"with {v.get('name')}, the graph executor deciding from {sim}'s state {what}"})
    for mode, r in (xc.get("runs") or {}).items():
        e = r.get("executor") if isinstance(r, dict) else None
        if isinstance(e, dict) and (not e.get("safe", True) or not e.get("reached_every_goal", True)):
            what = _executor_trouble(e, e.get("goals"), e.get("waiting"))
            out.append({"mode": mode, "text": f"the {mode} executor deciding from {sim}'s state {what}"})
    return out


def _executor_trouble(verdict: dict, goals, waiting) -> str:
    """What went wrong with an executor's run: 'is unsafe: <first violation or failure>', else 'does not
    reach every goal: <where it waits, or the goals it missed>'."""
    if not verdict.get("safe", True):
        f = verdict.get("first_violation") or {}
        first = f": {f.get('h')} of {f.get('primitive')} at t = {_num(f.get('t'))} s, {_num(f.get('value'))}" \
            if f else f": {verdict.get('failed')}" if verdict.get("failed") else ""
        return f"is unsafe{first}"
    w = waiting or {}
    return "does not reach every goal" + (f": it waits in {w.get('primitive')}, {waiting_why(w)}" if w else _missed(goals))


def _missed(goals) -> str:
    """': it misses A (commanded at t s), ...' for the goals a run never reached, or ''."""
    out = [f"{g.get('goal')} (commanded at {_num(g.get('t'))} s)" for g in goals or []
           if isinstance(g, dict) and g.get("arrived") is None]
    return f": it misses {', '.join(out)}" if out else ""


def waiting_why(w: dict) -> str:
    """Why an executor waits in a primitive, from its best RoA margin there."""
    m = w.get("best_roa_margin")
    if m is not None and m > 0:
        return (f"whose E its state entered (best E margin {_num(m)}) but never within the share of it the next "
                f"switch was checked from (edges, from E_A)")
    return f"whose E its state never enters (best E margin {_num(m)})"


def nominal_only_path(report: dict) -> dict | None:
    """{hops, nominal_only} of the graph run's path when the report has a robust graph and some hop
    of that path is not in it (the planned path is then verified for the nominal model only); None
    otherwise."""
    rob = report.get("robust")
    run = ((report.get("sequence") or {}).get("runs") or {}).get("graph")
    if not isinstance(rob, dict) or not isinstance(run, dict):
        return None
    survives = {(e.get("from"), e.get("to")): bool(e.get("survives")) for e in rob.get("edges") or []}
    hops = []
    for s in run.get("switches") or []:
        hop = (s.get("from"), s.get("to"))
        if hop[0] is not None and hop in survives and hop not in hops:
            hops.append(hop)
    bad = [h for h in hops if not survives[h]]
    return {"hops": len(hops), "nominal_only": [f"{a} -> {b}" for a, b in bad]} if bad else None


def warning_count(report: dict | None) -> int:
    """Assumption checks that warn, cross-check disagreements, and a graph run through nominal-only edges."""
    r = report or {}
    return (sum(c.get("status") == "warn" for c in r.get("assumptions", [])) + len(disagreements(r))
            + (nominal_only_path(r) is not None))


def path_text(bad: dict) -> str:
    """The warning line of nominal_only_path's result."""
    return (f"{len(bad['nominal_only'])} of the {bad['hops']} edges the graph run takes are nominal only (not robust "
            f"to the project's uncertainty): {', '.join(bad['nominal_only'])}")
