"""Steps that end where a guard crosses: RK4 on smooth pieces of a non-smooth closed loop.

RK4's embedded error estimate dt/6 (k4 - f(x_next)) means what it says only where f is smooth over
the step. When a law switches or an input saturates between samples, both ends may sit on the same
branch and the estimate maps no error onto h although the step's stages straddled the kink. For a
loop with guards (compile/guards.py) every step is first tried whole: the guards are evaluated at
its three inner stage states and at its end, and compared with their side just after its start
(at x + NUDGE dt f(x)). If none changes sign, the step is taken as it is. Otherwise the crossing is
located by BISECTIONS bisections on the length of the RK4 step (each trial step checked at its
stages and end as the whole one was), and the step ends just before it: the piece is smooth, its
estimate valid. The next step starts at the guard; its first stage is then evaluated just after
its start, on the new branch, as every later stage is. A crossing that cannot be resolved (a piece
shorter than MIN_PIECE: a guard that chatters, a pulse shorter than that) gives the step the error
estimate UNRESOLVED, so the rollout can never be judged safe.

A step is an MX graph: the smooth step (one function, which also says whether a guard may have
crossed in it), and a conditional whose other branch, the trial, the location and the outputs,
runs only where a guard crosses; elsewhere the smooth step's values pass through.
"""
from __future__ import annotations

import casadi as ca

from ..compile.primitive import CompiledPrimitive
from .flow import active, edge_end, one_sided_rate, step_end, step_length, wrap
from .jit import cse, cse_sx
from .looplib import guarded, is_large, loop_and_guards, part

__all__ = ["guarded", "guarded_body", "guarded_doubling_body"]

BISECTIONS = 36
"""Bisections of a step where a guard crosses: the piece ends within dt 2^-36 (1.5e-13 s at dt = 0.01)
of the crossing."""
BAND = 1e-9
"""A step that starts with a guard within BAND times its change over the step of zero is not taken
as smooth (the branch of its first stage is in doubt): the full step nudges it (NUDGE)."""
NUDGE = 1e-9
"""A step's first stage is evaluated NUDGE dt after its start where a guard changes sign in between
(the step starts on a guard): on the branch the step runs on, at a cost of order NUDGE dt |f'|."""
CLOCK_BISECTIONS = 44
"""Bisections of a step where a clock guard crosses: the step ends within dt 2^-44 (6e-17 s at
dt = 1e-3) after the crossing, closer than the clock's own rounding."""
SECANTS = 10
"""Illinois steps a large loop takes before bisecting the rest of a crossing's bracket."""
MIN_PIECE = 1e-9
"""A located piece shorter than this (seconds) is not resolved: the step gets UNRESOLVED."""
UNRESOLVED = 1e30
"""The error estimate of a step whose crossing could not be resolved: no safe verdict survives it."""


def _with_guards(prim: CompiledPrimitive) -> ca.Function:
    """(x, t, s, x_sw) -> (xdot, g): a small loop and its guards sharing their subexpressions."""
    a = prim.f_cl.sx_in()
    return cse(ca.Function("f_and_g", a, [prim.f_cl(*a), prim.guards.fn(*a)]))


def inline(f, *args) -> list:
    """f's outputs at args, its graph inlined where f is an MX Function (so that common
    subexpressions, the same loop evaluated at the same point twice, merge in the caller)."""
    if isinstance(f, ca.Function):
        return f.call(list(args), f.is_a("MXFunction"), False)
    return list(f(*args))


def _crossed(r, gs: list):
    """1 when a guard value in gs is zero or on the other side of its reference sign r (at zero a
    law may already take either branch; a guard with r = 0 never counts)."""
    flips = [ca.logic_and(r * g <= 0, r != 0) for g in gs]
    v = ca.vertcat(*flips)
    return ca.mmax(v) if v.shape[0] else ca.DM(0)


def _rows(v, sizes: tuple) -> list:
    """v split into consecutive parts of the given numbers of rows (empty parts as 0 x 1)."""
    offsets = [0]
    for n in sizes:
        offsets.append(offsets[-1] + n)
    return ca.vertsplit(v, offsets)


def _only_where(flag, v, sizes: tuple) -> list:
    """The parts (_rows) of the MX column v, evaluated only where `flag` (a conditional: its code
    runs only then), zeros elsewhere."""
    return _rows(ca.if_else(flag, v, ca.MX.zeros(v.shape[0]), True), sizes)


def _sides(r, gs: list):
    """Each guard's least value times its reference side r over the values gs (a trial's stages
    and end): positive where no evaluation crossed it, <= 0 where one did (as _crossed decides)."""
    q = r * gs[0]
    for g in gs[1:]:
        q = ca.fmin(q, r * g)
    return q


def _suspect(g0, gs: list, resting: bool = False):
    """1 when a step from guard values g0 may not be smooth: a guard changes sign at a stage or the
    end (gs), or starts within BAND of its change over the step of zero (where the first stage's
    branch is in doubt). Such a step is taken by the full, located step instead. With `resting`, a
    guard that is zero at the start and at every stage is not suspect: every evaluation of the
    loop in the step sees the same value, so takes the same branch (an event clock parked on its
    sentinel, `x < 1e6` at x = 1e6).

    Both tests on the products p = g0 g of each guard: a sign change (or a zero) is p <= 0; without
    one, |g - g0| >= |g0| / BAND means g / g0 >= 1 + 1 / BAND, i.e. p >= (1 + 1 / BAND) g0^2. A
    product and two comparisons per guard and stage, where each comparison with the sign and the
    change apart would take seven (and no fmin or fmax, which generated C calls per entry): the
    guards' share of a step."""
    if not g0.shape[0]:
        return ca.DM(0)
    far = (1 + 1 / BAND) * (g0 * g0)
    doubt = None
    for g in gs:
        p = g0 * g
        d = ca.logic_or(p <= 0, p >= far)
        doubt = d if doubt is None else ca.logic_or(doubt, d)
    if resting:
        moved = g0 != 0
        for g in gs:
            moved = ca.logic_or(moved, g != 0)
        doubt = ca.logic_and(doubt, moved)
    return ca.mmax(doubt)


def _trial(fg: ca.Function, x, t, s, xs, k1, tau, te, spread: bool = False, end=None):
    """(x_end, k4, guard values at the three inner stages and the end) of one RK4 step of tau; with
    `spread`, also the range (max - min, entry by entry) of the rates at the stages and the end.
    `end`: the clocks (t, s) at which the end is evaluated, formed as the caller's end sample forms
    them (so that the two evaluations, equal, are one); (t + te, s + te) by default."""
    k2, g2 = fg(x + tau / 2 * k1, t + tau / 2, s + tau / 2, xs)
    k3, g3 = fg(x + tau / 2 * k2, t + tau / 2, s + tau / 2, xs)
    k4, g4 = fg(x + tau * k3, t + te, s + te, xs)
    x_end = x + tau / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    k5, g5 = fg(x_end, *(end or (t + te, s + te)), xs)
    if not spread:
        return x_end, k4, [g2, g3, g4, g5]
    hi, lo = k1, k1
    for k in (k2, k3, k4, k5):
        hi, lo = ca.fmax(hi, k), ca.fmin(lo, k)
    return x_end, k4, [g2, g3, g4, g5], hi - lo


class _Parts:
    """The compiled parts every guarded step shares: the loop with its guards, the bisection of a
    step's length and one RK4 step of a given length."""

    def __init__(self, prim: CompiledPrimitive):
        self.prim, self.nx, self.ng, self.nh = prim, prim.system.nx, len(prim.guards), len(prim.h_names)
        # a large loop (a robot's) is called from MX graphs, the loop and its guards as one compiled
        # Function (looplib.loop_and_guards, from its library when attached): every point of a step
        # evaluates it once; h's rates are differences through it (as integrator._ends_differences)
        self.large = is_large(prim)
        self.sym = ca.MX.sym if self.large else ca.SX.sym
        x, k1, xs, r = self.sx("x"), self.sx("k1"), self.sx("x_sw"), self.sym("r", self.ng)
        t, s, lohi = self.sym("t"), self.sym("s"), self.sym("lohi", 2)
        e, k = self.sx("e"), self.sx("k")
        if self.large:
            self.loop_g = part(prim, "loop_g") or loop_and_guards(prim)
            self.fg = lambda *a: (lambda o: (o[0], o[4]))(self.loop_g.call(list(a)))
            self.G = lambda *a: self.loop_g.call(list(a))[4]
            hv = self.loop_g.call([x, t, s, xs])[1]
            h_at = (lambda y, tt, ss: self.loop_g.call([y, tt, ss, xs])[1])
            # |grad h| e for e >= 0 entry by entry: the larger change of h over +e and -e (a difference)
            self.onto_h = ca.Function("onto_h", [x, t, s, xs, e], [ca.fmax(ca.fabs(h_at(x + e, t, s) - hv),
                                                                         ca.fabs(h_at(x - e, t, s) - hv))])
            self.rate = ca.Function("h_rate", [x, t, s, xs, k], [self.h_rate(x, t, s, xs, k, hv)])
        else:
            self.fg = _with_guards(prim)
            self.G = prim.guards.fn
            a = prim.loop.sx_in()
            hv = prim.loop(*a)[1]
            self.onto_h = ca.Function("onto_h", [*a, e], [ca.mtimes(ca.fabs(ca.jacobian(hv, a[0])), e)])
            self.rate = ca.Function("h_rate", [*a, k], [ca.jtimes(hv, ca.vertcat(*a[:3]), ca.vertcat(k, 1, 1))])
        mid = (lohi[0] + lohi[1]) / 2
        cut = _crossed(r, _trial(self.fg, x, t, s, xs, k1, mid, mid)[2])
        self.bisect = ca.Function("bisect", [lohi, x, t, s, xs, k1, r],
                                  [ca.vertcat(ca.if_else(cut, lohi[0], mid), ca.if_else(cut, mid, lohi[1]))])
        tau, te = self.sym("tau"), self.sym("te")
        xe, k4, gs, spread = _trial(self.fg, x, t, s, xs, k1, tau, te, spread=True)
        self.rk4 = ca.Function("rk4_checked", [x, t, s, xs, k1, tau, te, r], [xe, k4, _crossed(r, gs), spread])
        k1n, rn, _on, _e = self.nudged(x, t, s, xs, tau)
        self.first = ca.Function("first_stage", [x, t, s, xs, tau], [k1n, rn])
        self._clock_guards(prim)

    def sx(self, name: str):
        return self.sym(name, self.nx)

    def h_rate(self, x, t, s, xs, k, hv):
        """A large loop's dh/dt along (k, 1, 1) through loop_g (flow.one_sided_rate)."""
        return one_sided_rate(lambda y, tt, ss: self.loop_g.call([y, tt, ss, xs])[1], x, t, s, k, hv)

    def ends(self):
        """A large loop's (start, end, at_end, loop) as integrator._ends_differences and _at_end
        form them, through loop_g as graphs to inline (so that the step's evaluations at the same
        point merge: its end with the next stage's check, its start with the guards')."""
        def start(x, t, s, xs):
            xdot, hv, ur, u, _g = self.loop_g.call([x, t, s, xs])
            return xdot, hv, self.h_rate(x, t, s, xs, xdot, hv), ur, u

        def end(x, t, s, xs, k4, dt):
            xdot, hv = self.loop_g.call([x, t, s, xs])[:2]
            e = dt / 6 * (k4 - xdot)
            low = self.loop_g.call([x - e, t, s, xs])[1]
            return xdot, hv, self.h_rate(x, t, s, xs, xdot, hv), ca.fabs(hv - low), e

        def at_end(x, t, s, xs):
            xdot, hv = self.loop_g.call([x, t, s, xs])[:2]
            return hv, self.h_rate(x, t, s, xs, xdot, hv)

        return start, end, at_end, lambda x, t, s, xs: self.loop_g.call([x, t, s, xs])[:4]

    def _clock_guards(self, prim: CompiledPrimitive) -> None:
        """A large loop's guards split into clock guards (functions of t and s alone: a contact
        schedule's phases, a motion profile's end) and state guards; Gc (t, s) -> the clock guards,
        cheap enough to evaluate at every step. A small loop keeps them together (clock = [])."""
        self.clock, self.state, self.Gc, self._fns = [], list(range(self.ng)), None, {}
        if not self.large:
            return
        a = prim.guards.fn.sx_in()
        g = prim.guards.fn(*a)
        live = ca.vertcat(a[0], a[3])
        self.clock = [i for i in range(self.ng) if not ca.depends_on(g[i], live)]
        self.state = [i for i in range(self.ng) if i not in self.clock]
        if self.clock:
            gc = ca.substitute(ca.vertcat(*[g[i] for i in self.clock]), live, ca.DM.zeros(live.shape[0]))
            self.Gc = ca.Function("hot_clock_guards", [a[1], a[2]], [gc])

    def clock_cut(self, t, s, h, edge):
        """(h, edge): a step of h from clock t shortened to end just past the first crossing of a
        clock guard inside it (located by CLOCK_BISECTIONS bisections of the clock guards alone, no
        loop evaluation: a swing profile's switch is a step boundary like a contact switch), with its
        last stage and end sample inside (edge, flow.step_end). A crossing is looked for at the
        step's middle and at its last stage: at the end, or LEFT before it where the step ends on a
        switching time (`edge`: a guard of that switch, such as a contact schedule's, which reads the
        clock SNAP ahead, crosses between the last stage and the end; the switch is the step's end,
        which steps already meet, not a crossing to locate one step early)."""
        if self.Gc is None:
            return h, edge
        r = self.Gc(t + NUDGE * h, s + NUDGE * h)
        last = edge_end(h, edge)
        half = _crossed(r, [self.Gc(t + h / 2, s + h / 2)])
        cut = ca.logic_or(half, _crossed(r, [self.Gc(t + last, s + last)]))
        h_cut = ca.if_else(cut, self._clock_bisect(t, s, h, last, r, half), h, True)  # bisected only where cut
        return h_cut, (cut if edge is None else ca.logic_or(edge, cut))

    def _clock_bisect(self, t, s, h, last, r, half):
        """The upper end of the bracket of the first clock guard crossing in (0, last] after
        CLOCK_BISECTIONS bisections (in the half of the step where it lies)."""
        if "bisect" not in self._fns:  # one bisection, folded: a loop in C, not CLOCK_BISECTIONS copies
            b, P = ca.SX.sym("b", 2), ca.SX.sym("p", 2 + r.shape[0])  # [lo, hi]; [t, s, r]
            lo, hi = b[0], b[1]
            mid = (lo + hi) / 2
            c = _crossed(P[2:], [self.Gc(P[0] + mid, P[1] + mid)])
            one = ca.Function("clock_bisection", [b, P], [ca.vertcat(ca.if_else(c, lo, mid), ca.if_else(c, mid, hi))])
            T, S, H, L, HF = (ca.MX.sym(n) for n in ("t", "s", "h", "last", "half"))
            R = ca.MX.sym("r", r.shape[0])
            b0 = ca.vertcat(ca.if_else(HF, 0, H / 2), ca.if_else(HF, H / 2, L))
            bn = one.fold(CLOCK_BISECTIONS)(b0, ca.repmat(ca.vertcat(T, S, R), 1, CLOCK_BISECTIONS))
            self._fns["bisect"] = ca.Function("clock_bisect", [T, S, H, L, R, HF], [bn[1]])
        return self._fns["bisect"](t, s, h, last, r, half)

    def clock_start(self, t, s, h):
        """(shift, r_c, on) at a smooth step's start: a clock guard that changes sign between the
        start and NUDGE h after it (the step starts on a clock switch, which steps end on) moves the
        start's evaluation that far on (shift), so its first stage runs on the new branch, as every
        later stage does; r_c is each clock guard's side just after the start. No clock guards:
        (0, None, 0)."""
        if self.Gc is None:
            return 0, None, 0
        d = NUDGE * h
        rc = self.Gc(t + d, s + d)
        on = _crossed(rc, [self.Gc(t, s)])
        return ca.if_else(on, d, 0), rc, on

    def smooth_suspect(self, pieces: list, rc, clocks: list):
        """_suspect over a smooth step's RK4 pieces [(g at the piece's start, [g at its stages and
        end]), ...], with the clock guards (when split) compared by side with r_c (clock_start)
        instead, at the clocks [(t, s), ...] of the pieces' stages and ends (Gc there, formed as the
        stages form them: the same values as theirs, without taking them apart from the state
        guards' at every stage): a clock switch at the step's start is met by the shift, not by
        locating it; one anywhere else in the step is located."""
        if rc is None:
            out = [_suspect(g0, gs) for g0, gs in pieces]
        else:
            st = self.state
            out = [_suspect(g0[st], [g[st] for g in gs], True) for g0, gs in pieces] if st else []
            out.append(_crossed(rc, [self.Gc(tt, ss) for tt, ss in clocks]))
        v = out[0]
        for o in out[1:]:
            v = ca.logic_or(v, o)
        return v

    def clock_nudge(self, on, shift, x, t, s, xs, k1):
        """(norm, bound on h, e) of starting a step `shift` late on its first stage k1 (clock_start):
        the state may be off by e = shift (f(x, t, s) - k1). Its loop evaluation runs only where a
        clock guard switches at the start (a conditional)."""
        if self.Gc is None:
            return 0, ca.DM.zeros(self.nh), ca.DM.zeros(self.nx)
        e = shift * (self.fg(x, t, s, xs)[0] - k1)
        return _only_where(on, ca.vertcat(ca.norm_2(e), self.onto_h(x, t, s, xs, ca.fabs(e)), e), (1, self.nh, self.nx))

    def nudged(self, x, t, s, xs, h):
        """(k1, r, on_guard, e) for a step of h from x: each guard's side r just after the start, the
        first stage f(x), or f just after the start where a guard changes sign in between (the step
        starts on a guard: on_guard = 1), and the error e of taking that new branch from the start:
        the guard lies within NUDGE dt of it (the last piece ended within the bracket before it), so
        the state may be off by up to NUDGE dt (f(x) - f(x + NUDGE dt f)); 0 off a guard."""
        k1, g0 = self.fg(x, t, s, xs)
        d = NUDGE * h
        k1n, r = self.fg(x + d * k1, t + d, s + d, xs)
        on = _crossed(r, [g0])
        return ca.if_else(on, k1n, k1), r, on, ca.if_else(on, d * (k1 - k1n), ca.DM.zeros(self.nx))

    def nudge_error(self, x, t, s, xs, e, on):
        """(norm, bound on h) of a nudged start's error e (nudged; zero unless `on`). A large loop
        maps it onto h only where the step starts on a guard (a conditional: 0 elsewhere, as the
        map of e = 0 is)."""
        v = ca.vertcat(ca.norm_2(e), self.onto_h(x, t, s, xs, ca.fabs(e)))
        return _only_where(on, v, (1, self.nh)) if self.large else _rows(v, (1, self.nh))

    def located(self, x, t, s, xs, k1, h, r):
        """MX: (lo, hi, short): the bracket of the first crossing of a step of h from x, as narrow
        as BISECTIONS bisections make it (h 2^-BISECTIONS), and 1 when the piece before it is shorter
        than MIN_PIECE. A large loop first takes up to SECANTS Illinois steps (each trial evaluates
        its loop four times), then bisects what is left: the same bracket, in fewer trials."""
        if not self.large:
            b = self.bisect.fold(BISECTIONS)(ca.vertcat(0, h), x, t, s, xs, k1, r)
            return b[0], b[1], b[0] < MIN_PIECE
        near = ca.fmin(MIN_PIECE, h)  # a crossing this close after the start needs no search
        b = self._search()(_crossed(r, _trial(self.fg, x, t, s, xs, k1, near, near)[2]), x, t, s, xs, k1, h, r, near)
        return b[0], b[1], b[0] < MIN_PIECE

    def _search(self) -> ca.Function:
        """(near, x, t, s, x_sw, k1, h, r, p) -> [lo; hi]: [0; p] where a trial of p already crosses
        (`near`: the step is stepped across by a sliver, or unresolved), else the bracket from
        SECANTS Illinois steps and the bisection of what is left (its code runs only then)."""
        if "search" not in self._fns:
            x, k1, xs, r = self.sx("x"), self.sx("k1"), self.sx("x_sw"), self.sym("r", self.ng)
            t, s, h, p = self.sym("t"), self.sym("s"), self.sym("h"), self.sym("p")
            a = [x, t, s, xs, k1, h, r, p]
            tol = h * 2.0 ** -BISECTIONS
            q_h = _sides(r, _trial(self.fg, x, t, s, xs, k1, h, h)[2])
            state = ca.vertcat(0, h, r * self.G(x, t, s, xs), q_h, 0)
            state = self._secant().fold(SECANTS)(state, x, t, s, xs, k1, r, tol)
            far = ca.Function("bracket", a, [self._narrow().fold(BISECTIONS)(state[:2], x, t, s, xs, k1, r, tol)])
            at_once = ca.Function("at_once", a, [ca.vertcat(0, p)])
            self._fns["search"] = ca.Function.if_else("search", at_once, far)
        return self._fns["search"]

    def _secant(self) -> ca.Function:
        """One Illinois (modified regula falsi) step on the bracket [lo, hi] of the first crossing,
        skipped (a switch) once it is narrower than tol. state = [lo; hi; q_lo; q_hi; last]: q the
        guards' values times their reference sides at a trial of lo and of hi (positive: not
        crossed), last which end moved last (+1 lo, -1 hi). The next trial is the earliest of the
        guards' secant roots (a guard crossed at hi's end, not at lo's), or the middle where none is,
        kept inside the bracket; lo stays uncrossed and hi crossed, as under bisection. q is the
        least of a guard's sides at the trial's stages and end (_sides), the quantity whose sign
        decides a crossing, so its roots are where the trials first cross."""
        if "secant" not in self._fns:
            ng = self.ng
            st, x, k1, xs, r = self.sym("state", 3 + 2 * ng), self.sx("x"), self.sx("k1"), self.sx("x_sw"), \
                self.sym("r", ng)
            t, s, tol = self.sym("t"), self.sym("s"), self.sym("tol")
            lo, hi, qlo, qhi, last = st[0], st[1], st[2:2 + ng], st[2 + ng:2 + 2 * ng], st[2 + 2 * ng]
            w = hi - lo
            ok = ca.logic_and(qhi <= 0, qlo > 0)
            roots = ca.if_else(ok, lo + w * qlo / ca.if_else(ok, qlo - qhi, 1), ca.inf)
            m = ca.mmin(roots)
            m = ca.if_else(m < ca.inf, m, lo + w / 2)
            m = ca.fmin(ca.fmax(m, lo + w * 1e-3), hi - w * 1e-3)
            _xe, _k4, gs = _trial(self.fg, x, t, s, xs, k1, m, m)
            cut, qm = _crossed(r, gs), _sides(r, gs)
            moved_hi = ca.vertcat(lo, m, ca.if_else(last < 0, qlo / 2, qlo), qm, -1)
            moved_lo = ca.vertcat(m, hi, qm, ca.if_else(last > 0, qhi / 2, qhi), 1)
            step = ca.Function("illinois", [st, x, t, s, xs, k1, r, tol], [ca.if_else(cut, moved_hi, moved_lo)])
            keep = ca.Function("narrow_enough", [st, x, t, s, xs, k1, r, tol], [st])
            sw = ca.Function.if_else("secant_step", step, keep)
            self._fns["secant"] = ca.Function("secant", [st, x, t, s, xs, k1, r, tol],
                                                    [sw(w > tol, st, x, t, s, xs, k1, r, tol)])
        return self._fns["secant"]

    def _narrow(self) -> ca.Function:
        """A bisection of [lo, hi] (self.bisect), skipped once it is narrower than tol."""
        if "narrow" not in self._fns:
            lohi, x, k1, xs, r = self.sym("lohi", 2), self.sx("x"), self.sx("k1"), self.sx("x_sw"), self.sym("r", self.ng)
            t, s, tol = self.sym("t"), self.sym("s"), self.sym("tol")
            a = [lohi, x, t, s, xs, k1, r, tol]
            step = ca.Function("halve", a, [self.bisect(lohi, x, t, s, xs, k1, r)])
            keep = ca.Function("narrow_enough", a, [lohi])
            self._fns["narrow"] = ca.Function("narrow", a, [ca.Function.if_else("bisect_step", step, keep)(
                lohi[1] - lohi[0] > tol, *a)])
        return self._fns["narrow"]

    def sliver(self, x, t, s, xs, k1, hi, h, r, taken):
        """MX: a step just across a crossing right after the start, of twice the bracket's end:
        (its length, x after it, its k4, the bound tau * (range of its rates) of its error, that
        error mapped onto h), evaluated only where `taken` (zeros elsewhere, where it is not used)."""
        tau = ca.fmin(2 * hi, h)
        xe, k4, _c, spread = self.rk4(x, t, s, xs, k1, tau, tau, r)
        extra = tau * spread
        v = ca.vertcat(tau, xe, k4, ca.norm_2(extra), self.onto_h(xe, t + tau, s + tau, xs, extra))
        return _only_where(taken, v, (1, self.nx, self.nx, 1, self.nh))


def _choice(short, on_guard):
    """(unresolved, sliver, pick) for a located crossing: a piece shorter than MIN_PIECE is stepped
    over by a sliver unless the step starts on a guard (then it is unresolved); pick(a, b, c) takes
    the unresolved, the sliver's or the piece's value."""
    bad = ca.logic_and(short, on_guard)
    sl = ca.logic_and(short, ca.logic_not(on_guard))
    return bad, sl, lambda a, b, c: ca.if_else(bad, a, ca.if_else(sl, b, c))


def _locate(parts: _Parts) -> ca.Function:
    """(cross, x, t, s, x_sw, k1, h, te, x_end, k4, r, on_guard) -> (piece, end stage, x_end, k4,
    unresolved, extra error norm, extra error of h): where a guard crosses, the bisected piece
    before the first crossing; a crossing right after the start is stepped across by a sliver
    (_Parts.sliver) unless the step starts on a guard (it would chatter: the whole step,
    unresolved); else the step as tried."""
    M = [ca.MX.sym(n, *shape) for n, shape in (("x", (parts.nx, 1)), ("t", (1, 1)), ("s", (1, 1)),
                                                ("x_sw", (parts.nx, 1)), ("k1", (parts.nx, 1)), ("h", (1, 1)),
                                                ("te", (1, 1)), ("x_end", (parts.nx, 1)), ("k4", (parts.nx, 1)),
                                                ("r", (parts.ng, 1)), ("on_guard", (1, 1)))]
    mx, mt, ms, mxs, mk1, mh, mte, mxe, mk4, mr, mon = M
    lo, hi, short = parts.located(mx, mt, ms, mxs, mk1, mh, mr)
    xe_p, k4_p, _c, _sp = parts.rk4(mx, mt, ms, mxs, mk1, lo, lo, mr)
    bad, sl, pick = _choice(short, mon)
    ts, xs_s, k4_s, en_s, eh_s = parts.sliver(mx, mt, ms, mxs, mk1, hi, mh, mr, sl)
    nh = parts.nh
    out = [pick(mh, ts, lo), pick(mte, ts, lo), pick(mxe, xs_s, xe_p), pick(mk4, k4_s, k4_p), bad,
           ca.if_else(sl, en_s, 0), ca.if_else(sl, eh_s, ca.MX.zeros(nh))]
    located = ca.Function("locate", M, out)
    whole = ca.Function("whole", M, [mh, mte, mxe, mk4, ca.MX(0), ca.MX(0), ca.MX.zeros(nh)])
    return ca.Function.if_else("piece_or_whole", located, whole)


def _split(parts: _Parts) -> ca.Function:
    """(again, x, t, s, x_sw, k1, tau, te, x_end, r) -> (x after tau, extra error norm, extra error
    of h): when `again`, a step of tau from x in two RK4 pieces split at its first crossing, or, when
    the crossing is right after the start, a sliver across it (twice the bracket's end, as the judged
    rollout's _Parts.sliver) and the rest; a piece that straddles a crossing adds the bound (its length)
    * (range of its rates) (never unresolved: the companion's error only widens the estimate); else
    x_end as given. (The companion trails the judged rollout by its error: where the judged one starts
    a step on a guard, the companion's crossing lies just after its start; stepped whole, its 1 ms
    straddle bound was 4e-5 m on a lifting foot, 5,000 times the rollouts' difference.)"""
    M = [ca.MX.sym(n, *shape) for n, shape in (("x", (parts.nx, 1)), ("t", (1, 1)), ("s", (1, 1)),
                                                ("x_sw", (parts.nx, 1)), ("k1", (parts.nx, 1)), ("tau", (1, 1)),
                                                ("te", (1, 1)), ("x_end", (parts.nx, 1)), ("r", (parts.ng, 1)))]
    mx, mt, ms, mxs, mk1, mtau, mte, mxe, mr = M
    W = ca.MX.sym("whole", parts.nx)
    # where the companion's own guard crosses in its step: the two pieces (located only then)
    lo, hi, short = parts.located(mx, mt, ms, mxs, mk1, mtau, mr)
    cut = ca.if_else(short, ca.fmin(2 * hi, mtau), lo)
    x1, _k4, _c, spread1 = parts.rk4(mx, mt, ms, mxs, mk1, cut, cut, mr)
    rest = mtau - cut
    k1b, rb = parts.first(x1, mt + cut, ms + cut, mxs, rest)
    x2, _k4, again, spread2 = parts.rk4(x1, mt + cut, ms + cut, mxs, k1b, rest, mte - cut, rb)
    extra = ca.if_else(short, cut * spread1, ca.MX.zeros(parts.nx)) + \
        ca.if_else(again, rest * spread2, ca.MX.zeros(parts.nx))
    pieces = ca.Function("pieces", M + [W], [x2, ca.norm_2(extra), parts.onto_h(x2, mt + mte, ms + mte, mxs, extra)])
    whole_ = ca.Function("whole", M + [W], [W, ca.MX(0), ca.MX.zeros(parts.nh)])
    whole, _k4, cross, _spread = parts.rk4(mx, mt, ms, mxs, mk1, mtau, mte, mr)
    split = ca.Function("split", M, ca.Function.if_else("crossed", pieces, whole_)(cross, *M, whole))
    keep = ca.Function("as_tried", M, [mxe, ca.MX(0), ca.MX.zeros(parts.nh)])
    return ca.Function.if_else("split_or_keep", split, keep)


def guarded_body(prim: CompiledPrimitive, dt: float, start: ca.Function, end: ca.Function, jump: ca.Function,
                 margin: ca.Function, with_state: bool, boundaries: bool, h_rows) -> ca.Function:
    """integrator.step_body's step for a loop with guards (see the module's docstring): z -> (z after
    the step, its outputs in Rows order). h_rows(h0, h1, d0,
    d1, step, act) gives the h and lower bound rows; the error rows of an unresolved step are
    UNRESOLVED."""
    nx = prim.system.nx
    parts = _Parts(prim)
    fg = parts.fg
    if parts.large:
        start, end, _at_end, _loop = parts.ends()
    # part 1: the step's start and its whole trial
    z = parts.sym("z", 2 * nx + 2)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2]
    tc = wrap(prim, t)
    h, edge = step_length(prim, dt, tc, x, s, edge=True) if boundaries else (ca.DM(dt), None)
    h, edge = parts.clock_cut(t, s, h, edge)
    te = step_end(prim, h, edge)
    _k1, h0, _d0, u_raw, u = start(x, t, s, xs)
    k1, r, on, e0 = parts.nudged(x, t, s, xs, h)
    d0 = parts.rate(x, t, s, xs, k1)  # h's rate along the branch the step runs on
    x_end, k4, gs = _trial(fg, x, t, s, xs, k1, h, te)
    cross = _crossed(r, gs)
    en0, eh0 = parts.nudge_error(x, t, s, xs, e0, on)
    trial = cse_sx(ca.Function("trial", [z], [h, te, k1, h0, d0, u_raw, u, x_end, k4, cross, r, on, en0, eh0]))
    # part 3: the step's outputs from the piece taken
    tau, tep, xe, k4p, bad = (parts.sym("tau"), parts.sym("te"), parts.sym("x_end", nx), parts.sym("k4", nx),
                             parts.sym("unresolved"))
    en_x, eh_x = parts.sym("extra"), parts.sym("extra_h", parts.nh)
    h0s, d0s = parts.sym("h0", h0.shape[0]), parts.sym("d0", d0.shape[0])
    urs, us = parts.sym("u_raw", u_raw.shape[0]), parts.sym("u", u.shape[0])
    _k5, h1, d1, dh, e = end(xe, t + tep, s + tep, xs, k4p, tau)
    x_next = jump(xe, us, t + tau, s + tau)
    act = active(prim, wrap(prim, t + tau / 2), x, s, x_next, tau)
    worse = bad * UNRESOLVED
    out = ca.vertcat(*h_rows(h0s, h1, d0s, d1, tau, act), dh + eh_x + worse, margin(x, t),
                     ca.norm_2(e) + en_x + worse, s, tau, urs, us, *([x] if with_state else []))
    finish = cse_sx(ca.Function("finish", [z, tau, tep, xe, k4p, bad, en_x, eh_x, h0s, d0s, urs, us],
                                [ca.vertcat(x_next, t + tau, s + tau, xs), out]))
    # the smooth step (no guard crosses: the step as tried), one SX function
    dl, rc, on_c = parts.clock_start(t, s, h)
    k1s_, h0_, d0_, ur_, u_ = start(x, t + dl, s + dl, xs)
    xe_, k4_, gs_ = _trial(fg, x, t, s, xs, k1s_, h, te)
    suspect = parts.smooth_suspect([(parts.G(x, t + dl, s + dl, xs), gs_)], rc,
                                   [(t + h / 2, s + h / 2), (t + te, s + te)])
    en_c, eh_c, _e = parts.clock_nudge(on_c, dl, x, t, s, xs, k1s_)
    smooth = cse(ca.Function("hot_smooth", [z], [*inline(finish, z, h, te, xe_, k4_, 0, en_c, eh_c, h0_, d0_, ur_, u_),
                                              suspect]))
    # the located step: trial, the location, the outputs
    Z = ca.MX.sym("z", 2 * nx + 2)
    (hM, teM, k1M, h0M, d0M, urM, uM, xeM, k4M, crM, rM, onM, en0M, eh0M) = trial(Z)
    Xm, Tm, Sm, XSm = Z[:nx], Z[nx], Z[nx + 1], Z[nx + 2:2 * nx + 2]
    tau, tep, xe, k4p, bad, en_x, eh_x = _locate(parts)(crM, Xm, Tm, Sm, XSm, k1M, hM, teM, xeM, k4M, rM, onM)
    located = ca.Function("located", [Z], list(finish(Z, tau, tep, xe, k4p, bad, en_x + en0M, eh_x + eh0M, h0M, d0M,
                                                           urM, uM)))
    return _smooth_or_located(smooth, located)


def _smooth_or_located(smooth: ca.Function, located: ca.Function) -> ca.Function:
    """z -> (z after the step, its outputs): the smooth step (z -> (z after, outputs, crossed)), and
    where a guard crossed in it the located one instead (a switch: the located step's code runs
    only then, and the smooth step's values are passed through, not computed again)."""
    Z = ca.MX.sym("z", smooth.size1_in(0))
    zf, of, cross = smooth(Z)
    n, m = zf.shape[0], of.shape[0]
    zs, os_ = ca.MX.sym("z_smooth", n), ca.MX.sym("out_smooth", m)
    take = ca.Function("located_step", [Z, zs, os_], [ca.vertcat(*located(Z))])
    keep = ca.Function("smooth_step", [Z, zs, os_], [ca.vertcat(zs, os_)])
    v = ca.Function.if_else("smooth_or_located", take, keep)(cross, Z, zf, of)
    return ca.Function("body", [Z], [v[:n], v[n:]])


def guarded_doubling_body(prim: CompiledPrimitive, dt: float, start: ca.Function, at_end: ca.Function,
                          loop: ca.Function, jump: ca.Function, margin: ca.Function, with_state: bool,
                          boundaries: bool, h_rows) -> ca.Function:
    """integrator.step_body's step-doubling step for a loop with guards: the judged rollout's two
    half steps are tried; where a guard crosses, the step ends just before the first crossing of its
    single-step trial and both halves are taken again over that piece. The companion advances by the
    same length, split in two RK4 pieces where one of its own guards crosses (its state differs from
    the judged one by its error, so its crossing does too). A crossing that cannot be resolved gives
    the step's estimates UNRESOLVED. z = [x; t; s; x_sw; x_c], as for the unguarded step."""
    nx = prim.system.nx
    parts = _Parts(prim)
    fg = parts.fg
    if parts.large:
        start, _end, at_end, loop = parts.ends()
    z = parts.sym("z", 3 * nx + 2)
    x, t, s, xs, xc = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2], z[2 * nx + 2:3 * nx + 2]
    tc = wrap(prim, t)
    h, edge = step_length(prim, dt, tc, x, s, edge=True) if boundaries else (ca.DM(dt), None)
    h, edge = parts.clock_cut(t, s, h, edge)
    te = step_end(prim, h, edge)
    _k1, h0, _d0, u_raw, u = start(x, t, s, xs)
    _kc, h0c, _ucr, uc = loop(xc, t, s, xs)
    k1, r, on, e0 = parts.nudged(x, t, s, xs, h)
    d0 = parts.rate(x, t, s, xs, k1)  # h's rate along the branch the step runs on
    kc1, rc, onc, e0c = parts.nudged(xc, t, s, xs, h)
    hh = h / 2
    x_mid, _k4, ga = _trial(fg, x, t, s, xs, k1, hh, hh)
    km, rm, _on, _e = parts.nudged(x_mid, t + hh, s + hh, xs, hh)
    x_end, _k4, gb = _trial(fg, x_mid, t + hh, s + hh, xs, km, hh, te - hh, end=(t + te, s + te))
    cross = ca.logic_or(_crossed(r, ga), _crossed(rm, gb))
    xc_end, _k4, cross_c, _sp = parts.rk4(xc, t, s, xs, kc1, h, te, rc)
    en0, eh0 = parts.nudge_error(x, t, s, xs, e0, on)
    en0c, eh0c = parts.nudge_error(xc, t, s, xs, e0c, onc)
    trial = cse_sx(ca.Function("trial2", [z], [h, te, k1, h0, d0, u_raw, u, x_end, cross, h0c, uc, kc1, rc,
                                               xc_end, cross_c, r, on, en0 + en0c, eh0 + eh0c, e0]))
    # the judged rollout (where a guard crosses in its halves or the companion's step): the piece before its
    # first crossing, both halves again over it (or a sliver across a crossing right after the start, or
    # the whole step unresolved when it starts on a guard)
    M = [ca.MX.sym(n, *shape) for n, shape in (("x", (nx, 1)), ("t", (1, 1)), ("s", (1, 1)), ("x_sw", (nx, 1)),
                                                ("k1", (nx, 1)), ("h", (1, 1)), ("te", (1, 1)),
                                                ("x_end", (nx, 1)), ("r", (parts.ng, 1)), ("on_guard", (1, 1)))]
    mx, mt, ms, mxs, mk1, mh, mte, mxe, mr, mon = M
    lo, hi, short = parts.located(mx, mt, ms, mxs, mk1, mh, mr)
    x2, _k4, _c, _sp = parts.rk4(mx, mt, ms, mxs, mk1, lo / 2, lo / 2, mr)
    km2, rm2 = parts.first(x2, mt + lo / 2, ms + lo / 2, mxs, lo / 2)
    x4, _k4, _c, _sp = parts.rk4(x2, mt + lo / 2, ms + lo / 2, mxs, km2, lo / 2, lo / 2, rm2)
    bad, sl, pick = _choice(short, mon)
    ts, xs_s, _k4s, en_s, eh_s = parts.sliver(mx, mt, ms, mxs, mk1, hi, mh, mr, sl)
    nh = parts.nh
    located = ca.Function("halves", M, [pick(mh, ts, lo), pick(mte, ts, lo), pick(mxe, xs_s, x4), bad,
                                        ca.if_else(sl, en_s, 0), ca.if_else(sl, eh_s, ca.MX.zeros(nh))])
    whole = ca.Function("whole2", M, [mh, mte, mxe, ca.MX(0), ca.MX(0), ca.MX.zeros(nh)])
    halves = ca.Function.if_else("halves_or_whole", located, whole)
    # the located step: trial, the judged piece, the companion over it, the outputs
    Z = ca.MX.sym("z", 3 * nx + 2)
    (hM, teM, k1M, h0M, d0M, urM, uM, xeM, crM, h0cM, ucM, kc1M, rcM, xceM, crcM, rM, onM, en0M, eh0M, e0M) = trial(Z)
    Xm, Tm, Sm, XSm, XCm = Z[:nx], Z[nx], Z[nx + 1], Z[nx + 2:2 * nx + 2], Z[2 * nx + 2:3 * nx + 2]
    tau, tep, xe, bad, en_j, eh_j = halves(crM, Xm, Tm, Sm, XSm, k1M, hM, teM, xeM, rM, onM)
    again = ca.logic_or(crcM, tau < hM)  # the companion crosses, or its step is the shorter piece
    xce, en_c, eh_c = _split(parts)(again, XCm, Tm, Sm, XSm, kc1M, tau, tep, xceM, rcM)
    # the outputs, as the unguarded doubling step forms them
    T_, te_, xe_, xce_, b_ = parts.sym("tau"), parts.sym("te"), parts.sx("x_end"), parts.sx("xc_end"), parts.sym("bad")
    h0s, d0s = parts.sym("h0", h0.shape[0]), parts.sym("d0", d0.shape[0])
    h0cs, urs, us, ucs = parts.sym("h0c", h0.shape[0]), parts.sym("u_raw", u.shape[0]), parts.sym("u", u.shape[0]), \
        parts.sym("uc", u.shape[0])
    h1, d1 = at_end(xe_, t + te_, s + te_, xs)
    h1c = loop(xce_, t + te_, s + te_, xs)[1]
    # the companion also carries the judged rollout's possible error at a guard (nudge_error), pushed
    # away from the judged state, so that the difference keeps it from step to step (errors at two
    # guards cannot cancel)
    off_ = parts.sx("offset")
    away = ca.fabs(off_) * ca.if_else(xce_ >= xe_, 1, -1)
    x_next, xc_next = jump(xe_, us, t + T_, s + T_), jump(xce_ + away, ucs, t + T_, s + T_)
    act = active(prim, wrap(prim, t + T_ / 2), x, s, x_next, T_)
    m_f, m_c = margin(x, t), margin(xc, t)
    worse = b_ * UNRESOLVED
    en_, eh_ = parts.sym("extra"), parts.sym("extra_h", h0.shape[0])
    out = ca.vertcat(*h_rows(h0s, h1, d0s, d1, T_, act), ca.fabs(h1 - h1c) + eh_ + worse, m_f,
                     ca.fabs(m_f - m_c) + en_ + worse, s, T_, urs, us, *([x] if with_state else []),
                     ca.fabs(h0s - h0cs) + worse)
    finish = cse_sx(ca.Function("finish2", [z, T_, te_, xe_, xce_, b_, en_, eh_, off_, h0s, d0s, h0cs, urs, us, ucs],
                                [ca.vertcat(x_next, t + T_, s + T_, xs, xc_next), out]))
    located = ca.Function("located2", [Z], list(finish(Z, tau, tep, xe, xce, bad, en_j + en_c + en0M,
                                                            eh_j + eh_c + eh0M, e0M, h0M, d0M, h0cM, urM, uM, ucM)))
    # the smooth step (no guard crosses in the judged halves or the companion's step), one SX function
    dl, rc, on_c = parts.clock_start(t, s, h)
    k1_, h0_, d0_, ur_, u_ = start(x, t + dl, s + dl, xs)
    kc_, h0c_, _ucr, uc_ = loop(xc, t + dl, s + dl, xs)
    xm_, _k4, ga_ = _trial(fg, x, t, s, xs, k1_, hh, hh)
    km_, gm_ = fg(xm_, t + hh, s + hh, xs)
    xe_2, _k4, gb_ = _trial(fg, xm_, t + hh, s + hh, xs, km_, hh, te - hh, end=(t + te, s + te))
    xce_2, _k4, gc_ = _trial(fg, xc, t, s, xs, kc_, h, te)
    th, sh = t + hh, s + hh
    clocks = [(t + hh / 2, s + hh / 2), (th, sh), (th + hh / 2, sh + hh / 2), (th + (te - hh), sh + (te - hh)),
              (t + h / 2, s + h / 2), (t + te, s + te)]  # the stages' and ends' clocks: halves, companion
    suspect = parts.smooth_suspect([(parts.G(x, t + dl, s + dl, xs), ga_), (gm_, gb_),
                                    (parts.G(xc, t + dl, s + dl, xs), gc_)], rc, clocks)
    en_j, eh_j, e_j = parts.clock_nudge(on_c, dl, x, t, s, xs, k1_)
    en_c, eh_c, _e = parts.clock_nudge(on_c, dl, xc, t, s, xs, kc_)
    smooth = cse(ca.Function("hot_smooth2", [z], [*inline(finish, z, h, te, xe_2, xce_2, 0, en_j + en_c, eh_j + eh_c,
                                                      e_j, h0_, d0_, h0c_, ur_, u_, uc_), suspect]))
    return _smooth_or_located(smooth, located)
