"""Non-smooth closed loops: guards collected by the compiler, steps ended where a guard crosses.

Known answers in closed form on x' = u (test_oracle's scalar integrator) and, in bulk, the
generated families of pieces_campaign.py (read its docstring): laws that switch on the state and
on the clock, input saturation and pulses, at every preset and both error estimates. The full
campaign (600 cases per family, 2,400 in all) runs stand-alone:

    . .venv/bin/activate && python tests/oracle/pieces_campaign.py --cases-per-family 600
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.compile.guards import collect
from mpgspec.oracle import SafetyOracle
from mpgspec.oracle.pieces import MIN_PIECE, guarded
from mpgspec.settings import OracleSettings

from test_oracle import GOAL, one

sys.path.insert(0, str(Path(__file__).parent))
import pieces_campaign as campaign  # noqa: E402

PRESETS = ("low", "medium", "high", "very_high")
ERRORS = ("local", "doubling")
SCIPY_CI = 4  # generated cases per family through the scipy backend here (10 stand-alone)


# ----------------------------------------------------------------------------- guards
def _loop(expr):
    x, t, s, xs = ca.SX.sym("x", 2), ca.SX.sym("t"), ca.SX.sym("s"), ca.SX.sym("x_sw", 2)
    return ca.Function("f", [x, t, s, xs], [expr(x, t)])


@pytest.mark.parametrize("expr,kinds", [
    (lambda x, t: ca.vertcat(x[1], ca.if_else(x[0] < 0.3, 1, 3)), ["<"]),
    (lambda x, t: ca.vertcat(x[1], ca.fmin(ca.fmax(-4 * x[0], -1), 1)), ["max", "min"]),
    (lambda x, t: ca.vertcat(ca.sign(t - 0.5), ca.fabs(x[1])), ["abs", "sign"]),
    (lambda x, t: ca.vertcat(ca.floor(t / 0.7), x[0]), ["floor"]),
])
def test_the_compiler_collects_every_switching_point_of_the_loop(expr, kinds):
    g = collect(_loop(expr))
    assert g.exposed and sorted(n.split(":")[0] for n in g.names) == kinds
    assert g.fn.size1_out(0) == len(kinds)


def test_a_guard_changes_sign_where_the_law_switches():
    g = collect(_loop(lambda x, t: ca.vertcat(x[1], ca.if_else(x[0] < 0.3, 1, 3))))
    below, above = (float(g.fn([x0, 0], 0, 0, [0, 0])) for x0 in (0.29, 0.31))
    assert below > 0 > above


def test_a_smooth_loop_has_no_guards_and_a_compiled_law_none_exposed():
    assert len(collect(_loop(lambda x, t: ca.vertcat(x[1], -x[0] - x[1] ** 3)))) == 0
    x = ca.MX.sym("x", 2)
    mx = ca.Function("f", [x, ca.MX.sym("t"), ca.MX.sym("s"), ca.MX.sym("x_sw", 2)], [x])
    g = collect(mx)
    assert not g.exposed and "not exposed" in g.why and g.record()["why"] == g.why


def test_the_primitive_carries_its_guards(tmp_path):
    prim = one(tmp_path, GOAL.replace("-2*(x - 1)", "-5*(x - 1)"), bounds=(-1, 1))  # saturated at 1
    assert prim.guards.names == ["saturation: u at its lower bound -1", "saturation: u at its upper bound 1"]
    assert guarded(prim)
    assert len(one(tmp_path, GOAL).guards) == 2  # the bounds of +-10 are guards too
    assert len(one(tmp_path, GOAL, bounds=("-.inf", ".inf")).guards) == 0


# ----------------------------------------------------------------------------- known answers
def _switching(tmp_path, law: str, c: float, T: float = 0.6):
    """x' = law from x0 = 0; c - x required on the clock window [0, T); E around 2 beyond x(T); the
    input unbounded."""
    prim = GOAL.replace('setpoint: {expr: [1]}', 'setpoint: {expr: [2]}').replace("-2*(x - 1)", law)
    return one(tmp_path, prim + f'  safe_set:\n    - {{name: cap, h: "{c!r} - x", when: [0, {T}]}}\n',
               bounds=("-.inf", ".inf"))


@pytest.mark.parametrize("error", ERRORS)
@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("on", ["state", "clock"])
@pytest.mark.parametrize("theta", [0.05, 0.31, 0.77])  # where the switch falls inside its step of 10 ms
def test_a_law_that_switches_inside_a_step_is_judged_on_each_branch(tmp_path, on, theta, preset, error):
    """Rate 1 until the switch at t* = 0.5 + theta dt, then 3: x(T) = t* + 3 (T - t*) exactly. RK4
    across the switch is off by up to 0.8 dt; on its two pieces it is exact. With c = x(T) - 3e-5
    (violated at the window's end by 3e-5) the answer must not be safe and the bound must read the
    true -3e-5; with c = x(T) + 3e-5 it is safe."""
    ts = 0.5 + theta * 0.01
    law = f"if_else(x < {ts!r}, 1, 3)" if on == "state" else f"if_else(t < {ts!r}, 1, 3)"
    x_T = ts + 3 * (0.6 - ts)
    s = OracleSettings.with_accuracy(preset, horizon=3.0, dt=0.01, error=error, jit=False)
    e = SafetyOracle(_switching(tmp_path, law, x_T - 3e-5), s)(np.array([0.0]), 0.0)
    assert e.status != "safe" and e.violated == "cap", e
    assert e.lower_bounds["cap"] == pytest.approx(-3e-5, abs=1e-9)
    e = SafetyOracle(_switching(tmp_path, law, x_T + 3e-5), s)(np.array([0.0]), 0.0)
    assert e.status == "safe", e
    assert e.lower_bounds["cap"] == pytest.approx(3e-5, abs=1e-9)


@pytest.mark.parametrize("error", ERRORS)
def test_a_saturation_kink_inside_a_step_is_judged_on_each_side(tmp_path, error):
    """u = clip(-4 (x - 2), -1, 1) from x0 = 1.3537: rate 1 until x = 1.75 at t_k = 0.3963, then
    x = 2 - e^(-4 (t - t_k)) / 4; c = x(T) -+ 1e-6 at T = 0.6."""
    tk = 0.3963
    x0 = 1.75 - tk
    x_T = 2 - math.exp(-4 * (0.6 - tk)) / 4
    s = OracleSettings.with_accuracy("very_high", horizon=3.0, dt=0.01, error=error, jit=False)
    for c, truth in ((x_T - 1e-6, "unsafe"), (x_T + 1e-6, "safe")):
        e = SafetyOracle(_switching(tmp_path, "clip(-4*(x - 2), -1, 1)", c), s)(np.array([x0]), 0.0)
        assert (e.status == "safe") == (truth == "safe"), e
        if truth == "safe":  # a bound over the window's last step: positive, at most the true margin
            assert 0 < e.lower_bounds["cap"] <= c - x_T + 1e-9


@pytest.mark.parametrize("error", ERRORS)
@pytest.mark.parametrize("width", [1e-5, 0.3 * MIN_PIECE])
def test_a_pulse_narrower_than_a_step_is_integrated_or_inconclusive(tmp_path, width, error):
    """A kick of area 0.2 at t = 0.2537 lasting `width`: x(T) = T + 0.2. A kick wider than
    MIN_PIECE is integrated on its own piece (the answer is right either way); a narrower one cannot
    be resolved, and the rollout is never safe."""
    P = 0.2 / width
    law = f"1 + {P!r}*(if_else(t > 0.2537, 1, 0) - if_else(t > {0.2537 + width!r}, 1, 0))"
    s = OracleSettings.with_accuracy("medium", horizon=3.0, dt=0.01, error=error, jit=False)
    for c in (0.8 - 1e-3, 0.8 + 1e-3):  # x(T) = 0.8
        e = SafetyOracle(_switching(tmp_path, law, c), s)(np.array([0.0]), 0.0)
        if width < MIN_PIECE or c < 0.8:
            assert e.status != "safe", (c, e)
        else:
            assert e.status == "safe", (c, e)


def test_a_law_that_chatters_ends_inconclusive(tmp_path):
    """x' = -sign(x - 0.3) from 0 slides on x = 0.3 forever and never reaches E around 1: every
    step there starts on the guard and crosses it again at once, so it is not resolved; the call
    returns, and never says safe."""
    prim = one(tmp_path, GOAL.replace("-2*(x - 1)", "-sign(x - 0.3)"))
    e = SafetyOracle(prim, OracleSettings(horizon=2.0, dt=0.01, refinements=0, jit=False))(np.array([0.0]), 0.0)
    assert e.status != "safe" and e.steps <= 2.0 / 0.01 + 5, e


@pytest.mark.parametrize("law, at", [("if_else(x < 0.50537, 1, 3)", [0.50537]), ("if_else(t < 0.3137, 1, 3)", [0.3137]),
                                     ("if_else(t < 0.2537, 1, 3) - if_else(t < 0.4211, 2, 0)", [0.2537, 0.4211])])
def test_a_trace_counts_the_crossings_it_located(tmp_path, law, at):
    """The report's traces count the steps that ended at a guard: one per switch of the law, at
    its time (x' = 1 from x0 = 0 reaches 0.50537 at t = 0.50537); a smooth loop's trace has none."""
    from mpgspec.oracle.trace import trace

    s = OracleSettings(horizon=1.0, dt=0.01, jit=False)
    c = trace(_switching(tmp_path, law, 10.0), np.array([0.0]), 0.0, 0.8, s)["crossings"]
    assert c["count"] == len(at) and c["t"] == pytest.approx(at, abs=1e-9), c
    assert "crossings" not in trace(one(tmp_path, GOAL, bounds=("-.inf", ".inf")), np.array([0.0]), 0.0, 0.8, s)


# ----------------------------------------------------------------------------- generated families
@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    # in CasADi's virtual machine: compiling the 24 chunks (4 loops, 3 steps, 2 estimates) would cost more
    return campaign.run(tmp_path_factory.mktemp("pieces"), per_family=40, jit=False, scipy=SCIPY_CI)


@pytest.fixture(scope="module")
def generated_large(tmp_path_factory):
    from mpgspec.oracle import integrator, looplib

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(looplib, "INLINE_NODES", 0)
        mp.setattr(integrator, "INLINE_NODES", 0)
        return campaign.run(tmp_path_factory.mktemp("pieces_large"), per_family=10, jit=False, scipy=0)


def test_no_false_safe_on_generated_loops_stepped_as_large_ones(generated_large):
    """The same families through a large loop's steps (a robot's): no false safe either."""
    bad = [(c.family, k, c.x_T - c.c) for c in generated_large for k, s in c.status.items()
           if c.unsafe and s == "safe"]
    assert not bad, campaign.table(generated_large)


def test_no_false_safe_on_any_generated_non_smooth_loop(generated):
    bad = [(c.family, k, c.x_T - c.c) for c in generated for k, s in c.status.items() if c.unsafe and s == "safe"]
    assert not bad, campaign.table(generated)


def test_the_scipy_reference_ran_every_family(generated):
    for fam in campaign.FAMILIES:
        ran = [c for c in generated if c.family == fam and ("scipy", "low") in c.status]
        assert len(ran) == SCIPY_CI


def test_every_generated_family_has_safe_answers_at_the_finest_preset(generated):
    for fam in campaign.FAMILIES:
        safe = [c for c in generated if c.family == fam and not c.unsafe]
        got = [c.status[("local", "very_high")] == "safe" for c in safe]
        assert np.mean(got) >= 0.5, (fam, campaign.table(generated))


@pytest.mark.parametrize("on", ["state", "clock"])
def test_the_scipy_reference_stops_at_every_guard(tmp_path, on):
    """The reference backend ends a solver piece at each guard crossing (a terminal event) and starts
    the next just after it: the same switching law gives the true margins, -3e-5 and 3e-5."""
    ts = 0.5 + 0.31 * 0.01
    law = f"if_else(x < {ts!r}, 1, 3)" if on == "state" else f"if_else(t < {ts!r}, 1, 3)"
    x_T = ts + 3 * (0.6 - ts)
    s = OracleSettings.with_accuracy("medium", horizon=3.0, dt=0.01, method="scipy", jit=False)
    for off in (-3e-5, 3e-5):
        e = SafetyOracle(_switching(tmp_path, law, x_T + off), s)(np.array([0.0]), 0.0)
        assert (e.status == "safe") == (off > 0), e
        assert e.lower_bounds["cap"] == pytest.approx(off, abs=1e-8)


# ----------------------------------------------------------------------------- large loops (a robot's)
@pytest.fixture
def as_large(monkeypatch):
    """Every loop taken as large: called from MX graphs (with jit, from its loop library), its h
    rates from differences and its clock guards split off, as a robot's loop is."""
    from mpgspec.oracle import integrator, looplib

    monkeypatch.setattr(looplib, "INLINE_NODES", 0)
    monkeypatch.setattr(integrator, "INLINE_NODES", 0)


@pytest.mark.parametrize("error", ERRORS)
@pytest.mark.parametrize("on, ts", [("state", 0.5031), ("state", 0.5 + 0.3 * MIN_PIECE), ("clock", 0.5031),
                                    ("clock", 0.5)])
def test_a_large_loop_is_stepped_piece_by_piece(tmp_path, as_large, on, ts, error):
    """The known answers of test_a_law_that_switches_inside_a_step_is_judged_on_each_branch through
    the large loop's steps: a switch inside a step (located), one closer than MIN_PIECE after a
    step's start (stepped over by a sliver, found by one short trial), and a clock switch on a
    step's start (t* = 0.5 = 50 dt: met by starting the step there on the new branch), each judged
    right to the true margin of 3e-5 (the differences of a large loop's h rates are good to about
    1e-6)."""
    from mpgspec.oracle.looplib import is_large

    law = f"if_else(x < {ts!r}, 1, 3)" if on == "state" else f"if_else(t < {ts!r}, 1, 3)"
    x_T = ts + 3 * (0.6 - ts)
    s = OracleSettings.with_accuracy("medium", horizon=3.0, dt=0.01, error=error, jit=False)
    prim = _switching(tmp_path, law, x_T - 3e-5)
    assert is_large(prim) and guarded(prim)
    e = SafetyOracle(prim, s)(np.array([0.0]), 0.0)
    assert e.status != "safe" and e.violated == "cap", e
    assert e.lower_bounds["cap"] == pytest.approx(-3e-5, abs=2e-6)
    e = SafetyOracle(_switching(tmp_path, law, x_T + 3e-5), s)(np.array([0.0]), 0.0)
    assert e.status == "safe", e
    assert e.lower_bounds["cap"] == pytest.approx(3e-5, abs=2e-6)


@pytest.mark.parametrize("error", ERRORS)
def test_a_large_loop_through_its_library_judges_a_saturation_kink(tmp_path, as_large, error):
    """The saturation kink's known answer with jit: the large loop's rate and guards come from its
    compiled loop library (part "loop_g")."""
    from mpgspec.oracle.looplib import part

    tk = 0.3963
    x_T = 2 - math.exp(-4 * (0.6 - tk)) / 4
    s = OracleSettings.with_accuracy("very_high", horizon=3.0, dt=0.01, error=error, jit=True)
    for c, truth in ((x_T - 1e-6, "unsafe"), (x_T + 1e-6, "safe")):
        prim = _switching(tmp_path, "clip(-4*(x - 2), -1, 1)", c)
        e = SafetyOracle(prim, s)(np.array([1.75 - tk]), 0.0)
        assert part(prim, "loop_g") is not None
        assert (e.status == "safe") == (truth == "safe"), e


@pytest.mark.parametrize("width", [1e-5, 0.3 * MIN_PIECE])
def test_a_large_loop_ends_its_steps_on_both_edges_of_a_clock_pulse(tmp_path, as_large, width):
    """A large loop cuts its steps where a clock guard crosses (the guards of t alone, bisected
    without evaluating the loop): a kick of area 0.2 narrower than MIN_PIECE is then a step of its
    own and integrated exactly, x(T) = 0.8, judged right on both sides of it."""
    law = f"1 + {0.2 / width!r}*(if_else(t > 0.2537, 1, 0) - if_else(t > {0.2537 + width!r}, 1, 0))"
    prim = _switching(tmp_path, law, 0.8)
    assert len(prim.guards) == 2  # the two edges print alike and are two guards
    for error in ERRORS:
        s = OracleSettings.with_accuracy("medium", horizon=3.0, dt=0.01, error=error, jit=False)
        for c in (0.8 - 1e-3, 0.8 + 1e-3):
            e = SafetyOracle(_switching(tmp_path, law, c), s)(np.array([0.0]), 0.0)
            assert (e.status == "safe") == (c > 0.8), (error, c, e)


@pytest.mark.parametrize("error", ERRORS)
@pytest.mark.parametrize("T", [0.6, 0.7])
def test_a_large_loop_takes_a_switch_read_snap_early_at_the_step_that_ends_on_it(tmp_path, as_large, error, T):
    """A law that reads the clock SNAP (1e-9 s) ahead, as a contact schedule's mode does, switches
    at C's window edge T, where steps end (a clock summed from steps of 0.01 ends within rounding
    of T): the step ending there takes its last stage inside and is not cut 1e-9 s early (which
    cost a piece of 1e-9 s after it and dropped that much of the flow), so the rollout is the one
    of the law switching on the edge itself: the same steps and margins, judged right to 3e-5
    (x(T) = T)."""
    from mpgspec.compile.contacts import SNAP

    s = OracleSettings.with_accuracy("medium", horizon=3.0, dt=0.01, error=error, jit=False)
    seen = {}
    for law in (f"if_else(t + {SNAP!r} < {T!r}, 1, 3)", f"if_else(t < {T!r}, 1, 3)"):
        for off in (-3e-5, 3e-5):
            e = SafetyOracle(_switching(tmp_path, law, T + off, T=T), s)(np.array([0.0]), 0.0)
            assert (e.status == "safe") == (off > 0), (law, e)
            seen.setdefault(off, []).append((e.steps, e.lower_bounds["cap"]))
    for off, ((n1, m1), (n2, m2)) in seen.items():
        assert n1 == n2 and m1 == pytest.approx(m2, abs=1e-12) and m1 == pytest.approx(off, abs=2e-6), seen


@pytest.mark.parametrize("before", [1e-13, 5e-10])
def test_a_companion_crossing_right_after_its_start_takes_a_sliver_not_the_whole_step(tmp_path, before):
    """Under step doubling the companion trails the judged rollout by its error: where the judged one
    starts a step on a guard, the companion's crossing lies just after its start. x' = 1 until x = 0.5,
    then 3, from `before` seconds short of the switch: the step of 10 ms ends at 0.5 + 3 (0.01 - before)
    and the error it adds is a sliver's (its length times the jump of 2 in the rate), not the whole
    step's 0.02."""
    from mpgspec.oracle.pieces import _Parts, _split

    prim = _switching(tmp_path, "if_else(x < 0.5, 1, 3)", 10.0)
    parts = _Parts(prim)
    x0, h = np.array([0.5 - before]), 0.01
    k1, r, _on, _e = parts.nudged(ca.DM(x0), 0.0, 0.0, ca.DM(x0), h)
    x_end, extra, extra_h = (float(v) for v in _split(parts)(1, x0, 0.0, 0.0, x0, k1, h, h, x0, r))
    assert abs(x_end - (0.5 + 3 * (h - before))) <= extra + 1e-12 and extra < 1e-8  # the sliver's bound covers it
    assert extra_h == pytest.approx(extra)  # h = c - x moves with x
