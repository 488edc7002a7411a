"""Exact answers of the safety oracle (Definition 4) on the ladder project (specs/ladder).

Every primitive of the ladder is PD on p with the setpoint's acceleration as feedforward and no
input bound, so the error e = x - x_B*(t) of B's closed loop obeys e' = A_cl e with
A_cl = [[0, 1], [-kp, -kd]] (the gains read from the spec), and the flow switched into B at x0,
clock t_B is x(s) = x_B*(t_B + s) + expm(A_cl s) (x0 - x_B*(t_B)), the exponential of the 2 x 2
matrix in closed form (`expm2`). The safety functions, the setpoint and E's margin are the compiled
CasADi Functions (prim.h, prim.setpoint, prim.roa_margin), evaluated on that closed form.

Times are found on a 1 ms grid of the closed form and refined: each first crossing by Brent's
root finder (xtol 1e-13), each sampled local extremum (which also catches a dip between samples)
by a bounded scalar minimisation (xatol 1e-12). Nothing is integrated; the answers are exact to
about 1e-10 for loops whose rates are far below 1 kHz, as the ladder's are.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import brentq, minimize_scalar

SAMPLE = 1e-3  # s: grid of the closed form before refinement
XTOL = 1e-13  # s: root bracket width
XATOL = 1e-12  # s: extremum location


@dataclass(frozen=True)
class Truth:
    """Definition 4 for one cell (A, t_A, B, t_B).

    verdict: 1 when the flow enters E_B no later than the horizon with every h_B >= 0 until then.
    t_enter: first time inside E_B (None: not within the horizon). t_violation, violated: the first
    time some h_B < 0 before that (or before the horizon) and which. margins: the least value of
    each h_B over [0, t_enter] (over [0, horizon] when E is not entered).
    """

    verdict: int
    t_enter: float | None
    t_violation: float | None
    violated: str | None
    margins: dict[str, float]
    horizon: float

    @property
    def margin(self) -> float:
        return min(self.margins.values())

    @property
    def t_stop(self) -> float:
        """Where the oracle stops: at the entry when safe, else at the violation, else at the horizon."""
        if self.verdict:
            return self.t_enter
        return self.t_violation if self.t_violation is not None else self.horizon


def closed_loop_matrix(kp: float, kd: float) -> np.ndarray:
    """A_cl of the error dynamics e'' = -kp e - kd e'."""
    return np.array([[0.0, 1.0], [-float(kp), -float(kd)]])


def expm2(A: np.ndarray, s) -> np.ndarray:
    """expm(A s) of a 2 x 2 matrix A for every s, (len(s), 2, 2): with M = A - tr(A)/2 I, M^2 = q^2 I
    (q^2 = tr(A)^2/4 - det(A)), so expm(A s) = e^(tr(A) s/2) (cosh(q s) I + sinh(q s)/q M)."""
    s = np.atleast_1d(np.asarray(s, float))
    half = np.trace(A) / 2
    M = A - half * np.eye(2)
    q2 = half ** 2 - (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0])
    if q2 == 0:
        c, f = np.ones_like(s), s
    else:
        q = np.sqrt(complex(q2))
        c, f = np.cosh(q * s).real, (np.sinh(q * s) / q).real
    return np.exp(half * s)[:, None, None] * (c[:, None, None] * np.eye(2) + f[:, None, None] * M)


def gains(spec) -> dict[str, np.ndarray]:
    """A_cl of every node of a loaded ladder project, from its PD controller's kp and kd."""
    out = {}
    for inst in spec.primitives:
        c = inst.spec.controller
        if c.type != "pd" or list(c.outputs) != ["p"]:
            raise ValueError(f"{inst.name}: the ladder's truth needs PD on p, got {c.type} on {c.outputs}")
        out[inst.name] = closed_loop_matrix(c.kp[0], c.kd[0])
    return out


class Flow:
    """B's closed loop switched in at x0 and clock t_B, in closed form over [0, T]."""

    def __init__(self, prim, A: np.ndarray, x0, t_b: float, T: float):
        self.prim, self.A, self.t_b, self.T = prim, A, float(t_b), float(T)
        self.x0 = np.asarray(x0, float).ravel()
        self.e0 = self.x0 - self._setpoint(np.array([self.t_b]))[:, 0]
        self.s = np.linspace(0.0, self.T, int(np.ceil(self.T / SAMPLE)) + 1)
        self.h_s = self.h(self.s)
        self.m_s = self.roa(self.s)

    def _setpoint(self, t: np.ndarray) -> np.ndarray:
        return np.array(self.prim.setpoint.map(t.size)(t[None, :]), float).reshape(-1, t.size)

    def x(self, s) -> np.ndarray:
        """x(s) as (nx, len(s))."""
        s = np.atleast_1d(np.asarray(s, float))
        e = expm2(self.A, s) @ self.e0
        return self._setpoint(self.t_b + s) + e.T

    def h(self, s) -> np.ndarray:
        """Every h_B along the flow, (nh, len(s))."""
        s = np.atleast_1d(np.asarray(s, float))
        n, x = s.size, self.x(s)
        out = self.prim.h.map(n)(x, (self.t_b + s)[None, :], s[None, :], np.repeat(self.x0[:, None], n, axis=1))
        return np.array(out, float).reshape(-1, n)

    def roa(self, s) -> np.ndarray:
        """E_B's margin r - ||x - x_B*||_W along the flow (> 0 inside E)."""
        s = np.atleast_1d(np.asarray(s, float))
        return np.array(self.prim.roa_margin.map(s.size)(self.x(s), (self.t_b + s)[None, :]), float).ravel()

    def _window(self, values: np.ndarray, f, t_end: float) -> tuple[np.ndarray, np.ndarray]:
        """The grid samples before t_end and t_end itself, with the values there."""
        k = int(np.searchsorted(self.s, t_end, side="left"))
        return np.r_[self.s[:k], t_end], np.r_[values[:k], f(t_end)]

    def _first_positive(self, g, g_s: np.ndarray, t_end: float) -> float | None:
        """First s in [0, t_end] with g(s) > 0: a sampled sign change, or a bump between samples found
        by maximising g about each sampled local maximum before it."""
        s, v = self._window(g_s, g, t_end)
        if v[0] > 0:
            return 0.0
        pos = np.flatnonzero(v > 0)
        stop = pos[0] if pos.size else v.size
        for j in _local_extrema(v[:stop], -1):
            lo, hi = s[max(j - 1, 0)], s[min(j + 1, v.size - 1)]
            r = minimize_scalar(lambda t: -g(t), bounds=(lo, hi), method="bounded", options={"xatol": XATOL})
            if -r.fun > 0:
                return float(brentq(g, lo, r.x, xtol=XTOL))
        return float(brentq(g, s[stop - 1], s[stop], xtol=XTOL)) if pos.size else None

    def entry(self) -> float | None:
        """First time inside E_B within the horizon."""
        return self._first_positive(lambda t: float(self.roa(t)[0]), self.m_s, self.T)

    def violation(self, k: int, t_end: float) -> float | None:
        """First time h_k < 0 in [0, t_end]."""
        return self._first_positive(lambda t: -float(self.h(t)[k, 0]), -self.h_s[k], t_end)

    def least(self, k: int, t_end: float) -> float:
        """Least value of h_k over [0, t_end]."""
        f = lambda t: float(self.h(t)[k, 0])  # noqa: E731
        s, v = self._window(self.h_s[k], f, t_end)
        best = float(v.min())
        for j in _local_extrema(v, 1):
            lo, hi = s[max(j - 1, 0)], s[min(j + 1, v.size - 1)]
            if hi > lo:
                r = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": XATOL})
                best = min(best, float(r.fun))
        return best


def _local_extrema(v: np.ndarray, sign: int) -> np.ndarray:
    """Indices of sampled local minima (sign 1) or maxima (sign -1), ends included."""
    if v.size < 2:
        return np.arange(v.size)
    w = sign * v
    left = np.r_[True, w[1:] <= w[:-1]]
    right = np.r_[w[:-1] <= w[1:], True]
    return np.flatnonzero(left & right)


class Ladder:
    """The closed-form oracle of a compiled ladder project."""

    def __init__(self, spec, prims: dict):
        self.spec, self.prims, self.A = spec, prims, gains(spec)

    @classmethod
    def load(cls, path: str | Path) -> "Ladder":
        from mpgspec.pipeline.stages import compile_project
        from mpgspec.spec.loader import load_project

        spec = load_project(Path(path))
        return cls(spec, compile_project(spec))

    def flow(self, a: str, t_a: float, b: str, t_b: float, horizon: float) -> Flow:
        """B's flow from x_A*(t_A) switched in at t_B, over [0, horizon]."""
        return Flow(self.prims[b], self.A[b], self.prims[a].x_star(float(t_a)), t_b, horizon)

    def cell(self, a: str, t_a: float, b: str, t_b: float, horizon: float) -> Truth:
        """Definition 4's answer for switching from A at t_A into B at t_B."""
        fl = self.flow(a, t_a, b, t_b, horizon)
        names = self.prims[b].h_names
        t_enter = fl.entry()
        t_end = fl.T if t_enter is None else t_enter
        margins = {n: fl.least(k, t_end) for k, n in enumerate(names)}
        hits = [(t, n) for k, n in enumerate(names) if (t := fl.violation(k, t_end)) is not None]
        t_violation, violated = min(hits) if hits else (None, None)
        verdict = int(t_enter is not None and min(margins.values()) >= 0)
        return Truth(verdict, t_enter, t_violation, violated, margins, fl.T)
