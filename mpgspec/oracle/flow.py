"""The discrete flow of a closed loop: one oracle step, written once for every consumer.

A step of length h from clock t (time s since switch-in) is classical RK4 on xdot = f(x, t, s)
(`rk4`), then the jump (`jump_of`: back onto the state manifold, contact events, touchdowns of a
contact schedule) with the input of the step's start. Under a contact schedule, and for every
primitive on a step that ends on a switching time or a window's edge, the last stage and the end
sample are taken just before the step's end (`step_end`, LEFT), so a mode, a law or a safety
function switching there is not yet on. The step is shortened to end on the clock's next switching time
(`step_length`), and a safety function counts for a step when its window holds over it
(`active`). The oracle's chunks (oracle/integrator.py), the robust rollouts (robust/), the gait
orbits and the verifiers all build their steps from these functions.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..compile.closed_loop import CompiledPrimitive
from ..compile.contacts import SNAP, Schedule, plan_jump, wrap_clock
from ..compile.events import EventWindow

LEFT = 1e-8
"""The last RK4 stage and the end sample of a step are taken this long before the step's end, so a
step that ends on a contact switch, a law's switching time or a window's edge runs wholly on its
own side of it (modes switch 1e-9 s early, SNAP); the jump then applies the new mode at the end."""


def rk4(f, x, clocks: tuple, h, te=None, k1=None):
    """(x after one classical RK4 step of h on xdot = f(x, *clocks), that step's k4).

    Every clock advances with the step; the last stage sits at te (default h, see step_end); k1
    is given when already evaluated. x may be a tuple of parts (f then returns one rate per part),
    each advanced by the same weights.
    """
    te = h if te is None else te
    k1 = f(x, *clocks) if k1 is None else k1
    k2 = f(_along(x, h / 2, k1), *[c + h / 2 for c in clocks])
    k3 = f(_along(x, h / 2, k2), *[c + h / 2 for c in clocks])
    k4 = f(_along(x, h, k3), *[c + te for c in clocks])
    if isinstance(x, tuple):
        return tuple(xi + h / 6 * (a + 2 * b + 2 * c + d) for xi, a, b, c, d in zip(x, k1, k2, k3, k4)), k4
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), k4


def _along(x, a, k):
    """x + a k, part by part for a tuple state."""
    return tuple(xi + a * ki for xi, ki in zip(x, k)) if isinstance(x, tuple) else x + a * k


FD_STEP = 1e-6
"""Time step of the one-sided differences that give the rates of h along the flow in large loops."""


def one_sided_rate(h_at, x, t, s, k, hv):
    """dh/dt along (k, 1, 1) by one-sided differences of h_at(x, t, s) from its value hv at (x, t, s),
    the smaller in magnitude of the two: a forward difference at a step's end (or a backward one at
    its start) can reach across a contact switch or the end of a motion profile, where h jumps; for
    smooth h the two agree to O(FD_STEP)."""
    eps = FD_STEP
    fwd = (h_at(x + eps * k, t + eps, s + eps) - hv) / eps
    bwd = (hv - h_at(x - eps * k, t - eps, s - eps)) / eps
    return ca.if_else(ca.fabs(fwd) <= ca.fabs(bwd), fwd, bwd)


def step_end(prim: CompiledPrimitive, h, edge=None):
    """Where a step's last stage and end sample sit: seen from inside the step (LEFT before its end)
    under a contact schedule, and for any primitive when the step ends on a switching time of its
    clock or an edge of a window (`edge`, from step_length), so a mode, a law or a safety function
    switching there is not yet on; elsewhere at the end."""
    if isinstance(prim.contacts, Schedule):
        return inside(h)
    return edge_end(h, edge)


def inside(h):
    """A step of h's last stage seen from inside it: LEFT before its end (at most half the step)."""
    return h - ca.fmin(LEFT, h / 2)


def edge_end(h, edge=None):
    """A step's last stage: inside it where it ends on a switching time (`edge`, from step_length),
    else at its end."""
    return h if edge is None else ca.if_else(edge, inside(h), h)


def jump_of(prim: CompiledPrimitive) -> ca.Function:
    """(x, u, t, s) -> x: the primitive's discrete update after a step (its own, else the system's)."""
    if prim.jump is not None:
        return prim.jump
    return plan_jump(None, prim.system, ca.SX.sym("t"))


def wrap(prim: CompiledPrimitive, t):
    """The clock t wrapped into the primitive's period (unchanged without one)."""
    return wrap_clock(t, prim.period)


def rk4_jump(f, k, jump, x, t, h: float, left: float = 0.0, s: float = np.inf, start=None):
    """x after one oracle step of h from clock t, without the error bookkeeping: RK4 on
    xdot = f(x, t) with the last stage `left` before the step's end (see LEFT), then the jump with
    the input k(x, t) of the step's start (s: time since switch-in, inf for a settled orbit).
    start: (f(x, t), k(x, t)) when one evaluation of the loop already gave both (k is then not called)."""
    k1, u = start if start is not None else (None, None)
    x_end, _ = rk4(lambda xx, tt, _s: f(xx, tt), x, (t, 0.0), h, h - min(left, h / 2), k1)
    return jump(x_end, k(x, t) if start is None else u, t + h, s + h)


def switched_flow(prim: CompiledPrimitive, x0: np.ndarray, t0: float, dt: float, n: int) -> np.ndarray:
    """States (nx, n + 1) of a primitive's discrete flow switched in at clock t0 from x0: n oracle
    steps of dt (RK4, the step-end rule, the jump with contact events at each step's end), each
    evaluated through the compiled loop without the error bookkeeping."""
    x = ca.DM(np.asarray(x0, float))
    X = np.zeros((x.shape[0], n + 1))
    X[:, 0] = np.asarray(x0, float)
    for i in range(n):
        t = t0 + i * dt
        x = rk4_jump(lambda xx, tt: prim.f_cl(xx, tt, tt - t0, x0), lambda xx, tt: prim.control(xx, tt, tt - t0, x0)[1],
                     prim.jump, x, t, dt, LEFT, s=t - t0)
        X[:, i + 1] = np.array(x, float).ravel()
    return X


RAMP = 1 / 16
"""After a switch-in, and after a contact schedule's lift-off, the oracle's steps grow from RAMP dt,
each at most the time since (dt/16, dt/16, dt/8, dt/4, dt/2, then dt: four steps more). There a flow
starts hardest: a foot released from the ground at rest lifts at up to 1,000 m/s^2 when its law is
off its path, and a step's lower bound between its samples (the steepest end rate over the whole step)
then dips by about a dt^2 / 4 (0.23 mm at dt = 1 ms), far below a swing foot's 10 um; with steps in
proportion to the time since, it stays a quarter of what the foot has risen above its start. A law
held at a control rate keeps whole steps."""
RAMP_STEPS = 4
"""Steps the ramp adds: the first dt after a switch-in takes 1 + RAMP_STEPS steps (RAMP = 2^-RAMP_STEPS)."""


def step_length(prim: CompiledPrimitive, dt: float, tc, x=None, s=None, edge: bool = False):
    """dt, shortened so that the step ends on the next switching time of the clock and, once a
    contact event has happened, on the next edge of a window anchored on it (T_E + eps): x is the
    state at the step's start (its event clocks), s the time since switch-in (the first steps after
    it are shorter: RAMP). With `edge`, the pair (step, 1 when the step ends on such a time, up to
    SNAP) for step_end."""
    anchored = [w for w in prim.windows if isinstance(w, EventWindow) and w.edges]
    if anchored and x is None:
        raise ValueError("windows anchored on contact events need the state to place the step's end")
    gap = ca.DM(ca.inf)
    for w in anchored:
        gap = ca.fmin(gap, w.gap(x[w.clock], s))
    B = prim.boundaries
    if B:
        gap = ca.fmin(gap, _clock_gap(prim, tc))
    ramp = s is not None and prim.sampled is None
    full = ca.fmin(dt, ca.fmax(RAMP * dt, _since_start(prim, tc, s))) if ramp else ca.DM(dt)
    step = ca.fmin(full, gap)
    return (step, gap <= full + SNAP) if edge else step  # within SNAP before a switching time is at it


def _since_start(prim: CompiledPrimitive, tc, s):
    """Time since the flow last started afresh: the switch-in (s) or a scheduled lift-off, where the
    contact schedule releases a foot that its law then lifts from rest."""
    lifts = prim.contacts.liftoffs if isinstance(prim.contacts, Schedule) else []
    since = s
    for b in lifts:
        if prim.period is not None:
            since = ca.fmin(since, ca.if_else(b <= tc + SNAP, tc - b, tc + prim.period - b))
        else:
            since = ca.fmin(since, ca.if_else(b <= tc + SNAP, tc - b, ca.inf))
    return since


def _clock_gap(prim: CompiledPrimitive, tc):
    """Time from tc to the clock's next switching time (prim.boundaries, each period's)."""
    B = prim.boundaries
    eps = SNAP  # a clock this close below a switching time is at it (as for the contact mode)
    if prim.period is not None:  # the next b + k T ahead of tc (tc may sit within eps below T)
        P = prim.period
        nxt = [ca.if_else(b > tc + eps, b, ca.if_else(b + P > tc + eps, b + P, b + 2 * P)) for b in (*B, P)]
    else:
        nxt = [ca.if_else(b > tc + eps, b, ca.inf) for b in B]
    gap = nxt[0]
    for v in nxt[1:]:
        gap = ca.fmin(gap, v)
    return gap - tc


def active(prim: CompiledPrimitive, tc, x=None, s=None, x_next=None, h=0.0):
    """1 for every safety function active over a step, else 0: a clock window must contain the
    step's middle tc; a window anchored on a contact event must hold over the whole step of h from
    the state x at time s since switch-in to x_next after its jump (events.EventWindow.over_step:
    the step in which the event happens is judged by the functions that do not depend on it)."""
    def on(w):
        if w is None:
            return 1
        if isinstance(w, EventWindow):
            tau = x[w.clock]  # without the jump, the event clock only advances
            return w.over_step(tau, s, tau + h if x_next is None else x_next[w.clock], h)
        return ca.logic_and(tc >= w[0], tc < w[1])

    return ca.vertcat(*[on(w) for w in prim.windows]) if prim.windows else ca.DM(0, 1)


def solve_or_keep(law, nu: int) -> ca.Function:
    """(due, x, t, s, x_sw, w, u) -> (u, w) of a law solved at a control rate (hold.SampledLaw):
    solved from the warm start w when `due`, else the held input u and w kept. The oracle's
    chunks and the robust rollouts count the steps to the next solve each in their own way (the
    oracle solves at a step's start, the robust step at its end for the next one)."""
    a = [*law.solve.mx_in(), ca.MX.sym("u", nu)]
    return ca.Function.if_else("sample", ca.Function("solve", a, law.solve.call(a[:5])),
                               ca.Function("keep", a, [a[5], a[4]]))
