"""The periodic orbit of a trot's closed loop: the fixed point of its stride map, and its multipliers.

One stride is one period of the oracle's own discrete flow (RK4 steps of dt that end on every
contact switch, then the jump: quaternion renormalised, plastic impact of the feet that join).
The orbit solves, by Newton's method on the reduced state (the ground symmetry removed),

    reduce(P(lift(z), c)) = z,    forward displacement of P / T = v,

for z and the calibrated speed command c, so that the mean forward speed is the one asked for.
Jacobians are central differences of whole strides, run as one batch of compiled rollouts. The
reduced monodromy's eigenvalues are the Floquet multipliers; the three neutral ones (moving in x
and y and turning on flat ground) are measured along their generators.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ....compile.primitive import saturate
from ....compile.rigidbody.symmetry import (NEUTRAL, lift_function, lift_jacobian, reduce_function,
                                          reduced_monodromy)
from ....oracle.flow import LEFT, rk4_jump
from ....oracle.jit import compile_cached, cse_sx
from ..stance import nominal_geometry
from ..trot import gains_of, trot_torque

FD = 1e-6


@dataclass
class Orbit:
    """A trot's orbit at one speed, and how it was found."""

    speed: float
    command: float
    period: float
    dt: float
    t: np.ndarray  # samples on [0, T]
    X: np.ndarray  # nx x samples
    status: str
    residual: float
    iterations: int
    multipliers: np.ndarray  # of the reduced stride map
    neutral: dict  # name -> (multiplier, invariance defect)
    stats: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def spectral_radius(self) -> float:
        return float(np.abs(self.multipliers).max())


class StrideMap:
    """Compiled strides of the trot's closed loop with the speed command as an input."""

    def __init__(self, sys, controller, dt: float, jit: bool = True):
        self.sys, self.dt = sys, float(dt)
        c = ca.SX.sym("c")
        g = gains_of(controller, 0.0, sys)
        self.period = g.period
        g = gains_of(controller, c, sys)
        n = int(round(g.period / dt))
        feet = tuple(sys.model.contact_frames)
        schedule = g.schedule(feet)
        if abs(n * dt - g.period) > 1e-9 or any(abs(u / dt - round(u / dt)) > 1e-6 for u in schedule.boundaries):
            raise ValueError(f"the trot's switching times must be multiples of dt = {dt:g}")
        self.steps = n
        t = ca.SX.sym("t")
        mode = schedule.mode(feet, t)
        loop = sys.scheduled_loop(mode)
        inertia, offsets = nominal_geometry(sys, dict(controller.pose))
        u = saturate(trot_torque(sys, g, t, mode, inertia, offsets), sys.u_lo, sys.u_hi)
        x = sys.x
        xdot = ca.substitute(loop.xdot, sys.u, u)
        f = ca.Function("f", [x, t, c], [xdot], {"cse": True})
        fk = ca.Function("fk", [x, t, c], [xdot, u], {"cse": True})  # k1 and the jump's input in one evaluation
        lam = ca.vertcat(*[loop.env[f"{ft}_f{a}"] for ft in feet for a in "xyz"])
        fz = ca.vertcat(*[sys.extra_env[f"{ft}_z"] for ft in feet])
        self.aux = ca.Function("aux", [x, t, c], [u, ca.substitute(lam, sys.u, u), ca.vertcat(*mode.values()), fz])
        jump = cse_sx(schedule.jump(sys, ca.SX.sym("tj")))
        z = ca.MX.sym("z", sys.nx + 2)  # [x; t; c]: the RK4 stages call f, so its code is generated once
        xm, tm, cm = z[:sys.nx], z[sys.nx], z[sys.nx + 1]
        xn = rk4_jump(lambda xx, tt: f(xx, tt, cm), None, jump, xm, tm, self.dt, LEFT, start=fk(xm, tm, cm))
        body = ca.Function("body", [z], [ca.vertcat(xn, tm + self.dt, cm)])
        stride = ca.Function("gait_stride", [z], [body.mapaccum(n)(z)])  # every step's state out
        self.stride = compile_cached(stride, ("-O1",)) if jit else stride
        self.reduce, self.lift, self.lift_jacobian = reduce_function(sys), lift_function(sys), lift_jacobian(sys)

    def run(self, x0: np.ndarray, command: float, strides: int = 1) -> np.ndarray:
        z = np.concatenate([x0, [0.0, command]])
        for _ in range(strides):
            z = np.array(self.stride(z), float)[:, -1]
            z[-2] = 0.0
        return z[:-2]

    def strides(self, X0: np.ndarray, commands: np.ndarray) -> np.ndarray:
        """End states of one stride from each column of X0 with its command."""
        Z = np.vstack([X0, np.zeros((1, X0.shape[1])), commands[None, :]])
        return np.array(self.stride.map(X0.shape[1])(Z), float)[:-2, self.steps - 1::self.steps]

    def samples(self, x0: np.ndarray, command: float) -> tuple[np.ndarray, np.ndarray, dict]:
        """States at every step of one stride, with the torques, held-foot forces and foot heights."""
        N = self.steps
        X = np.hstack([x0[:, None], np.array(self.stride(np.concatenate([x0, [0.0, command]])), float)[:-2]])
        t = np.arange(N + 1) * self.dt
        U, lam, held, fz = (np.array(v, float) for v in self.aux.map(N + 1)(X, t[None, :], command))
        mu = float(self.sys.friction)
        on, off = held[:, :N] > 0.5, held[:, :N] < 0.5
        fx, fy, fzz = lam[0::3, :N], lam[1::3, :N], lam[2::3, :N]
        joined = (held[:, 1:] > 0.5) & off  # the gap of a foot at its scheduled touchdown (before the impact)
        stats = {"peak_torque": float(np.abs(U[:, :N]).max()),
                 "least_normal_force": float(fzz[on].min(initial=np.inf)),
                 "least_cone_margin": float((mu * fzz - np.hypot(fx, fy))[on].min(initial=np.inf)),
                 "largest_touchdown_gap": float(fz[:, 1:][joined].max(initial=0.0)),
                 "least_swing_foot_height": float(min(fz[:, :N][off].min(initial=np.inf),
                                                      fz[:, 1:][joined].min(initial=np.inf)))}
        return t, X, stats


def find_orbit(sm: StrideMap, x_stand: np.ndarray, speed: float, tol: float = 1e-10, max_iter: int = 20,
               warmup: int = 8) -> Orbit:
    """Newton's method on (z, c) from the orbit that `warmup` strides from `x_stand` approach."""
    t0 = time.perf_counter()
    T = sm.period
    red = lambda x: np.array(sm.reduce(x), float).ravel()  # noqa: E731
    lift = lambda z: np.array(sm.lift(z), float).ravel()  # noqa: E731
    c = float(speed)
    z0 = red(x_stand)
    z = red(sm.run(lift(z0), c, warmup))  # strides toward the orbit when it attracts ...
    if not np.isfinite(z).all() or np.abs(z - z0).max() > 1.0:
        z = z0  # ... else Newton's method from the stance, which finds unstable orbits as well
    nz = z.size
    status, it, res = "max_iter", 0, np.inf
    for it in range(1, max_iter + 1):
        x0 = lift(z)
        Dl = np.array(sm.lift_jacobian(z), float)
        X0 = np.hstack([x0[:, None] + FD * Dl, x0[:, None] - FD * Dl, np.tile(x0[:, None], (1, 3))])
        C = np.concatenate([np.full(2 * nz, c), [c + FD, c - FD, c]])
        XT = sm.strides(X0, C)
        xT = XT[:, -1]
        F = np.concatenate([red(xT) - z, [xT[0] / T - speed]])
        res = float(np.abs(F).max())
        if not np.isfinite(res):
            status = "diverged"
            break
        if res < tol:
            status = "converged"
            break
        plus, minus = XT[:, :nz], XT[:, nz:2 * nz]
        Rp = np.array([red(plus[:, j]) for j in range(nz)]).T
        Rm = np.array([red(minus[:, j]) for j in range(nz)]).T
        Jz = np.vstack([(Rp - Rm) / (2 * FD) - np.eye(nz), ((plus[0] - minus[0]) / (2 * FD) / T)[None, :]])
        cp, cm = XT[:, 2 * nz], XT[:, 2 * nz + 1]
        Jc = np.concatenate([(red(cp) - red(cm)) / (2 * FD), [(cp[0] - cm[0]) / (2 * FD) / T]])
        J = np.hstack([Jz, Jc[:, None]])
        step = np.linalg.lstsq(J, -F, rcond=None)[0]
        z, c = z + step[:nz], c + step[nz]
    x0 = lift(z)
    if status != "converged":
        nan = np.full(nz, np.nan)
        return Orbit(speed, c, T, sm.dt, np.zeros(1), x0[:, None], status, res, it, nan, {}, {},
                     time.perf_counter() - t0)
    M, found = reduced_monodromy(sm.sys, lambda X: sm.strides(X, np.full(X.shape[1], c)), x0, NEUTRAL, FD)
    mu = np.linalg.eigvals(M)
    mu = mu[np.argsort(-np.abs(mu))]
    neutral = {k: (v["multiplier"], v["invariance_defect"]) for k, v in found.items()}
    t, X, stats = sm.samples(x0, c)
    stats["mean_speed"] = float((X[0, -1] - X[0, 0]) / T)
    return Orbit(speed, c, T, sm.dt, t, X, status, res, it, mu, neutral, stats, time.perf_counter() - t0)
