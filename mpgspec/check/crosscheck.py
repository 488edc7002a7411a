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
    """One assertion per replayed run and per variant of a CrossCheckResult: the simulator's verdict
    is mpgspec's."""
    out = []
    for mode, r in result.runs.items():
        msg = f"{result.simulator}: {_verdict(r['mujoco'])}; mpgspec: {_verdict(r['mpgspec'])}"
        out.append(AssertionResult(start + len(out), "crosscheck", f"{mode} run agrees in {result.simulator}",
                                   "pass" if r["agree"] else "fail", msg))
    for v in result.variants:
        sim = result.simulator
        msg = f"{sim}: {_verdict(v[sim])}; mpgspec: {_verdict(v['mpgspec'])}"
        out.append(AssertionResult(start + len(out), "crosscheck", f"graph run agrees in {sim} with {v['name']}",
                                   "pass" if v["agree"] else "fail", msg))
    return out
