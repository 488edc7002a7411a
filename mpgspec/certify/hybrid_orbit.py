"""The one-period map of a periodic closed loop whose state jumps (gaits), its orbit and monodromy.

The flow is the oracle's own discrete one: RK4 steps of dt from clock times on the dt grid (every
contact switch lies on it), each followed by the primitive's jump (quaternion renormalised,
plastic impact of feet that join the contact mode); a sampled law (an ID-QP with a control rate)
is solved at a step's start when due and held over the step, as the oracle holds it. x*(t) must be a trajectory of that flow step
by step (`orbit`); the monodromy is the derivative of one period of the map by central
differences, with `neutral` (base_x, base_y, yaw of a floating base on flat ground) taken on the
reduced state and the neutral multipliers reported by name. The assumption checks
(check/assumptions.py) and the floquet verifier read it.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..compile.rigidbody.symmetry import reduced_monodromy
from ..compile.contacts import Schedule
from ..oracle.flow import LEFT, jump_of, rk4_jump
from ..oracle.integrator import compiled_jump, hold_inputs, hold_size, loop_of
from ..oracle import looplib
from ..oracle.jit import compile_many, cse_sx

FD = 1e-6
S_LONG = 1e6  # time since switch-in: long after any motion profile


def _parts(prim, xs0: np.ndarray) -> tuple:
    """(f(x, t), k(x, t), jump, h(x, t), start(x, t)) of the settled loop: through the primitive's loop
    library (looplib.py: one compiled closed loop, h with its windows applied) when it has one, else
    f_cl, control and h inlined. start(x, t) is (f, k, h) at one state: one call of the library's loop."""
    lib = looplib.attach(prim)
    if lib is not None and lib.get("loop") is not None:
        loop = lib.get("loop")
        h_of = lambda xx, tt: looplib.windowed(prim, loop(xx, tt, S_LONG, xs0)[1], xx, tt, S_LONG)  # noqa: E731

        def start(xx, tt):
            o = loop(xx, tt, S_LONG, xs0)
            return o[0], o[3], looplib.windowed(prim, o[1], xx, tt, S_LONG)

        return (lambda xx, tt: loop(xx, tt, S_LONG, xs0)[0], lambda xx, tt: loop(xx, tt, S_LONG, xs0)[3],
                lib.get("jump"), h_of, start)
    f_cl, ctrl, jump, h_fn = (cse_sx(g) for g in (prim.f_cl, prim.control, jump_of(prim), prim.h))
    f, k, h_of = (lambda xx, tt: f_cl(xx, tt, S_LONG, xs0), lambda xx, tt: ctrl(xx, tt, S_LONG, xs0)[1],
                  lambda xx, tt: h_fn(xx, tt, S_LONG, xs0))
    return f, k, jump, h_of, lambda xx, tt: (f(xx, tt), k(xx, tt), h_of(xx, tt))


def _held_step(prim, xs0: np.ndarray, x, t, h: float, left: float, hold):
    """(x after one step, h at its end, hold after it) of a sampled law held over the step, as the
    oracle runs it (integrator.hold_inputs: solved at the step's start from the warm start when due),
    the open loop integrated under the held input, then the jump."""
    (u,), hold_next = hold_inputs(prim, h, hold, [(x, t, S_LONG, xs0)])
    loop_u = loop_of(prim, held=True)
    o = loop_u(x, t, S_LONG, xs0, u)  # k1 and the jump's input from one evaluation
    xn = rk4_jump(lambda xx, tt: loop_u(xx, tt, S_LONG, xs0, u)[0], None, compiled_jump(prim), x, t, h, left,
                  start=(o[0], o[3]))
    hv = looplib.windowed(prim, loop_u(xn, t + h, S_LONG, xs0, u)[1], xn, t + h, S_LONG)
    return xn, hv, hold_next


def _least(m, hv):
    """The least safety function so far, with hv's."""
    return ca.fmin(m, ca.mmin(hv)) if hv.shape[0] else m


def _period_ends(f, start, jump, z, nx: int, h: float, left: float, *lengths: int) -> list:
    """z after each count of steps in `lengths`, as hybrid_body's fold computes it, with one evaluation of the
    loop per state for k1, the jump's input and h: the step that leaves x_k takes h(x_k) from the loop it
    evaluates there anyway (rather than the step before evaluating the loop at x_k a second time),
    so the first step takes none and h(x_steps) is evaluated once at the end. The same functions at
    the same states in the same order: the same numbers with 4 loop evaluations per step instead of 6.
    Every count folds the same step function."""
    def step(zk, with_h: bool):
        x, t, m = zk[:nx], zk[nx], zk[nx + 1]
        k1, u, hx = start(x, t)
        return ca.vertcat(rk4_jump(f, None, jump, x, t, h, left, start=(k1, u)), t + h, _least(m, hx) if with_h else m)

    zs = ca.MX.sym("z", nx + 2)
    z0 = step(z, False)
    stepper = ca.Function("hybrid_step", [zs], [step(zs, True)])
    ends = []
    for n in lengths:
        z1 = stepper.fold(n - 1)(z0) if n > 1 else z0
        x_n, t_n = z1[:nx], z1[nx]
        ends.append(ca.vertcat(x_n, t_n, _least(z1[nx + 1], start(x_n, t_n)[2])))
    return ends


class HybridFlow:
    """Compiled steps, periods and tubes of a compiled primitive's discrete flow. `period` (default:
    the primitive's) is the stretch one call runs: a fixed primitive's flow is run in such chunks;
    `states`: also compile the period with every step's state out (orbit, monodromy), not only its end;
    `stretch` > 0: also a run of that many steps (run_stretch), compiled with the others."""

    def __init__(self, prim, dt: float, period: float | None = None, states: bool = True, stretch: int = 0):
        self.prim, self.dt = prim, float(dt)
        T = float(prim.period if period is None else period)
        self.steps = int(round(T / dt))
        if abs(self.steps * dt - T) > 1e-9 or any(abs(b / dt - round(b / dt)) > 1e-6 for b in prim.boundaries):
            raise ValueError(f"the period and switching times must be multiples of dt = {dt:g}")
        nx = prim.system.nx
        xs0 = np.array(prim.setpoint(0.0), float).ravel()
        f, k, jump, h_of, start = _parts(prim, xs0)
        self.hold = hold_size(prim)
        z = ca.MX.sym("z", nx + 2 + self.hold)  # [x; t; min h so far (; a sampled law's hold)]
        x, t, m = z[:nx], z[nx], z[nx + 1]
        h = self.dt
        left = LEFT if isinstance(prim.contacts, Schedule) else 0.0
        if self.hold:
            xn, hv, hold_next = _held_step(prim, xs0, x, t, h, left, z[nx + 2:])
        else:
            xn, hold_next = rk4_jump(f, k, jump, x, t, h, left), ca.MX(0, 1)
            hv = h_of(xn, t + h)
        mn = _least(m, hv)
        body = ca.Function("hybrid_body", [z], [ca.vertcat(xn, t + h, mn, hold_next)])
        xs, ts = ca.MX.sym("x", nx), ca.MX.sym("t")
        h0 = h_of(xs, ts)
        self._least_h = ca.Function("hybrid_least_h", [xs, ts], [ca.mmin(h0) if h0.shape[0] else ca.inf])
        self._h = ca.Function("hybrid_h", [xs, ts], [h0])
        zz = ca.MX.sym("z", nx + 2 + self.hold)  # a period with every step's state out, and with the last one only
        self.stretch = int(stretch)
        lengths = (self.steps, self.stretch) if self.stretch > 0 else (self.steps,)
        ends = [body.fold(n)(zz) for n in lengths] if self.hold else _period_ends(f, start, jump, zz, nx, h, left, *lengths)
        fns = [ca.Function("hybrid_period_end", [zz], [ends[0]])]
        if states:
            fns.append(ca.Function("hybrid_period", [zz], [body.mapaccum(self.steps)(zz)[:nx + 2, :]]))
        if self.stretch > 0:
            fns.append(ca.Function("hybrid_stretch_end", [zz], [ends[1]]))
        compiled = compile_many(fns, looplib.caller_flags(prim, ("-O1",)), libs=looplib.libs_of(prim))
        self.period_end, self.period_fn = compiled[0], (compiled[1] if states else None)
        self.stretch_end = compiled[-1] if self.stretch > 0 else None

    def states(self, x0: np.ndarray, t0: float = 0.0) -> np.ndarray:
        """[x; t; least h] after each step of one period from x0 at clock t0 (columns)."""
        return np.array(self.period_fn(np.concatenate([x0, [t0, np.inf], np.zeros(self.hold)])), float)

    def least_h(self, X: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The least safety function (its windows applied) at the columns of X at clocks t, as a step
        of the flow judges its end state."""
        n = X.shape[1]
        return np.array(self._least_h.map(n)(X, np.asarray(t, float)[None, :]), float).ravel()

    def first_exit(self, x0: np.ndarray, t0: float) -> dict | None:
        """Where the rollout from x0 at clock t0 first leaves C within one period: the clock at the end of
        the step whose state the flow judged unsafe, the safety function that is least there and its value;
        None when it stays in C for the period."""
        S = self.states(np.asarray(x0, float), float(t0))
        nx = S.shape[0] - 2
        out = np.flatnonzero(~(S[nx + 1] >= 0))
        if not out.size:
            return None
        j = int(out[0])
        hv = np.array(self._h(S[:nx, j], S[nx, j]), float).ravel()
        names = list(getattr(self.prim, "h_names", []))
        i = int(np.nanargmin(hv)) if np.isfinite(hv).any() else -1
        return {"t": float(S[nx, j]), "h": names[i] if 0 <= i < len(names) else "?",
                "value": float(hv[i]) if i >= 0 else float("nan")}

    def run(self, X0: np.ndarray, t0: np.ndarray, periods: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """End states and least h of rollouts from the columns of X0 at clocks t0."""
        XT, hmin, _ = self.run_until(X0, t0, periods)
        return XT, hmin

    def _packed(self, X0: np.ndarray, t0: np.ndarray) -> np.ndarray:
        """[x; t; least h; hold] columns of rollouts from X0 at clocks t0, least h not yet taken, a solve due at once."""
        n = X0.shape[1]
        return np.vstack([X0, t0[None, :], np.full((1, n), np.inf), np.zeros((self.hold, n))])

    def run_stretch(self, X0: np.ndarray, t0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(states, least h) of rollouts from the columns of X0 at clocks t0 after `stretch` steps."""
        nx = X0.shape[0]
        Z = np.array(self.stretch_end.map(X0.shape[1])(self._packed(X0, t0)), float)
        return Z[:nx], Z[nx + 1]

    def run_until(self, X0: np.ndarray, t0: np.ndarray, periods: int, stop=None) -> tuple[np.ndarray, np.ndarray, int]:
        """(states, least h, periods run) of rollouts from the columns of X0 at clocks t0: `periods`
        periods, or fewer when stop(states, least h) says after one that the outcome is decided."""
        nx = X0.shape[0]
        Z = self._packed(X0, t0)
        fn = self.period_end.map(X0.shape[1])
        for k in range(periods):
            Z = np.array(fn(Z), float)
            if stop is not None and k + 1 < periods and stop(Z[:nx], Z[nx + 1]):
                return Z[:nx], Z[nx + 1], k + 1
        return Z[:nx], Z[nx + 1], periods


def orbit(flow: HybridFlow, W: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(x* on the step grid of one period, orbit defect, least h along it): x*(t) must be a
    trajectory of the loop's own discrete flow, step by step; the defect is the largest W-distance
    between a step from x*(t_k) and x*(t_k+1)."""
    x_star = flow.prim.setpoint.map(flow.steps + 1)
    ts = np.arange(flow.steps + 1) * flow.dt
    Xs = np.array(x_star(ts[None, :]), float)
    Z = flow.states(Xs[:, 0])
    E = Z[:-2] - Xs[:, 1:]
    return Xs, float(np.sqrt(np.einsum("ij,ik,kj->j", E, W, E)).max()), float(Z[-1, -1])


def monodromy(flow: HybridFlow, x0: np.ndarray, neutral: list[str]) -> tuple[np.ndarray, dict]:
    """The one-period derivative at x0 (clock 0): reduced if `neutral` names the ground symmetry."""
    sys = flow.prim.system
    if neutral:
        return reduced_monodromy(sys, lambda X: flow.run(X, np.zeros(X.shape[1]))[0], x0, neutral, FD)
    nx = sys.nx
    E = np.eye(nx)
    XT, _ = flow.run(np.hstack([x0[:, None] + FD * E, x0[:, None] - FD * E]), np.zeros(2 * nx))
    return (XT[:, :nx] - XT[:, nx:]) / (2 * FD), {}
