"""Soundness of the default rk4 safety oracle on the pendulum example, against an independent reference.

The reference below does not use mpgspec's compiled functions: the pendulum's closed loops
(specs/pendulum/system.yaml and primitives/*.yaml: PD with feedforward for Hang, Swing(amp) and
SwingUp, LQR for Balance, torque saturation at +-7, the safety functions and E as a Euclidean ball)
are written out in plain Python and integrated with scipy's DOP853 (rtol 1e-10, atol 1e-12). The
dense solution is scanned on a 0.2 ms grid: the reference verdict is 1 when the flow is inside E
before any h < -1e-9 (Definition 4).

Start points follow Algorithm 1: the setpoints of the other primitives at random clock times, most
with a random perturbation, switched in at a random t_B (half of them phase-matched to the target's
setpoint). The oracle must never call a start point safe that the reference finds unsafe, and must
agree with it on (nearly) every verdict, so it cannot pass by answering 0 everywhere.
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import yaml
from scipy.integrate import solve_ivp

from mpgspec.api import compile_project, settings_for
from mpgspec.oracle import Reason, SafetyOracle
from mpgspec.spec.loader import load_project

ROOT = Path(__file__).parents[2]
PROJECT = ROOT / "specs" / "pendulum" / "project.yaml"
N_POINTS = 480
N_SCIPY_PER_TARGET = 12
H_EPS = 1e-9

# ----------------------------------------------------------------------------- the pendulum, by hand
M, L, G, B = 1.0, 1.0, 9.81, 0.1  # system.yaml
U_MAX = 7.0
SPEED_LIMIT = 9.0
A0, T1 = 2.6, 1.5  # SwingUp: cubic from the crest of Swing(2.6) to the upright in 1.5 s
RADIUS = {"Hang": 0.15, "Swing": 0.15, "SwingUp": 0.1, "Balance": 0.2}


def lqr_gain() -> np.ndarray:
    """Balance: continuous-time LQR at theta = pi, Q = diag(10, 1), R = 0.1."""
    A = np.array([[0.0, 1.0], [G / L * 1.0, -B / (M * L * L)]])  # d/dtheta of -g/l sin(theta) at pi is +g/l
    Bm = np.array([[0.0], [1.0 / (M * L * L)]])
    R = np.array([[0.1]])
    P = scipy.linalg.solve_continuous_are(A, Bm, np.diag([10.0, 1.0]), R)
    return np.linalg.solve(R, Bm.T @ P).ravel()


K_LQR = lqr_gain()


def swing_frequency(amp: float) -> float:
    return math.sqrt(G / L * math.sin(amp * 0.8) / (amp * 0.8))


class Reference:
    """Closed loop, safety functions and E of one pendulum primitive, in plain Python."""

    def __init__(self, name: str):
        self.name = name
        self.kind = name.split("(")[0]
        if self.kind == "Swing":
            self.amp = float(name[6:-1])
            self.w = swing_frequency(self.amp)
        self.radius = RADIUS[self.kind]

    def setpoint(self, t: float) -> tuple[float, float, float]:
        """theta*, omega*, d omega*/dt."""
        if self.kind == "Hang":
            return 0.0, 0.0, 0.0
        if self.kind == "Balance":
            return math.pi, 0.0, 0.0
        if self.kind == "SwingUp":
            if t >= T1:
                return math.pi, 0.0, 0.0
            q, d = t / T1, math.pi - A0
            return (A0 + d * (3 * q * q - 2 * q ** 3), d * (6 * t / T1 ** 2 - 6 * t * t / T1 ** 3),
                    d * (6 / T1 ** 2 - 12 * t / T1 ** 3))
        a, w = self.amp, self.w
        return a * math.sin(w * t), a * w * math.cos(w * t), -a * w * w * math.sin(w * t)

    def control(self, th: float, om: float, t: float) -> float:
        ts, ws, wds = self.setpoint(t)
        if self.kind == "Hang":
            return -4.0 * th - 2.0 * om
        if self.kind == "Balance":
            return -(K_LQR[0] * (th - math.pi) + K_LQR[1] * om)
        kp, kd = (16.0, 6.0) if self.kind == "Swing" else (25.0, 8.0)
        feedforward = M * L * L * wds + M * G * L * math.sin(th) + B * om
        return -kp * (th - ts) - kd * (om - ws) + feedforward

    def rhs(self, t: float, x) -> list[float]:
        th, om = x
        u = min(max(self.control(th, om, t), -U_MAX), U_MAX)
        return [om, (-M * G * L * math.sin(th) - B * om + u) / (M * L * L)]

    def h(self, th: float, om: float, t: float) -> dict[str, float]:
        out = {"speed_limit": SPEED_LIMIT - abs(om)}
        if self.kind == "Swing":
            out["track_band"] = 1.2 - abs(th - self.setpoint(t)[0])
        elif self.kind == "SwingUp":
            out["track_band"] = 0.5 - abs(th - self.setpoint(t)[0])
        elif self.kind == "Balance":
            out["upright_cone"] = 1.0 - abs(th - math.pi)
        return out

    def margin(self, th: float, om: float, t: float) -> float:
        ts, ws, _ = self.setpoint(t)
        return self.radius - math.hypot(th - ts, om - ws)

    def verdict(self, x0, t0: float, horizon: float, grid: float = 2e-4, segment: float = 0.5):
        """(verdict, reason, time, violated h) of Definition 4 from x0 at clock t0."""
        x, s0 = np.asarray(x0, float), 0.0
        while s0 < horizon - 1e-12:
            s1 = min(horizon, s0 + segment)
            sol = solve_ivp(lambda s, y: self.rhs(t0 + s, y), (s0, s1), x, method="DOP853",
                            rtol=1e-10, atol=1e-12, dense_output=True)
            assert sol.success, sol.message
            ss = np.linspace(s0, s1, max(2, int(round((s1 - s0) / grid)) + 1))
            Y = sol.sol(ss)
            for k in range(0 if s0 == 0 else 1, len(ss)):
                th, om, t = Y[0, k], Y[1, k], t0 + ss[k]
                hs = self.h(th, om, t)
                worst = min(hs, key=hs.get)
                if hs[worst] < -H_EPS:
                    return 0, "left_C", float(ss[k]), worst
                if self.margin(th, om, t) > 0:
                    return 1, "entered_E", float(ss[k]), None
            x, s0 = sol.y[:, -1], s1
        return 0, "horizon_reached", horizon, None


# ----------------------------------------------------------------------------- the experiment
def clock_range(p, role: str) -> tuple[float, float]:
    if p.cls.value == "fixed":
        return 0.0, 0.0
    if p.cls.value == "periodic":
        return 0.0, float(p.period)
    a, b = p.domain
    return (a, b) if role == "A" else (a, b - 0.1)  # as a target, leave it some time to converge


@pytest.fixture(scope="module")
def pendulum():
    spec = load_project(PROJECT)
    return spec, compile_project(spec), settings_for(spec)


@pytest.fixture(scope="module")
def experiment(pendulum):
    spec, prims, settings = pendulum
    rng = np.random.default_rng(20240611)
    names = list(prims)
    starts: dict[str, list] = {b: [] for b in names}
    for k in range(N_POINTS):
        b = names[k % len(names)]
        a = str(rng.choice([n for n in names if n != b]))
        x0 = prims[a].x_star(rng.uniform(*clock_range(prims[a], "A")))
        if rng.random() < 0.7:
            x0 = x0 + rng.normal(0.0, [0.1, 0.3])
        lo, hi = clock_range(prims[b], "B")
        if hi > lo and rng.random() < 0.5:  # switch in near the closest point of B's setpoint
            cand = np.linspace(lo, hi, 200, endpoint=False)
            best = cand[int(np.argmin([np.linalg.norm(prims[b].x_star(c) - x0) for c in cand]))]
            t_B = float(np.clip(best + rng.normal(0.0, 0.05), lo, hi))
        else:
            t_B = float(rng.uniform(lo, hi))
        starts[b].append((x0, t_B))
    rows = []
    for b in names:
        oracle = SafetyOracle(prims[b], settings)
        X = np.array([x for x, _ in starts[b]])
        T = np.array([t for _, t in starts[b]])
        ref = Reference(b)
        for (x0, t_B), e, horizon in zip(starts[b], oracle.evaluate(X, T), oracle.horizons(T)):
            rows.append({"target": b, "x0": x0, "t_B": t_B, "horizon": float(horizon), "rk4": e,
                         "ref": ref.verdict(x0, t_B, float(horizon))})
    return rows


def describe(row) -> str:
    e = row["rk4"]
    return (f"{row['target']} x0={np.round(row['x0'], 4).tolist()} t_B={row['t_B']:.4f}: rk4 {e.verdict} "
            f"{e.reason.value} at {e.t_stop:.4f} ({e.violated}); reference {row['ref']}")


# ----------------------------------------------------------------------------- the reference is the pendulum
def test_reference_constants_match_the_example_spec(pendulum):
    """Guard: if the example spec changes, the hand-written reference above must change with it."""
    folder = PROJECT.parent
    system = yaml.safe_load((folder / "system.yaml").read_text())
    assert system["parameters"] == {"m": M, "l": L, "g": G, "b": B}
    assert system["input_bounds"] == {"tau": [-U_MAX, U_MAX]}
    assert system["dynamics"] == {"f": ["omega", "-g/l*sin(theta) - b/(m*l^2)*omega"], "g": [[0], ["1/(m*l^2)"]]}
    prim = {p: yaml.safe_load((folder / "primitives" / f"{p}.yaml").read_text())
            for p in ("hang", "swing", "swing_up", "balance")}
    assert prim["hang"]["controller"] == {"type": "pd", "outputs": ["theta"], "kp": [4], "kd": [2]}
    assert (prim["swing"]["controller"]["kp"], prim["swing"]["controller"]["kd"]) == ([16], [6])
    assert (prim["swing_up"]["controller"]["kp"], prim["swing_up"]["controller"]["kd"]) == ([25], [8])
    assert prim["swing"]["let"]["w"] == "sqrt(g/l * sin(amp*0.8)/(amp*0.8))"
    assert prim["swing_up"]["let"] == {"a0": A0, "T1": T1} and prim["swing_up"]["domain"] == [0, T1]
    assert prim["balance"]["controller"] == {"type": "lqr", "Q": [10, 1], "R": [0.1]}
    for p, kind in (("hang", "Hang"), ("swing", "Swing"), ("swing_up", "SwingUp"), ("balance", "Balance")):
        roa = prim[p]["roa"]  # E is a Euclidean ball of the given radius (a verifier may size it later)
        assert roa["radius"] == RADIUS[kind] and "weights" not in roa and "matrix" not in roa
    project = yaml.safe_load(PROJECT.read_text())
    assert project["safe_sets"]["speed_limit"] == [{"name": "speed_limit", "h": "9 - abs(omega)"}]
    _, prims, _ = pendulum
    np.testing.assert_allclose(prims["Balance"].info["lqr"]["K"], [K_LQR], rtol=1e-8)


def test_reference_closed_loops_match_the_compiled_ones(pendulum):
    """Spot check of the two implementations at random states, before comparing their verdicts."""
    _, prims, _ = pendulum
    rng = np.random.default_rng(7)
    for name, p in prims.items():
        ref = Reference(name)
        for _ in range(20):
            x = rng.uniform([-3.5, -8.0], [3.5, 8.0])
            t = rng.uniform(0.0, 1.5)
            np.testing.assert_allclose(np.array(p.f_cl(x, t, 10.0, x)).ravel(), ref.rhs(t, x), rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(np.array(p.h(x, t, 10.0, x)).ravel(), list(ref.h(*x, t).values()), atol=1e-9)
            assert float(p.roa_margin(x, t)) == pytest.approx(ref.margin(*x, t), abs=1e-9)


# ----------------------------------------------------------------------------- soundness and tightness
def test_no_safe_verdict_is_contradicted(experiment):
    ones = [r for r in experiment if r["rk4"].verdict == 1]
    assert len(ones) >= 0.2 * len(experiment), "too few safe verdicts to say anything"
    assert {r["target"] for r in ones} == {r["target"] for r in experiment}, "some target never verified safe"
    wrong = [describe(r) for r in ones if r["ref"][0] != 1]
    assert not wrong, f"{len(wrong)} rk4 'safe' verdicts are unsafe by the reference:\n" + "\n".join(wrong)


def test_verdicts_agree_with_the_reference(experiment):
    agree = [r["rk4"].verdict == r["ref"][0] for r in experiment]
    rate = sum(agree) / len(agree)
    by_target = Counter((r["target"], r["rk4"].verdict) for r in experiment)
    print(f"rk4 vs reference: {rate:.1%} of {len(agree)} verdicts agree; {dict(by_target)}")
    assert rate >= 0.9, "\n".join(describe(r) for r, ok in zip(experiment, agree) if not ok)


def test_evidence_agrees_with_the_reference(experiment, pendulum):
    """Where both say 1, rk4's t_enter is the first step after the true entry; where both say left_C,
    they name the same safety function (almost always: near-simultaneous violations may differ)."""
    dt = pendulum[2].dt
    both_safe = [r for r in experiment if r["rk4"].verdict == 1 and r["ref"][0] == 1]
    for r in both_safe:
        assert r["rk4"].reason is Reason.ENTERED_E
        assert -1e-3 <= r["rk4"].t_enter - r["ref"][2] <= dt + 1e-3, describe(r)
    both_left = [r for r in experiment if r["rk4"].reason is Reason.LEFT_C and r["ref"][1] == "left_C"]
    same = sum(r["rk4"].violated == r["ref"][3] for r in both_left)
    assert same >= 0.9 * len(both_left)
    for r in both_left:
        assert abs(r["rk4"].t_stop - r["ref"][2]) <= dt + 1e-3, describe(r)


def test_rk4_agrees_with_the_scipy_backend(experiment, pendulum):
    _, prims, settings = pendulum
    dt = settings.dt
    mismatches, compared = [], 0
    for b, p in prims.items():
        rows = [r for r in experiment if r["target"] == b][:N_SCIPY_PER_TARGET]
        oracle = SafetyOracle(p, settings.replace(method="scipy"))
        ev = oracle.evaluate(np.array([r["x0"] for r in rows]), np.array([r["t_B"] for r in rows]))
        for r, e in zip(rows, ev):
            compared += 1
            if (e.verdict, e.reason) != (r["rk4"].verdict, r["rk4"].reason):
                mismatches.append(f"{describe(r)}; scipy {e.verdict} {e.reason.value} at {e.t_stop:.4f}")
            elif e.verdict == 1:
                assert -1e-3 <= r["rk4"].t_enter - e.t_enter <= dt + 1e-3, describe(r)
    assert compared == N_SCIPY_PER_TARGET * len(prims)
    assert len(mismatches) <= 0.05 * compared, "\n".join(mismatches)
