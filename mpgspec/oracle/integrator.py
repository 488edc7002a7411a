"""Compiled fixed-step Runge-Kutta rollouts of a primitive's closed loop.

A chunk advances the augmented state z = [x; t; s; x_sw] by K steps with CasADi's mapaccum and
returns, for each step's start state, the safety functions h, the RoA margin and the raw input.
The chunk is jit-compiled once with the machine's C compiler; batches of start points are
evaluated by mapping the compiled chunk, so one Python call advances many rollouts.
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from ..compile.primitive import CompiledPrimitive


def _jit_opts(flags: tuple[str, ...]) -> dict:
    """Compile with the system C compiler; -O1 builds fast and runs about as fast as -O3 here."""
    folder = Path(os.environ.get("MPGSPEC_JIT_DIR", Path(tempfile.gettempdir()) / "mpgspec-jit"))
    folder.mkdir(parents=True, exist_ok=True)
    return {"jit": True, "compiler": "shell", "jit_cleanup": True,
            "jit_options": {"flags": list(flags), "verbose": False, "directory": str(folder) + os.sep}}


INLINE_NODES = 4000
"""Closed loops up to this many SX nodes are inlined (fastest code); larger ones become calls
in an MX graph, so each Function is generated once and jit compilation stays quick."""


def _sym(f: ca.Function):
    return ca.SX.sym if f.is_a("SXFunction") and f.n_nodes() <= INLINE_NODES else ca.MX.sym


def rk4_step(f: ca.Function, nx: int, dt: float, project=lambda x: x) -> ca.Function:
    """z -> z_next, one classical RK4 step of f(x, t, s, x_sw) with the clocks advanced.

    `project` maps the new state back onto the state manifold (unit base quaternion).
    """
    z = _sym(f)("z", 2 * nx + 2)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:]
    k1 = f(x, t, s, xs)
    k2 = f(x + dt / 2 * k1, t + dt / 2, s + dt / 2, xs)
    k3 = f(x + dt / 2 * k2, t + dt / 2, s + dt / 2, xs)
    k4 = f(x + dt * k3, t + dt, s + dt, xs)
    x_next = project(x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
    return ca.Function("rk4", [z], [ca.vertcat(x_next, t + dt, s + dt, xs)])


def _project_fn(system, nx: int):
    xs = ca.SX.sym("x", nx)
    return ca.Function("project", [xs], [system.project(xs)])


@dataclass
class Chunk:
    """K compiled steps of one primitive's closed loop; rows of `out` are [h; roa_margin; u_raw]."""

    prim: CompiledPrimitive
    dt: float
    K: int
    fn: ca.Function
    nh: int
    nu: int
    _maps: dict = field(default_factory=dict)

    def mapped(self, n: int) -> ca.Function:
        if n not in self._maps:
            self._maps[n] = self.fn.map(n, "serial")
        return self._maps[n]

    def run(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance the columns of Z (nz x n) by K steps; out has shape (nh + 1 + nu, n, K)."""
        n = Z.shape[1]
        zf, out = self.mapped(n)(Z)
        out = np.asarray(out).reshape(-1, n, self.K)
        return np.asarray(zf), out


def build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool = True,
                flags: tuple[str, ...] = ("-O1",), with_state: bool = False) -> Chunk:
    """Compile K steps of RK4 with per-step outputs for one primitive (and the states, if asked).

    Compiled chunks are remembered on the primitive, so oracles, traces and executions share them.
    """
    key = (dt, K, jit, tuple(flags), with_state)
    if key not in prim.cache:
        prim.cache[key] = _build_chunk(prim, dt, K, jit, flags, with_state)
    return prim.cache[key]


def _build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool, flags: tuple[str, ...],
                 with_state: bool) -> Chunk:
    nx = prim.system.nx
    z = _sym(prim.f_cl)("z", 2 * nx + 2)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:]
    u_raw, _ = prim.control(x, t, s, xs)
    out = ca.vertcat(prim.h(x, t, s, xs), prim.roa_margin(x, t), u_raw, *([x] if with_state else []))
    step = rk4_step(prim.f_cl, nx, dt, _project_fn(prim.system, nx))
    body = ca.Function("body", [z], [step(z), out])
    acc = body.mapaccum("acc", K)
    Z = ca.MX.sym("Z", 2 * nx + 2)
    zs, outs = acc(Z)
    name = "chunk_" + hashlib.sha1(f"{prim.name}{dt}{K}{with_state}".encode()).hexdigest()[:10]
    fn = ca.Function(name, [Z], [zs[:, -1], outs], _jit_opts(flags) if jit else {})
    return Chunk(prim, dt, K, fn, len(prim.h_names), prim.system.nu)


def initial_state(prim: CompiledPrimitive, x0: np.ndarray, t0: float) -> np.ndarray:
    """z at switch-in: clock t0, zero time since switch, x_sw = x0."""
    return np.concatenate([x0, [t0, 0.0], x0])
