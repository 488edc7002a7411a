"""Certified quadratic Lyapunov level sets of non-polynomial closed loops by interval branch-and-bound.

For V(y) = y'Py (y = x - x*) and a level rho, boxes covering {V <= rho} are evaluated in arb ball
arithmetic on the closed loop's operation sequence (mpgspec.validated.tape), its non-smooth
operations as sound hulls. A box is dropped when V > rho on it, proved when every safety function
is > 0 on it and Vdot = 2 y'P f(x* + y) < 0 on it, and otherwise split in two, up to a budget of
boxes; the widest boxes go first, so a centre that breaks the level is met early. Vdot's upper
bound is the better of the plain interval one and the mean-value form (its gradient from jets
over the box, where every branch of the loop is fixed).

A box that holds x* is proved by the mean-value form around x*: f(x* + y) = f(x*) + J y with J in
the interval Jacobian of the box, so Vdot <= 2 |P f(x*)| |y| - mu |y|^2 when -(PJ + J'P) - mu I is
positive definite for every such J (Cholesky in ball arithmetic). That leaves out only the ball
|y| <= eps = 2 |P f(x*)| / mu, where f(x*), the rounding of the equilibrium, is enclosed in arb.

A success proves: h > 0 on {V <= rho} (so it lies in C), and Vdot < 0 on {V <= rho} outside
|y| <= eps; so {V <= rho} is forward invariant and every flow from it converges to
{V <= lambda_max(P) eps^2} (x* itself when f(x*) = 0).
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import casadi as ca
import numpy as np
from flint import arb, arb_mat

from mpgspec.validated.jet import Jet
from mpgspec.validated.tape import Tape, TapeError

from .roa_common import ball_radius

ZERO = arb(0)
MIN_WIDTH = 1e-12
"""Narrowest box, relative to the cover of the level set, before the level is given up."""
LEVELS = (1.0, 0.9, 0.75, 0.5, 0.25)
"""Fractions of the estimated level tried in turn, largest first."""


@dataclass
class BoxProof:
    """The outcome of the branch-and-bound at one level rho."""

    ok: bool
    rho: float
    boxes: int = 0
    proved: int = 0
    dropped: int = 0
    inner: int = 0
    eps: float = 0.0
    mu: float = float("inf")
    depth: int = 0
    seconds: float = 0.0
    reason: str = ""
    counterexample: list | None = None
    parts: tuple = ()

    def to_dict(self) -> dict:
        d = {"ok": self.ok, "rho": self.rho, "boxes": self.boxes, "proved": self.proved, "dropped": self.dropped,
             "boxes_holding_x_star": self.inner, "exceptional_radius": self.eps, "depth": self.depth,
             "time_s": self.seconds, "parts": list(self.parts)}
        if np.isfinite(self.mu):
            d["least_mu"] = self.mu
        if self.reason:
            d["reason"] = self.reason
        if self.counterexample is not None:
            d["counterexample_y"] = self.counterexample
        return d


def tapes(f: ca.Function, h: ca.Function | None) -> tuple[Tape, Tape | None] | str:
    """The tapes of the closed loop and the safety functions, or why they cannot be read."""
    try:
        return Tape.of(f), (Tape.of(h) if h is not None and h.nnz_out(0) else None)
    except TapeError as e:
        return f"no interval enclosure of the closed loop: {e}"


def certainly_pd(M: list[list[arb]]) -> bool:
    """Whether every symmetric matrix in the ball matrix M (lower triangle read) is positive definite:
    Cholesky in ball arithmetic with every pivot certainly > 0."""
    n = len(M)
    L = [[ZERO] * n for _ in range(n)]
    for j in range(n):
        d = M[j][j] - sum((L[j][k] * L[j][k] for k in range(j)), ZERO)
        if not d > 0:
            return False
        L[j][j] = d.sqrt()
        for i in range(j + 1, n):
            L[i][j] = (M[i][j] - sum((L[i][k] * L[j][k] for k in range(j)), ZERO)) / L[j][j]
    return True


def inscribed_radius(P: np.ndarray, rho: float, W: np.ndarray) -> float:
    """A radius r with {y'Wy < r^2} inside {y'Py <= rho} (P symmetric), checked in ball arithmetic
    (rho W - r^2 P > 0); 0 when no check passes."""
    if not np.array_equal(P, np.transpose(P)):
        return 0.0
    r = ball_radius(P, rho, W)
    n = len(P)
    for shrink in (1 - 1e-9, 1 - 1e-6, 1 - 1e-3):
        r2 = arb(r * shrink) ** 2
        M = [[arb(rho) * (arb(float(W[i, j])) + arb(float(W[j, i]))) / 2 - r2 * arb(float(P[i, j]))
              for j in range(n)] for i in range(n)]
        if certainly_pd(M):
            return r * shrink
    return 0.0


def cover(P: np.ndarray, rho: float) -> np.ndarray:
    """Half-widths R with {y'Py <= rho} inside the box |y_i| <= R_i (R_i^2 >= rho (P^-1)_ii, in arb)."""
    Pi = arb_mat([[float(v) for v in row] for row in P]).inv()
    n = len(P)
    return np.array([float((arb(rho) * Pi[i, i]).sqrt().upper()) * (1 + 1e-6) for i in range(n)])


class LevelProver:
    """Vdot < 0 and h > 0 on {V <= rho} for V = y'Py around x*, by branch-and-bound over boxes."""

    def __init__(self, f_tape: Tape, h_tape: Tape | None, x_star: np.ndarray, P: np.ndarray,
                 prove_vdot: bool = True, h_rows: list[int] | None = None):
        """h_rows: the safety functions to prove > 0 (all when None)."""
        self.f, self.vdot = f_tape, prove_vdot
        rows = range(h_tape.out_sizes[0]) if h_tape is not None and h_rows is None else (h_rows or [])
        self.rows = list(rows) if h_tape is not None else []
        self.h = h_tape if self.rows else None
        self.xs = np.asarray(x_star, float).ravel()
        self.n = len(self.xs)
        self.P = np.asarray(P, float)
        self.Pa = [[arb(float(v)) for v in row] for row in self.P]
        self.X0 = [arb(float(v)) for v in self.xs]
        self.Pf0 = self._norm_Pf0()

    def _norm_Pf0(self) -> arb:
        """An enclosure of |P f(x*)|_2, the rounding of the equilibrium."""
        f0 = self.f([self.X0])[0][0]
        v = [sum((self.Pa[i][j] * f0[j] for j in range(self.n)), ZERO) for i in range(self.n)]
        u = [vi.abs_upper() for vi in v]
        return sum((ui * ui for ui in u), ZERO).sqrt()

    def prove(self, rho: float, budget: int = 50_000) -> BoxProof:
        """Branch-and-bound at level rho with at most `budget` boxes."""
        t0 = time.perf_counter()
        n, parts = self.n, (("Vdot",) if self.vdot else ()) + (("h",) if self.h is not None else ())
        res = BoxProof(False, float(rho), parts=parts)
        if not (np.isfinite(rho) and rho > 0 and np.array_equal(self.P, self.P.T) and certainly_pd(self.Pa)):
            res.reason = "the level must be > 0 and P symmetric and certainly positive definite"
            return res
        R = cover(self.P, rho)
        queue = deque([(np.zeros(n), R.copy(), 0)])
        rho_a = arb(rho)
        while queue:
            if res.boxes >= budget:
                res.reason = f"box budget {budget} exhausted with {len(queue)} boxes open"
                break
            c, w, depth = queue.popleft()
            res.boxes += 1
            res.depth = max(res.depth, depth)
            verdict = self._box(c, w, rho_a, res)
            if verdict == "dropped":
                res.dropped += 1
            elif verdict == "proved":
                res.proved += 1
            else:
                bad = self._counterexample(c, rho_a)
                if bad:
                    res.reason, res.counterexample = bad, c.tolist()
                    break
                k = int(np.argmax(w / R))
                if w[k] < MIN_WIDTH * R[k]:
                    res.reason = f"undecided on a box of relative width {MIN_WIDTH:g} at y = {np.round(c, 6).tolist()}"
                    break
                half = w.copy()
                half[k] = 0.5 * w[k]
                for s in (-1.0, 1.0):
                    cc = c.copy()
                    cc[k] = c[k] + s * half[k]
                    queue.append((cc, half, depth + 1))
        else:
            res.ok = True
        res.seconds = time.perf_counter() - t0
        return res

    def _balls(self, c: np.ndarray, w: np.ndarray) -> tuple[list[arb], list[arb]]:
        Y = [arb(float(ci), float(wi)) for ci, wi in zip(c, w)]
        return Y, [x0 + y for x0, y in zip(self.X0, Y)]

    def _v_lower_exceeds(self, c: np.ndarray, w: np.ndarray, Y: list[arb], rho: arb) -> bool:
        """Whether V > rho on the box: centred form V(c) + 2 (Pc)'d + d'Pd >= V(c) + 2 (Pc)'d, and
        the plain interval form with squares taken >= 0."""
        n, P = self.n, self.Pa
        C = [arb(float(v)) for v in c]
        Pc = [sum((P[i][j] * C[j] for j in range(n)), ZERO) for i in range(n)]
        centred = sum((C[i] * Pc[i] for i in range(n)), ZERO) + \
            sum((2 * Pc[i] * arb(0, float(w[i])) for i in range(n)), ZERO)
        if centred > rho:
            return True
        plain = sum((P[i][i] * (Y[i] * Y[i]).nonnegative_part() for i in range(n)), ZERO) + \
            sum((2 * P[i][j] * Y[i] * Y[j] for i in range(n) for j in range(i + 1, n)), ZERO)
        return bool(plain > rho)

    def _box(self, c: np.ndarray, w: np.ndarray, rho: arb, res: BoxProof) -> str:
        Y, X = self._balls(c, w)
        if self._v_lower_exceeds(c, w, Y, rho):
            return "dropped"
        if self.h is not None:
            hv = self.h([X])[0][0]
            if not all(hv[i] > 0 for i in self.rows):
                return "open"
        if not self.vdot:
            return "proved"
        (fB,), dec = self.f([X])
        n, P = self.n, self.Pa
        plain = sum((2 * P[i][j] * Y[i] * fB[j] for i in range(n) for j in range(n)), ZERO)
        if plain < 0:
            return "proved"
        fJ = self.f([Jet.seed(X, ZERO)], dec)[0][0]
        if any(v is None for v in fJ):
            return "open"
        if all(abs(ci) <= wi for ci, wi in zip(c, w)):
            return "proved" if self._near_x_star(fJ, res) else "open"
        YJ = Jet.seed(Y, ZERO)
        vd = sum((2 * P[i][j] * YJ[i] * fJ[j] for i in range(n) for j in range(n)), Jet(ZERO, [ZERO] * n))
        Yc, Xc = self._balls(c, np.zeros(n))
        fc = self.f([Xc])[0][0]
        at_c = sum((2 * P[i][j] * Yc[i] * fc[j] for i in range(n) for j in range(n)), ZERO)
        mean_value = at_c + sum((g * arb(0, float(wi)) for g, wi in zip(vd.d, w)), ZERO)
        return "proved" if mean_value < 0 else "open"

    def _near_x_star(self, fJ: list, res: BoxProof) -> bool:
        """Vdot < 0 on a box holding x*, outside |y| <= eps: -(PJ + J'P) - mu I > 0 for every J in
        the box's interval Jacobian (f(x* + y) = f(x*) + J y, J averaged along the segment)."""
        n, P = self.n, self.Pa
        J = [fJ[k].d if isinstance(fJ[k], Jet) else [ZERO] * n for k in range(n)]  # constants: no gradient
        S = [[sum((P[i][k] * J[k][j] + J[k][i] * P[k][j] for k in range(n)), ZERO) for j in range(n)]
             for i in range(n)]
        mid = np.array([[float(S[i][j].mid()) for j in range(n)] for i in range(n)])
        lam = float(np.linalg.eigvalsh(-0.5 * (mid + mid.T)).min())
        if not lam > 0:
            return False
        mu = 0.5 * lam
        M = [[-S[i][j] - (arb(mu) if i == j else ZERO) for j in range(n)] for i in range(n)]
        if not certainly_pd(M):
            return False
        eps = 0.0 if self.Pf0.is_zero() else float(np.nextafter(float((2 * self.Pf0 / arb(mu)).upper()), np.inf))
        if not np.isfinite(eps):
            return False
        res.inner += 1
        res.mu = min(res.mu, mu)
        res.eps = max(res.eps, eps)
        return True

    def _counterexample(self, c: np.ndarray, rho: arb) -> str:
        """Why the level cannot hold, when the box's centre certainly breaks it; else ''."""
        n, P = self.n, self.Pa
        Y, X = self._balls(c, np.zeros(n))
        V = sum((P[i][j] * Y[i] * Y[j] for i in range(n) for j in range(n)), ZERO)
        if not V <= rho:
            return ""
        if self.h is not None:
            hv = self.h([X])[0][0]
            bad = [i for i in self.rows if hv[i] <= 0]
            if bad:
                return f"h[{bad[0]}] <= 0 at y = {np.round(c, 6).tolist()} inside the level set"
        if self.vdot and V > rho * arb(1e-9):
            fc = self.f([X])[0][0]
            vd = sum((2 * P[i][j] * Y[i] * fc[j] for i in range(n) for j in range(n)), ZERO)
            if vd >= 0:
                return f"Vdot >= 0 at y = {np.round(c, 6).tolist()} inside the level set"
        return ""


def certify_level(prover: LevelProver, rho0: float, fixed: float | None = None,
                  budget: int = 50_000) -> tuple[BoxProof, list[dict]]:
    """The first level proved among `fixed`, or the fractions LEVELS of rho0 (largest first), and the
    record of every attempt. A counterexample caps the next levels below it."""
    attempts, best = [], None
    levels = [float(fixed)] if fixed is not None else [rho0 * s for s in LEVELS]
    cap = float("inf")
    for rho in levels:
        if rho >= cap:
            continue
        res = prover.prove(rho, budget)
        attempts.append(res.to_dict())
        best = res
        if res.ok:
            break
        if res.counterexample is not None:
            y = np.asarray(res.counterexample)
            cap = float(y @ prover.P @ y)
    return best, attempts
