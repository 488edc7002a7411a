"""The cross-check as assertions: with `require_agreement`, each replayed run's verdict must match."""
from __future__ import annotations

from .assertions import AssertionResult


def _verdict(side: dict) -> str:
    fv = side.get("first_violation")
    if side.get("safe"):
        return "safe"
    if fv:
        return f"unsafe ({fv['h']} of {fv['primitive']} at t = {fv['t']:.3f} s)"
    return f"unsafe ({side.get('failed') or 'stopped'})"


def agreement_assertions(result, start: int) -> list[AssertionResult]:
    """One assertion per replayed run of a CrossCheckResult (the simulator's verdict is mpgspec's) and
    per variant (the graph executor on the simulator's state is safe and reaches every goal)."""
    out = []
    for mode, r in result.runs.items():
        msg = f"{result.simulator}: {_verdict(r['mujoco'])}; mpgspec: {_verdict(r['mpgspec'])}"
        out.append(AssertionResult(start + len(out), "crosscheck", f"{mode} run agrees in {result.simulator}",
                                   "pass" if r["agree"] else "fail", msg))
    for v in result.variants:
        sim = result.simulator
        missed = [g["goal"] for g in v.get("goals") or [] if g.get("arrived") is None]
        goals = "every goal reached" if not missed else f"not reached: {', '.join(missed)}"
        msg = f"{sim} executor: {_verdict(v[sim])}, {goals}; mpgspec: {_verdict(v['mpgspec'])}"
        out.append(AssertionResult(start + len(out), "crosscheck", f"graph executor holds in {sim} with {v['name']}",
                                   "pass" if v["agree"] else "fail", msg))
    return out
