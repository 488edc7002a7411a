"""Adversarial soundness of the safety oracle: no FALSE SAFE on any family, backend or preset.

The families, the exact reference and the runner are in adversarial.py (read its docstring): about
2,400 cases (narrow `when` windows, thin keep-out slabs, grazing peaks, fast underdamped
undershoots), each with an exact answer computed without mpgspec. Every case runs through the
"rk4" backend at every preset; the "scipy" backend (one Python rollout at a time) runs a fixed
random subset of 75 cases per family, 300 per preset, the same subset for every preset. The two
backends' jobs run in two spawned processes, in this one inside a pytest-xdist worker (ADVERSARIAL_WORKERS
overrides).

The summary table (family x backend x preset: cases, false safe, false unsafe, inconclusive,
agreement, safe-recall) is printed in pytest's terminal summary, also with -q:

    . .venv/bin/activate && python -m pytest -q tests/oracle/test_adversarial.py

About 1-1.5 minutes on 2 idle cores, most of it the scipy backend. Nothing is marked slow.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).parent))
import adversarial as adv  # noqa: E402

MIN_SAFE_RECALL = 0.25  # loose: the oracle must call at least this share of the truly safe cases safe
COMBOS = [(b, p) for b in adv.BACKENDS for p in adv.PRESETS]


class _Summary:
    """Prints the campaign's table in pytest's terminal summary (shown with -q too)."""

    def __init__(self, text: str):
        self.text = text

    def pytest_terminal_summary(self, terminalreporter):
        terminalreporter.section("adversarial oracle soundness (tests/oracle/adversarial.py)")
        for line in self.text.splitlines():
            terminalreporter.write_line(line)


@pytest.fixture(scope="module")
def campaign(request):
    res = adv.run_campaign()
    text = adv.summary_table(res)
    for b, p in COMBOS:
        for c in adv.false_safes(res, b, p)[:1]:
            text += f"\nFALSE SAFE {b}/{p}: {c.describe()}"
    name = "adversarial-summary"
    if request.config.pluginmanager.get_plugin(name) is None:
        request.config.pluginmanager.register(_Summary(text), name)
    return res


# ----------------------------------------------------------------------------- the cases
def test_every_family_has_both_answers_and_enough_cases(campaign):
    cases = campaign["cases"]
    assert len(cases) >= 2000
    for fam in adv.FAMILIES:
        truths = [c.truth.safe for c in cases if c.family == fam]
        assert 0.15 <= np.mean(truths) <= 0.85, f"{fam}: {np.mean(truths):.0%} truly safe"
    for b, p in COMBOS:
        ran = [c for c in cases if (b, p) in c.status]
        assert len(ran) == (len(cases) if b.startswith("rk4") else min(len(cases), 4 * adv.SCIPY_PER_FAMILY))
        assert len(ran) >= 300
        assert {c.family for c in ran} == set(adv.FAMILIES)


# ----------------------------------------------------------------------------- soundness
@pytest.mark.parametrize("backend,preset", COMBOS)
def test_no_false_safe(campaign, backend, preset):
    bad = adv.false_safes(campaign, backend, preset)
    by_family = {f: sum(c.family == f for c in bad) for f in adv.FAMILIES}
    assert len(bad) == 0, (f"{backend}/{preset}: {len(bad)} FALSE SAFE {by_family}, e.g.\n"
                           + "\n".join(c.describe() for c in bad[:10]))


@pytest.mark.parametrize("backend,preset", COMBOS)
def test_safe_answers_are_not_withheld_everywhere(campaign, backend, preset):
    t = adv.tallies(campaign)[("all", backend, preset)]
    errors = [c.status[(backend, preset)] for c in campaign["cases"]
              if c.status.get((backend, preset), "").startswith("error")]
    print(f"{backend}/{preset}: {t.recall:.1%} of {t.truly_safe} truly safe called safe, "
          f"{t.inconclusive / t.cases:.1%} inconclusive, {t.false_unsafe} truly safe called unsafe")
    assert not errors, f"{len(errors)} oracle errors, e.g. {errors[0]}"
    assert t.recall >= MIN_SAFE_RECALL, (f"{backend}/{preset} calls only {t.recall:.1%} of the truly safe cases "
                                         f"safe ({t.inconclusive / t.cases:.1%} inconclusive)")


# ----------------------------------------------------------------------------- the reference itself
def test_closed_form_matches_the_matrix_exponential():
    rng = np.random.default_rng(3)
    for _ in range(200):
        om, ze = adv.log_uniform(rng, 2.0, 500.0), float(rng.uniform(0.02, 1.8))
        if abs(ze - 1.0) < 0.05:
            continue
        x0 = rng.normal(0.0, [1.0, om])
        loop = adv.Loop(om, ze, *x0)
        A = np.array([[0.0, 1.0], [-om * om, -2.0 * ze * om]])
        for s in rng.uniform(0.0, adv.HORIZON, 4):
            want = scipy.linalg.expm(A * s) @ x0
            np.testing.assert_allclose(loop.pv(s), want, rtol=1e-9, atol=1e-11 * (abs(x0[0]) * om + abs(x0[1])))


def _scan(case, ds_max=2e-5):
    """min h over the active part of [0, tau_E] and the first time in E, from DOP853 (rtol 1e-12)
    scanned on a grid: an independent, approximate second reference."""
    p0, v0, om, ze, c, w, sg = case.x0
    r, wp, wv = adv.E_SPEC[case.prim]
    K = adv.PARAM_WEIGHT * (om * om + ze * ze + c * c + w * w + sg * sg)
    end = case.truth.tau_E if case.truth.tau_E is not None else adv.HORIZON
    sol = solve_ivp(lambda s, x: [x[1], -om * om * x[0] - 2 * ze * om * x[1]], (0.0, min(adv.HORIZON, end + 0.01)),
                    [p0, v0], method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
    ds = min(ds_max, math.pi / om / 200)
    s = np.linspace(0.0, sol.t[-1], int(sol.t[-1] / ds) + 2)
    P, V = sol.sol(s)
    M = r - np.sqrt(wp * P * P + wv * V * V + K)
    entered = s[np.argmax(M > 0)] if (M > 0).any() else None
    act = s <= end
    if case.prim == "Window":
        on = np.zeros_like(act)
        for k in range(len(adv.WINDOW_FRACTIONS)):
            a, b = adv.window_bounds(k)
            on |= (case.t0 + s >= a) & (case.t0 + s < b)
        act &= on
    H = np.abs(P - c) - w if case.prim == "Slab" else sg * (P - c)
    hmin = H[act].min() if act.any() else math.inf
    tol = np.abs(V).max() * ds + om * om * np.abs(P).max() * ds * ds  # what a grid of step ds can miss
    return hmin, entered, tol, ds


def test_exact_answers_agree_with_dense_integration():
    cases, _ = adv.generate(40, seed=11)
    rng = np.random.default_rng(5)
    checked = 0
    for fam in adv.FAMILIES:
        fam_cases = [c for c in cases if c.family == fam]
        for c in rng.choice(fam_cases, 10, replace=False):
            hmin, entered, tol, ds = _scan(c)
            t = c.truth
            if t.tau_E is not None:
                assert entered is not None and t.tau_E - 1e-9 <= entered <= t.tau_E + ds + 1e-9, c.describe()
            if math.isfinite(t.h_min):
                assert t.h_min <= hmin + 1e-9, c.describe()  # the exact min is below every sample
                assert hmin - t.h_min <= tol + 1e-9, c.describe()
                if abs(t.h_min) > tol:
                    assert (hmin > 0) == (t.h_min > 0), c.describe()
            checked += 1
    assert checked == 40


def test_the_spec_encodes_what_the_reference_assumes():
    """Guard: the compiled project's closed loop, safety functions and E are the reference's formulas."""
    prims, _ = adv.compile_adversarial_project()
    rng = np.random.default_rng(9)
    for name, prim in prims.items():
        r, wp, wv = adv.E_SPEC[name]
        for _ in range(30):
            x = np.array([rng.normal(), rng.normal(0, 10), rng.uniform(1, 500), rng.uniform(0.01, 1.0),
                          rng.normal(), rng.uniform(0, 0.01), rng.choice([-1.0, 1.0])])
            p, v, om, ze, c, w, sg = x
            k = int(rng.integers(len(adv.WINDOW_FRACTIONS)))
            a, b = adv.window_bounds(k)
            t = float(rng.choice([a, b, 0.5 * (a + b), a - 1e-9, b - 1e-12, rng.uniform(0, 60)]))
            np.testing.assert_allclose(np.array(prim.f_cl(x, t, 0.3, x)).ravel(),
                                       [v, -om * om * p - 2 * ze * om * v, 0, 0, 0, 0, 0], rtol=1e-12, atol=1e-12)
            h = np.array(prim.h(x, t, 0.3, x)).ravel()
            if name == "Window":
                want = [sg * (p - c) if wa <= t < wb else None for wa, wb in map(adv.window_bounds, range(5))]
                for hv, wv_ in zip(h, want):
                    assert (hv == pytest.approx(wv_, abs=1e-12)) if wv_ is not None else hv >= 1e8
            else:
                want = abs(p - c) - w if name == "Slab" else sg * (p - c)
                assert h.tolist() == [pytest.approx(want, abs=1e-12)]
            K = adv.PARAM_WEIGHT * (om * om + ze * ze + c * c + w * w + sg * sg)
            assert float(prim.roa_margin(x, t)) == pytest.approx(r - math.sqrt(wp * p * p + wv * v * v + K), abs=1e-13)
