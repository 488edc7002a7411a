"""The validated backend in the pipeline: certified verdicts, certified windows and refusals.

On the ladder (tests/validated/ladder_truth.py gives every answer in closed form) each validated
verdict must be the exact one, and every t_A inside a certified window must be safe in closed form
at the t_B that proved it, while an interval of t_A that holds an unsafe switch is never proved.
On the cart, every decided verdict must agree with rk4's. Loops that jump are refused by name at
the spec's `oracle.method`.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.graph.certified import prove
from mpgspec.validated.flow import Options

sys.path.insert(0, str(Path(__file__).parent))
from ladder_truth import Ladder  # noqa: E402

ROOT = Path(__file__).parents[2]
SPECS = ROOT / "specs"


@pytest.fixture(scope="module")
def ladder():
    """specs/ladder verified by its own method (validated), with its closed form."""
    p = api.verify([SPECS / "ladder"], out_dir=None).projects[0]
    assert p.status == "pass", [a for a in p.report["assertions"] if a["status"] != "pass"]
    return p, Ladder(p.compiled.spec, p.compiled.prims)


def test_every_ladder_verdict_is_certified_and_exact(ladder):
    p, truth = ladder
    g, prims = p.mpg, p.compiled.prims
    n = 0
    for (a, b), tr in g.transitions.items():
        for i, ta in enumerate(tr.t_A):
            for j, tb in enumerate(tr.t_B):
                e = tr.evidence[i][j]
                exact = truth.cell(a, ta, b, tb, float(prims[b].horizons(p.compiled.settings.horizon, [tb])[0]))
                assert e.method == "certified" and e.status == ("safe" if exact.verdict else "unsafe"), (a, b, ta, tb)
                if exact.verdict:
                    assert e.t_enter >= exact.t_enter - 1e-9
                    assert all(e.lower_bounds[k] <= v + 1e-9 for k, v in exact.margins.items())
                n += 1
    assert n == 54


def test_certified_windows_hold_for_every_t_A_in_them(ladder):
    """Re-prove each certified interval of t_A, then check 7 t_A inside it in closed form."""
    p, truth = ladder
    g, prims, s = p.mpg, p.compiled.prims, p.compiled.settings
    rng = np.random.default_rng(5)
    checked = 0
    for (a, b), tr in g.transitions.items():
        if prims[a].period is None:
            continue
        for lo, hi in tr.certified["windows"]:
            grid = [t for t in tr.t_A if lo - 1e-9 <= t <= hi + 1e-9] + ([hi] if hi > tr.t_A[-1] + 1e-9 else [])
            for ta, tb in zip(grid[:-1], grid[1:]):
                i = int(np.argmin(np.abs(tr.t_A - ta)))
                t_B = tr.best_t_B[i]
                H = float(prims[b].horizons(s.horizon, [t_B])[0])
                ok, _, _ = prove(prims[a], prims[b], ta, tb, t_B, H, Options())
                if not ok:  # proved with the other end's t_B
                    t_B = tr.best_t_B[(i + 1) % len(tr.t_A)]
                    H = float(prims[b].horizons(s.horizon, [t_B])[0])
                    assert prove(prims[a], prims[b], ta, tb, t_B, H, Options())[0]
                for t in rng.uniform(ta, tb, 7):
                    assert truth.cell(a, t % prims[a].period, b, t_B, H).verdict == 1, (a, b, t, t_B)
                    checked += 1
    assert checked >= 7 * 8


def test_an_interval_holding_an_unsafe_switch_is_never_proved(ladder):
    """Sway -> Hold(0) is Class 2: between a safe grid t_A and an unsafe one lies an unsafe t_A."""
    p, truth = ladder
    g, prims, s = p.mpg, p.compiled.prims, p.compiled.settings
    a, b = "Sway", "Hold(0)"
    tr = g.transitions[(a, b)]
    H = float(prims[b].horizons(s.horizon, [0.0])[0])
    ok = [truth.cell(a, t, b, 0.0, H).verdict for t in tr.t_A]
    edges = [(i, i + 1) for i in range(len(ok) - 1) if ok[i] != ok[i + 1]]
    assert edges
    for i, j in edges[:2]:
        assert not prove(prims[a], prims[b], float(tr.t_A[i]), float(tr.t_A[j]), 0.0, H, Options())[0]


def test_cart_validated_verdicts_agree_with_rk4_and_are_certified():
    val = api.verify([SPECS / "cart"], out_dir=None, overrides={"method": "validated"}).projects[0]
    rk4 = api.verify([SPECS / "cart"], out_dir=None, overrides={"method": "rk4"}).projects[0]
    statuses = []
    for key, tr in val.mpg.transitions.items():
        other = rk4.mpg.transitions[key]
        for row, row_r in zip(tr.evidence, other.evidence):
            for e, r in zip(row, row_r):
                assert e.status == r.status and e.method == "certified", (key, e.message)
                statuses.append(e.status)
    assert statuses.count("safe") > 20 and statuses.count("unsafe") > 5
    assert all(tr.method == "certified" for tr in val.mpg.transitions.values() if tr.cls)


def test_validated_refuses_a_loop_that_jumps():
    spec = ROOT / "tests" / "fixtures" / "falling_body" / "project.yaml"
    p = api.verify([spec], out_dir=None, overrides={"method": "validated"}).projects[0]
    assert p.status == "error", p.status
    text = str(p.errors)
    assert "MPG120" in text and "hybrid" in text and "oracle.method" in text, text
