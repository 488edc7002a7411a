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

from ..compile.primitive import _jump, saturate, scheduled_mode
from ..compile.rigidbody.symmetry import generators, lift_function, reduce_function
from ..compile.rigidbody.trot import gains_of, nominal_geometry, trot_torque
from ..oracle.integrator import LEFT, compile_cached

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
        g = gains_of(controller, 0.0)
        self.period = g.period
        g = gains_of(controller, c)
        n = int(round(g.period / dt))
        if abs(n * dt - g.period) > 1e-9 or any(abs(u / dt - round(u / dt)) > 1e-6 for u, _ in g.schedule(())):
            raise ValueError(f"the trot's switching times must be multiples of dt = {dt:g}")
        self.steps = n
        feet = tuple(sys.model.contact_frames)
        schedule = [(u, tuple(f)) for u, f in g.schedule(feet)]
        t = ca.SX.sym("t")
        mode = scheduled_mode(schedule, feet, t, g.period)
        loop = sys.scheduled_loop(mode)
        inertia, offsets = nominal_geometry(sys, dict(controller.pose))
        u = saturate(trot_torque(sys, g, t, mode, inertia, offsets), sys.u_lo, sys.u_hi)
        x = sys.x
        f = ca.Function("f", [x, t, c], [ca.substitute(loop.xdot, sys.u, u)], {"cse": True})
        k_u = ca.Function("k", [x, t, c], [u], {"cse": True})
        lam = ca.vertcat(*[loop.env[f"{ft}_f{a}"] for ft in feet for a in "xyz"])
        fz = ca.vertcat(*[sys.extra_env[f"{ft}_z"] for ft in feet])
        self.aux = ca.Function("aux", [x, t, c], [u, ca.substitute(lam, sys.u, u), ca.vertcat(*mode.values()), fz])
        jump = _jump(None, sys, ca.SX.sym("tj"), schedule, g.period)
        h = self.dt
        z = ca.MX.sym("z", sys.nx + 2)  # [x; t; c]: the RK4 stages call f, so its code is generated once
        xm, tm, cm = z[:sys.nx], z[sys.nx], z[sys.nx + 1]
        k1 = f(xm, tm, cm)
        k2 = f(xm + h / 2 * k1, tm + h / 2, cm)
        k3 = f(xm + h / 2 * k2, tm + h / 2, cm)
        k4 = f(xm + h * k3, tm + h - LEFT, cm)  # inside the step: its own contact mode
        xn = jump(xm + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4), k_u(xm, tm, cm), tm + h)
        body = ca.Function("body", [z], [ca.vertcat(xn, tm + h, cm)])
        one = ca.Function("gait_step", [z], [body(z)])
        stride = ca.Function("gait_stride", [z], [body.fold(n)(z)])
        self.step = compile_cached(one, ("-O1",)) if jit else one
        self.stride = compile_cached(stride, ("-O1",)) if jit else stride
        self.reduce, self.lift = reduce_function(sys), lift_function(sys)

    def run(self, x0: np.ndarray, command: float, strides: int = 1) -> np.ndarray:
        z = np.concatenate([x0, [0.0, command]])
        for _ in range(strides):
            z = np.array(self.stride(z), float).ravel()
            z[-2] = 0.0
        return z[:-2]

    def strides(self, X0: np.ndarray, commands: np.ndarray) -> np.ndarray:
        """End states of one stride from each column of X0 with its command."""
        Z = np.vstack([X0, np.zeros((1, X0.shape[1])), commands[None, :]])
        return np.array(self.stride.map(X0.shape[1])(Z), float)[:-2]

    def samples(self, x0: np.ndarray, command: float) -> tuple[np.ndarray, np.ndarray, dict]:
        """States at every step of one stride, with the torques, held-foot forces and foot heights."""
        z = np.concatenate([x0, [0.0, command]])
        X, stats = [x0.copy()], {"peak_torque": 0.0, "least_normal_force": np.inf, "least_cone_margin": np.inf,
                                 "largest_touchdown_gap": 0.0, "least_swing_foot_height": np.inf}
        mu = float(self.sys.friction)
        for k in range(self.steps):
            u, lam, held, fz = (np.array(v, float).ravel() for v in self.aux(z[:-2], k * self.dt, command))
            stats["peak_torque"] = max(stats["peak_torque"], float(np.abs(u).max()))
            if (held < 0.5).any():
                stats["least_swing_foot_height"] = min(stats["least_swing_foot_height"], float(fz[held < 0.5].min()))
            for i in np.flatnonzero(held > 0.5):
                fx, fy, fzz = lam[3 * i:3 * i + 3]
                stats["least_normal_force"] = min(stats["least_normal_force"], float(fzz))
                stats["least_cone_margin"] = min(stats["least_cone_margin"], float(mu * fzz - np.hypot(fx, fy)))
            z = np.array(self.step(z), float).ravel()
            _, _, held_next, fz_next = (np.array(v, float).ravel() for v in self.aux(z[:-2], (k + 1) * self.dt,
                                                                                     command))
            joined = (held_next > 0.5) & (held < 0.5)
            if joined.any():  # the gap of a foot at its scheduled touchdown (before the impact stops it)
                stats["largest_touchdown_gap"] = max(stats["largest_touchdown_gap"], float(fz_next[joined].max()))
                stats["least_swing_foot_height"] = min(stats["least_swing_foot_height"], float(fz_next[joined].min()))
            X.append(z[:-2].copy())
        t = np.arange(self.steps + 1) * self.dt
        return t, np.array(X).T, stats


def _jac(fn, z: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    z = np.asarray(z, float)
    cols = [(np.array(fn(z + eps * e), float).ravel() - np.array(fn(z - eps * e), float).ravel()) / (2 * eps)
            for e in np.eye(z.size)]
    return np.array(cols).T


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
        Dl = _jac(sm.lift, z)
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
    # the reduced monodromy and the neutral multipliers along the symmetry's generators
    M = _monodromy(sm, x0, c, red, lift, z)
    mu = np.linalg.eigvals(M)
    mu = mu[np.argsort(-np.abs(mu))]
    neutral = {}
    xT = sm.run(x0, c)
    after = generators(sm.sys, xT)
    for name, g in generators(sm.sys, x0).items():
        n = np.linalg.norm(g)
        XT = sm.strides(np.stack([x0 + FD * g / n, x0 - FD * g / n], axis=1), np.array([c, c]))
        Pg = (XT[:, 0] - XT[:, 1]) / (2 * FD) * n  # the stride's derivative along the generator ...
        gT = after[name]  # ... is the generator at the stride's end (exactly, by the symmetry)
        neutral[name] = (float(gT @ Pg / (gT @ gT)), float(np.linalg.norm(Pg - gT) / np.linalg.norm(gT)))
    t, X, stats = sm.samples(x0, c)
    stats["mean_speed"] = float((X[0, -1] - X[0, 0]) / T)
    return Orbit(speed, c, T, sm.dt, t, X, status, res, it, mu, neutral, stats, time.perf_counter() - t0)


def _monodromy(sm: StrideMap, x0, c, red, lift, z) -> np.ndarray:
    nz = z.size
    Dl = _jac(sm.lift, z)
    X0 = np.hstack([x0[:, None] + FD * Dl, x0[:, None] - FD * Dl])
    XT = sm.strides(X0, np.full(2 * nz, c))
    Rp = np.array([red(XT[:, j]) for j in range(nz)]).T
    Rm = np.array([red(XT[:, nz + j]) for j in range(nz)]).T
    return (Rp - Rm) / (2 * FD)
