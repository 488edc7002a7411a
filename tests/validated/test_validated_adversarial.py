"""Soundness of the `validated` oracle backend on generated cases with exact answers (CI sample).

The families, their exact answers and the runner are in validated_campaign.py (read its
docstring): the rk4 campaigns' generators (tests/oracle/adversarial.py, pieces_campaign.py) and
two more, grazing ties and a saturation kink followed by a tight margin. Each family is one test
on a seeded sample of CI_COUNTS cases: no certified `safe` where the exact answer is unsafe, no
certified `unsafe` where it is safe, no crash. Inconclusive is always allowed (grazing truths,
within 1e-9 of a tie, are expected to be); each test prints its family's row (shown with -rP).

The pieces families `state` and `sat` take 1-140 s per case in this backend, so they run only in
the full campaign (about 1,050 cases, every family):

    . .venv/bin/activate && python bench/bench_validated_soundness.py
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).parent))
import validated_campaign as vc  # noqa: E402

SEED = 20261203
CI_COUNTS = {"window": 30, "slab": 30, "graze": 30, "fast": 25, "graze_tie": 15, "satosc": 20, "clock": 25,
             "pulse": 15}
MIN_DECIDED = 0.15  # loose: share of the window, slab, graze and fast samples the backend must decide
_RESULTS: dict = {}


def _sample(family: str) -> list[vc.Item]:
    """The family's seeded CI sample with its exact answers (not judged)."""
    return vc.generate({family: CI_COUNTS[family]}, SEED + vc.FAMILIES.index(family))


def _judged(family: str) -> list[vc.Item]:
    """The family's CI sample, judged once per process."""
    if family not in _RESULTS:
        _RESULTS[family] = vc.judge(_sample(family))
    return _RESULTS[family]


@pytest.mark.parametrize("family", list(CI_COUNTS))
def test_no_false_verdicts(family):
    items = _judged(family)
    print("\n" + vc.table(items))
    wrong = vc.false_verdicts(items)
    assert not wrong, f"{family}: {len(wrong)} false verdicts, e.g.\n" + "\n".join(it.describe() for it in wrong[:5])
    errors = [it for it in items if it.status not in ("safe", "unsafe", "inconclusive")]
    assert not errors, f"{family}: {len(errors)} errors, e.g.\n" + "\n".join(it.describe() for it in errors[:3])


def test_the_backend_decides_cases_with_clear_margins():
    items = [it for fam in vc.ADV_FAMILIES for it in _judged(fam)]
    decided = sum(it.status in ("safe", "unsafe") for it in items) / len(items)
    assert decided >= MIN_DECIDED, f"only {decided:.0%} of {len(items)} cases decided"


# ----------------------------------------------------------------------------- the references themselves
def test_the_samples_hold_both_answers_and_the_sub_step_features():
    items = {fam: _sample(fam) for fam in CI_COUNTS}
    for fam, its in items.items():
        assert len(its) == CI_COUNTS[fam] and 0.1 <= np.mean([it.safe for it in its]) <= 0.9, fam
        assert all(it.grazing for it in its) if fam == "graze_tie" else not any(it.grazing for it in its), fam
    assert {it.kind for it in items["slab"]} >= {"crossed", "missed"}
    assert {it.kind for it in items["window"]} >= {"before_E_violated", "before_E_clear"}
    kinks = [vc.sat_path(it.x0).s1 for it in items["satosc"]]
    assert min(kinks) >= 2e-3 and max(kinks) <= 0.3


def test_graze_ties_keep_the_peak_and_move_the_limit():
    ties = vc.generate({"graze_tie": 20}, SEED)
    for it in ties:
        t = vc.adv.reference(it.prim, it.x0, it.t0)
        assert t.tie and 1e-12 * 0.99 <= abs(t.h_min) <= 1e-9 and t.safe == (t.h_min > 0) == it.safe
    assert {it.safe for it in ties} == {True, False}


def test_satosc_exact_path_matches_dense_integration():
    items = vc.generate({"satosc": 8}, SEED + 1)
    r, wp, wv = vc.SAT_E
    for it in items:
        p0, v0, om, ze, c, U, sg = it.x0
        t = vc.sat_reference(it.x0)
        end = t.tau_E + 0.01
        sol = solve_ivp(lambda s, x: [x[1], np.clip(-om * om * x[0] - 2 * ze * om * x[1], -U, U)], (0.0, end),
                        [p0, v0], method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True, max_step=2e-3)
        s = np.linspace(0.0, end, 20001)
        P, V = vc.sat_path(it.x0).pv(s)
        np.testing.assert_allclose(sol.sol(s)[0], P, atol=1e-8)
        K = vc.adv.PARAM_WEIGHT * (om * om + ze * ze + c * c + U * U + sg * sg)
        inside = r - np.sqrt(wp * P * P + wv * V * V + K) > 0
        assert inside.any() and t.tau_E - 1e-9 <= s[np.argmax(inside)] <= t.tau_E + s[1] + 1e-9
        sampled = (sg * (P - c))[s <= t.tau_E].min()
        assert t.h_min <= sampled + 1e-12 and sampled - t.h_min < 1e-5  # the exact least value is below every sample


def test_satosc_spec_encodes_what_the_reference_assumes():
    prim = vc.primitives("satosc")[vc.SAT_NAME]
    rng = np.random.default_rng(4)
    r, wp, wv = vc.SAT_E
    for _ in range(40):
        x = np.array([rng.normal(), rng.normal(0, 10), rng.uniform(1, 40), rng.uniform(0.05, 0.9), rng.normal(),
                      rng.uniform(0.1, 500), rng.choice([-1.0, 1.0])])
        p, v, om, ze, c, U, sg = x
        t = float(rng.uniform(0, 5))
        u = min(max(-om * om * p - 2 * ze * om * v, -U), U)
        np.testing.assert_allclose(np.array(prim.f_cl(x, t, 0.3, x)).ravel(), [v, u, 0, 0, 0, 0, 0], rtol=1e-12,
                                   atol=1e-12)
        assert float(prim.h(x, t, 0.3, x)) == pytest.approx(sg * (p - c), abs=1e-12)
        K = vc.adv.PARAM_WEIGHT * (om * om + ze * ze + c * c + U * U + sg * sg)
        assert float(prim.roa_margin(x, t)) == pytest.approx(r - math.sqrt(wp * p * p + wv * v * v + K), abs=1e-13)
