"""The validated flow of one closed loop from a start box, judged as Definition 4's oracle.

Each step from the set S_j = {m + B r} at clock t_j:
1. an a-priori box Y with X_j + [0, h] f(Y) inside Y (Picard-Lindelof): every solution from S_j
   stays in Y over the step;
2. the branch of every switch and kink decided over Y and the step's clock interval; undecided:
   the step is halved, and below `min_step` taken as a first-order hull step
   x(t_j + h) in S_j + h f(Y), which holds for any law, smooth or not;
3. otherwise a Taylor step of order p: the polynomial from m, the Lagrange remainder
   h^p x_p(Y, [t_j, t_j + h]), and the Jacobian of the polynomial over the hull of S_j (jets), and
   the Lohner QR update of the set (lohner.py).
Clock switching times of the primitive are crossed by hull steps of 2 `EDGE` seconds, so no Taylor
step spans one. Over every step each active safety function's lower bound is taken on enclosures
of the flow over sub-intervals of the step (bisected until it is >= 0); the step's end set is
tested against E. Certified safe: the end set lies inside E and no lower bound went negative
before. Certified unsafe: a safety function's upper bound is negative on an enclosure while the
flow cannot yet have been in E, or the horizon passed with the flow never possibly in E.
Anything else is inconclusive, with the reason.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from flint import arb, arb_mat

from .jet import Jet
from .lohner import LohnerSet
from .tape import Tape
from .taylor import coefficient, horner, solution

EDGE = 1e-9
"""Half-width (s) of the hull step that crosses a clock switching time."""
ETA = 1e-12
"""Relative distance from a clock switching time within which its branches are not told apart."""


@dataclass(frozen=True)
class Options:
    """order: Taylor order p; max_step / min_step: step bounds (s); remainder: the largest width of
    a step's remainder; box: the start box's half-width, relative to max(1, |x0|) (the rounding of
    a computed start); depth: bisections of a step when a safety function's bound is negative;
    max_steps: steps before giving up; blowup: an enclosure this wide is given up."""

    order: int = 10
    max_step: float = 0.1
    min_step: float = 1e-4
    remainder: float = 1e-10
    box: float = 1e-12
    depth: int = 10
    max_steps: int = 20000
    blowup: float = 10.0


@dataclass
class Loop:
    """The tapes of one primitive's closed loop, safe set and E, with its clock switching times."""

    f: Tape  # (x, t, s, x_sw) -> xdot
    h: Tape  # (x, t, s, x_sw) -> h values
    roa: Tape  # (x, t) -> r - ||x - x*(t)||_W
    h_names: list
    windows: list  # per h: None or a clock window (a, b)
    boundaries: tuple  # clock switching times within one period (or absolute)
    period: float | None


@dataclass
class Enclosure:
    """What a validated run proved: status safe / unsafe / inconclusive and how far it got."""

    status: str
    reason: str
    s_stop: float
    s_enter: float | None = None
    violated: str | None = None
    lower: dict = field(default_factory=dict)  # least proved lower bound of each h until the stop
    best_roa: float = -math.inf  # the largest proved lower bound of E's margin
    steps: int = 0
    hull_steps: int = 0
    width: float = 0.0  # the end set's largest width
    message: str = ""
    seconds: float = 0.0
    end: LohnerSet | None = None  # the set enclosing every flow at the last step end reached


def loop_of(prim) -> Loop:
    """The tapes of a compiled primitive's closed loop, safe set and E (a CompiledPrimitive)."""
    windows = [None if w is None else (float(w[0]), float(w[1])) for w in prim.windows]
    return Loop(Tape.of(prim.f_cl), Tape.of(prim.h), Tape.of(prim.roa_margin).of_psd(), list(prim.h_names),
                windows or [None] * len(prim.h_names), tuple(float(b) for b in prim.boundaries), prim.period)


def run(loop: Loop, start: LohnerSet, t0: float, horizon: float, x_sw: list, opts: Options = Options()) -> Enclosure:
    """Enclose the flow of `loop` switched in at clock t0 from every state of `start`."""
    clock = time.perf_counter()
    r = _Run(loop, start, t0, horizon, x_sw, opts)
    out = r.go()
    out.seconds = time.perf_counter() - clock
    return out


class _Run:
    def __init__(self, loop, start, t0, horizon, x_sw, opts):
        self.L, self.S, self.t0, self.H, self.x_sw, self.o = loop, start, float(t0), float(horizon), x_sw, opts
        self.lower = {k: math.inf for k in loop.h_names}
        self.maybe_E = False
        self.best_roa = -math.inf
        self.steps = self.hull_steps = 0
        self.doubt = None  # (h, lower bound, s_a, s_b): the first enclosure where some h may be negative

    def done(self, status, reason, s, **kw) -> Enclosure:
        lower = {k: v for k, v in self.lower.items() if v < math.inf}
        return Enclosure(status, reason, s, lower=lower, best_roa=self.best_roa, steps=self.steps,
                         hull_steps=self.hull_steps, width=self.S.width(), end=self.S, **kw)

    def go(self) -> Enclosure:
        s, h = 0.0, self.o.max_step
        if self._in_E(self.S.hull(), self.t0):
            return self.done("safe", "entered_E", 0.0, s_enter=0.0)
        while s < self.H - 1e-15:
            if self.steps >= self.o.max_steps:
                return self.done("inconclusive", "inconclusive", s, message=f"more than {self.o.max_steps} steps")
            t = self.t0 + s
            gap = self._to_boundary(t)
            if s == 0.0 and self._to_boundary(t - 2 * EDGE) <= 2 * EDGE:  # switched in on a switching time
                res = self._hull_step(t, s, EDGE)
            elif gap <= 2 * EDGE:  # cross a clock switching time by a short hull step
                res = self._hull_step(t, s, min(gap + EDGE, self.H - s))
            else:
                step = min(h, gap - EDGE, self.H - s)
                res = self._taylor_step(t, s, step)
                while res is None and step / 2 >= self.o.min_step:
                    step /= 2
                    res = self._taylor_step(t, s, step)
                if res is None:
                    res = self._kink_step(t, s, min(step, self.o.min_step))
                else:
                    h = min(self.o.max_step, 2 * step)
            if isinstance(res, str):
                return self.done("inconclusive", "inconclusive", s, message=res)
            S_new, step, checks = res
            verdict = self._judge(checks, s)
            if verdict is not None:
                return verdict
            self.S, s = S_new, s + step
            self.steps += 1
            if self.S.width() > self.o.blowup or not all(v.is_finite() for v in self.S.hull()):
                return self.done("inconclusive", "inconclusive", s,
                                 message=f"the enclosure grew past {self.o.blowup:g} at s = {s:.4g}")
            if self._in_E(self.S.hull(), self.t0 + s):
                if self.doubt is not None:
                    return self.inconclusive(s, "the flow entered E after it")
                return self.done("safe", "entered_E", s, s_enter=s)
        if self.maybe_E:
            return self.done("inconclusive", "inconclusive", self.H,
                             message="the horizon passed; the enclosure touched E's boundary but never lay inside")
        return self.done("unsafe", "horizon_reached", self.H, message="the flow certainly never entered E")

    # -- the safe set and E over a step --------------------------------------------------------
    def _judge(self, checks, s) -> Enclosure | None:
        """Fold a step's checks (in time order) into the running bounds; an Enclosure when decided.

        A safety function that may be negative rules out `safe`, but the run goes on: it may still
        be proved unsafe, by a later enclosure on which the function is certainly negative, as long
        as the flow cannot have entered E before it."""
        for tau, lows, highs, roa_hi, sure in checks:
            if roa_hi > 0:
                self.maybe_E = True
            for k, lo in lows.items():
                self.lower[k] = min(self.lower[k], lo)
            bad = [k for k, hi in highs.items() if hi < 0 and sure[k]]
            if bad and not self.maybe_E:
                return self.done("unsafe", "left_C", s + tau[1], violated=bad[0],
                                 message=f"{bad[0]} is certainly negative on an enclosure at s in "
                                         f"[{s + tau[0]:.6g}, {s + tau[1]:.6g}]")
            neg = [k for k, lo in lows.items() if lo < 0]
            if neg and self.doubt is None:
                self.doubt = (neg[0], lows[neg[0]], s + tau[0], s + tau[1])
            if self.doubt is not None and self.maybe_E:
                return self.inconclusive(s + tau[0], "the flow may have entered E before")
        return None

    def inconclusive(self, s, why) -> Enclosure:
        k, lo, a, b = self.doubt
        return self.done("inconclusive", "inconclusive", s, violated=k,
                         message=f"{k} may be negative at s in [{a:.6g}, {b:.6g}] (lower bound {lo:.3g}) and is "
                                 f"nowhere certainly negative; {why}")

    def _checks(self, enclose, t, s, step):
        """Bounds of h and E's margin over [0, step], bisected where some lower bound is negative:
        a list of ((tau_a, tau_b), lower bounds, upper bounds, E's upper bound, surely active)."""
        out = []
        todo = [(0.0, step, 0)]
        while todo:
            a, b, d = todo.pop(0)
            X = enclose(_ball(a, b))
            hv = self._bounds(self.L.h, X, t + a, t + b)
            act = [_active(w, t + a, t + b, self.L.period) for w in self.L.windows] or []
            lows, highs, sure = {}, {}, {}
            for k, (lo, hi), (maybe, surely) in zip(self.L.h_names, hv, act or [(True, True)] * len(hv)):
                if maybe:
                    lows[k], highs[k], sure[k] = lo, hi, surely
            if any(lo < 0 <= highs[k] for k, lo in lows.items()) and d < self.o.depth:
                m = (a + b) / 2
                todo[:0] = [(a, m, d + 1), (m, b, d + 1)]
                continue
            roa = self._bounds(self.L.roa, X, t + a, t + b)
            out.append(((a, b), lows, highs, roa[0][1], sure))
        return out

    def _in_E(self, X, t) -> bool:
        (roa, *_), _ = self.L.roa([X, [arb(t)]])
        lo = _lo(roa[0])
        self.best_roa = max(self.best_roa, lo)
        return lo > 0

    # -- steps ---------------------------------------------------------------------------------
    def _a_priori(self, X, t, step):
        """A box Y with X + [0, step] f(Y, [t, t + step]) inside Y, or None."""
        span = _ball(0.0, step)
        Y = X
        for _ in range(8):
            F = self._eval(self.L.f, Y, t, t + step)[0]
            Z = [x + span * v for x, v in zip(X, F)]
            if all(y.contains(z) for y, z in zip(Y, Z)):
                return Z
            Y = [_inflate(z) for z in Z]
        return None

    def _hull_step(self, t, s, step):
        X = self.S.hull()
        Y = self._a_priori(X, t, step)
        if Y is None:
            return f"no a-priori enclosure over a step of {step:.3g} s at s = {s:.6g}"
        F = self._eval(self.L.f, Y, t, t + step)[0]
        self.hull_steps += 1
        return self.S.shifted([arb(step) * v for v in F]), step, self._checks(lambda tau: Y, t, s, step)

    def _kink_step(self, t, s, step):
        """A first-order Lohner step over a switch or kink of a Lipschitz law: the point m moved by
        a hull step, the set by V(h) in I + h J (I + E), J the generalized (Clarke) Jacobian of f
        over the a-priori box, E the Gronwall bound of V - I over the step; a hull step where the
        law jumps (no Jacobian)."""
        n = len(self.S.m)
        X = self.S.hull()
        Y = self._a_priori(X, t, step)
        if Y is None or self._boundary_near(t, t + step) is not None:
            return self._hull_step(t, s, step)
        T, S = _ball(t, t + step), _ball(s, s + step)
        _, decisions = self.L.f([Y, [T], [S], self.x_sw])
        (F, *_), _ = self.L.f([Jet.seed(Y, arb(0)), [T], [S], self.x_sw], decisions, clarke=True)
        if any(v is None for v in F):
            return self._hull_step(t, s, step)
        Jm = arb_mat([[v.d[j] if isinstance(v, Jet) else arb(0) for j in range(n)] for v in F])
        Ym = self._a_priori(list(self.S.m), t, step)
        if Ym is None:
            return self._hull_step(t, s, step)
        Fm = self._eval(self.L.f, Ym, t, t + step)[0]
        h = arb(step)
        norm = max(sum(abs(float(Jm[i, j].mid())) + float(Jm[i, j].rad()) for j in range(n)) for i in range(n))
        e = math.expm1(step * norm) * (1 + 1e-12) + 1e-300
        I = arb_mat([[arb(1) if i == j else arb(0) for j in range(n)] for i in range(n)])
        Vbox = arb_mat([[arb(1 if i == j else 0, e) for j in range(n)] for i in range(n)])
        V = I + (Jm * Vbox) * h
        image = [self.S.m[i] + h * Fm[i] for i in range(n)]
        self.hull_steps += 1
        return self.S.through(image, V * arb_mat(self.S.B.tolist())), step, self._checks(lambda tau: Y, t, s, step)

    def _taylor_step(self, t, s, step):
        """(new set, step, checks), or None when this step is too long (no a-priori box, a branch
        not fixed over it, or a remainder wider than allowed)."""
        p, n = self.o.order, len(self.S.m)
        X = self.S.hull()
        T, S = _ball(t, t + step), _ball(s, s + step)
        Y = self._a_priori(X, t, step)
        if Y is None:
            return None
        _, decisions = self.L.f([Y, [T], [S], self.x_sw])
        rem = solution(self.L.f, Y, T, S, self.x_sw, decisions, p + 1)
        if rem is None:
            return None
        R = [coefficient(v, p) for v in rem]
        hp = arb(step) ** p
        Z = [c * hp for c in R]
        if max(2 * float(z.rad()) + abs(float(z.mid())) for z in Z) > self.o.remainder:
            return None
        point = solution(self.L.f, self.S.m, arb(t), arb(s), self.x_sw, decisions, p)
        jets = solution(self.L.f, Jet.seed(X, arb(0)), arb(t), arb(s), self.x_sw, decisions, p)
        if point is None or jets is None:
            return None
        h = arb(step)
        image = [horner(point[i], h, p) + Z[i] for i in range(n)]
        D = arb_mat([[horner(jets[i].d[j], h, p) for j in range(n)] for i in range(n)])
        C = D * arb_mat(self.S.B.tolist())
        new = self.S.through(image, C)
        Br = arb_mat(self.S.B.tolist()) * self.S.r
        dx = [Br[j, 0] for j in range(n)]

        def enclose(tau):
            return [horner(point[i], tau, p) + R[i] * tau ** p
                    + sum((horner(jets[i].d[j], tau, p) * dx[j] for j in range(n)), arb(0)) for i in range(n)]

        return new, step, self._checks(enclose, t, s, step)

    def _to_boundary(self, t) -> float:
        """Time from clock t to the next switching time of the clock (inf without one)."""
        B, P = self.L.boundaries, self.L.period
        if P:
            k = math.floor(t / P)
            cands = [b + j * P for j in (k - 1, k, k + 1, k + 2) for b in (*B, 0.0)]
        else:
            cands = list(B)
        ahead = [c - t for c in cands if c - t > 0]
        return min(ahead) if ahead else math.inf

    def _eval(self, tape: Tape, X, ta: float, tb: float):
        """A tape's outputs over the states X and the clock interval [ta, tb], as one ball each."""
        parts = self._eval_parts(tape, X, ta, tb)
        if len(parts) == 1:
            return parts[0]
        return [[u.union(v) for u, v in zip(p, q)] for p, q in zip(*parts)]

    def _bounds(self, tape: Tape, X, ta: float, tb: float):
        """Each output's (lower, upper) bound over X and [ta, tb], taken per side of a clock switch:
        a ball joining an active side (h = 0.3) with an inactive one (1e9) would lose the lower bound
        to its radius's rounding."""
        parts = [p[0] for p in self._eval_parts(tape, X, ta, tb)]
        return [(min(_lo(v) for v in vs), max(_hi(v) for v in vs)) for vs in zip(*parts)]

    def _eval_parts(self, tape: Tape, X, ta: float, tb: float):
        """A tape's outputs over the states X and the clock interval [ta, tb] (s alongside), one
        result per side of a clock switching time near the interval.

        Near a switching time b of the clock (within ETA), each side's branches are decided on that
        side alone ([ta, b - ETA], at least ETA wide, and likewise after b) and replayed over the
        side's part of [ta, tb], extended ETA across b, and the results joined. This assumes what
        the clock's switching times are: every clock switch at b happens at one instant within ETA
        of b, and no other switch falls within ETA of it.
        """
        b = self._boundary_near(ta, tb)
        if b is None:
            return [tape(self._args(tape, X, ta, tb))[0]]
        eta = ETA * max(1.0, abs(b))
        parts = []
        if ta < b + eta:
            lo = min(ta, b - 2 * eta)
            _, left = tape(self._args(tape, X, lo, b - eta))
            parts.append(tape(self._args(tape, X, ta, min(tb, b + eta)), left)[0])
        if tb > b - eta:
            hi = max(tb, b + 2 * eta)
            _, right = tape(self._args(tape, X, b + eta, hi))
            parts.append(tape(self._args(tape, X, max(ta, b - eta), tb), right)[0])
        return parts

    def _args(self, tape, X, ta, tb):
        T = _ball(ta, tb)
        if len(tape.in_sizes) == 2:
            return [X, [T]]
        return [X, [T], [_ball(ta - self.t0, tb - self.t0)], self.x_sw]

    def _boundary_near(self, ta: float, tb: float) -> float | None:
        """A clock switching time within ETA of [ta, tb], if any."""
        gap = self._to_boundary(ta - 2 * ETA * max(1.0, abs(ta)))
        b = ta - 2 * ETA * max(1.0, abs(ta)) + gap
        return b if b < tb + ETA * max(1.0, abs(tb)) else None


def _ball(a: float, b: float) -> arb:
    """The ball [a, b] (enclosing both ends)."""
    a, b = float(a), float(b)
    return arb(a) if a == b else arb(a).union(arb(b))


def _inflate(z: arb) -> arb:
    return arb(z.mid(), 1.1 * float(z.rad()) + 1e-12 + 1e-9 * abs(float(z.mid())))


def _lo(v: arb) -> float:
    """A float at or below every point of v (-inf for a non-finite ball)."""
    if not v.is_finite():
        return -math.inf
    return float(np.nextafter(float(v.mid()) - float(v.rad()), -np.inf))


def _hi(v: arb) -> float:
    if not v.is_finite():
        return math.inf
    return float(np.nextafter(float(v.mid()) + float(v.rad()), np.inf))


def _active(w, ta, tb, period):
    """(may be active, surely active) of a safety function's clock window over [ta, tb]."""
    if w is None:
        return True, True
    a, b = w
    if period:
        ta, tb = ta % period, ta % period + (tb - ta)
        if tb > period:  # the step wraps: judge it as active where it may be
            return True, False
    return (tb >= a and ta < b), (ta >= a and tb < b)
