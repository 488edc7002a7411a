"""Compiled fixed-step Runge-Kutta rollouts of a primitive's closed loop.

A chunk advances the augmented state z = [x; t; s; x_sw] by K steps with CasADi's mapaccum and
returns, for each step's start state, the safety functions h, the RoA margin and the raw input.
The chunk is jit-compiled once with the machine's C compiler; batches of start points are
evaluated by mapping the compiled chunk, so one Python call advances many rollouts.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

from ..compile.primitive import CompiledPrimitive


INLINE_NODES = 4000
"""Closed loops up to this many SX nodes are inlined (fastest code); larger ones become calls
in an MX graph, so each Function is generated once and jit compilation stays quick."""


def _sym(f: ca.Function):
    return ca.SX.sym if f.is_a("SXFunction") and f.n_nodes() <= INLINE_NODES else ca.MX.sym


def _jump_fn(prim: CompiledPrimitive) -> ca.Function:
    if prim.jump is not None:
        return prim.jump
    u, t = ca.SX.sym("u", prim.system.nu), ca.SX.sym("t")
    return ca.Function("jump", [prim.system.x, u, t], [prim.system.project(prim.system.x, u)])


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
    _buffers: dict = field(default_factory=dict)

    def mapped(self, n: int) -> ca.Function:
        if n not in self._maps:
            self._maps[n] = self.fn.map(n, "serial")
        return self._maps[n]

    def bound(self, n: int) -> tuple:
        """(evaluate, z_in, z_final, out): the batch-of-n function bound once to numpy arrays, column-major."""
        if n not in self._buffers:
            F = self.mapped(n)
            buf, ev = F.buffer()
            zin, zf, out = np.zeros(F.nnz_in(0)), np.zeros(F.nnz_out(0)), np.zeros(F.nnz_out(1))
            buf.set_arg(0, memoryview(zin))
            buf.set_res(0, memoryview(zf))
            buf.set_res(1, memoryview(out))
            self._buffers[n] = (buf, ev, zin, zf, out)  # buf keeps the bindings alive
        return self._buffers[n][1:]

    def run(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance the columns of Z (nz x n) by K steps; out has shape (nh + 1 + nu, n, K).

        Calls go through a FunctionBuffer bound once per batch size to numpy arrays (no copies
        through CasADi's DM type).
        """
        n = Z.shape[1]
        ev, zin, zf, out = self.bound(n)
        nz = zin.size // n
        zin.reshape(nz, n, order="F")[:] = Z
        ev()
        rows = out.size // (n * self.K)
        return (zf.reshape(nz, n, order="F").copy(),
                np.array(out.reshape(rows, n * self.K, order="F")).reshape(rows, n, self.K))


def build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool = True,
                flags: tuple[str, ...] = ("-O1",), with_state: bool = False) -> Chunk:
    """Compile K steps of RK4 with per-step outputs for one primitive (and the states, if asked).

    Compiled chunks are remembered on the primitive, so oracles, traces and executions share them.
    """
    key = (dt, K, jit, tuple(flags), with_state)
    if key not in prim.cache:
        prim.cache[key] = _build_chunk(prim, dt, K, jit, flags, with_state)
    return prim.cache[key]


def _with_cse(f: ca.Function) -> ca.Function:
    a = f.sx_in()
    return ca.Function(f.name(), a, f.call(a), f.name_in(), f.name_out(), {"cse": True})


def _stage1(prim: CompiledPrimitive, with_state: bool) -> tuple[ca.Function, ca.Function]:
    """(x, t, s, x_sw) -> (k1, outputs, u) from one Function, and f_cl for the other stages.

    For SX loops the first stage, h, the RoA margin and the control law share one expression
    graph with common subexpressions eliminated, so the dynamics at a step's start state (which h
    needs for contact forces) are computed once.
    """
    f, loop = prim.f_cl, prim.loop
    sx = loop.is_a("SXFunction")
    a = loop.sx_in() if sx else loop.mx_in()
    x = a[0]
    xdot, hv, u_raw, u_sat = loop.call(a)  # one evaluation of the control law (one QP for an ID-QP)
    out = ca.vertcat(hv, prim.roa_margin(x, a[1]), u_raw, *([x] if with_state else []))
    big = sx and f.n_nodes() > INLINE_NODES
    opts = {"cse": True} if big else {}
    stage1 = ca.Function("stage1", a, [xdot, out, u_sat], opts)
    return stage1, (_with_cse(f) if big else f)


def _build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool, flags: tuple[str, ...],
                 with_state: bool) -> Chunk:
    nx = prim.system.nx
    stage1, f = _stage1(prim, with_state)
    jump = _jump_fn(prim)
    z = _sym(prim.f_cl)("z", 2 * nx + 2)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:]
    k1, out, u = stage1(x, t, s, xs)
    k2 = f(x + dt / 2 * k1, t + dt / 2, s + dt / 2, xs)
    k3 = f(x + dt / 2 * k2, t + dt / 2, s + dt / 2, xs)
    k4 = f(x + dt * k3, t + dt, s + dt, xs)
    x_next = jump(x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), u, t + dt)
    body = ca.Function("body", [z], [ca.vertcat(x_next, t + dt, s + dt, xs), out])
    acc = body.mapaccum("acc", K)
    Z = ca.MX.sym("Z", 2 * nx + 2)
    zs, outs = acc(Z)
    name = "chunk_" + hashlib.sha1(f"{prim.name}{dt}{K}{with_state}".encode()).hexdigest()[:10]
    fn = ca.Function(name, [Z], [zs[:, -1], outs])
    return Chunk(prim, dt, K, compile_cached(fn, flags) if jit else fn, len(prim.h_names), prim.system.nu)


def cache_dir() -> Path:
    """Where compiled chunks are kept between runs (MPGSPEC_CACHE, else ~/.cache/mpgspec)."""
    return Path(os.environ.get("MPGSPEC_CACHE", Path.home() / ".cache" / "mpgspec")) / "jit"


def compile_cached(fn: ca.Function, flags: tuple[str, ...]) -> ca.Function:
    """fn compiled to a shared library with the system C compiler, reused when the generated C
    code and the flags are unchanged (the library's name is the hash of both)."""
    cg = ca.CodeGenerator(f"{fn.name()}.c", {"with_header": False})
    cg.add(fn)
    code = cg.dump()
    key = hashlib.sha256((code + " ".join(flags) + ca.__version__).encode()).hexdigest()[:24]
    folder = cache_dir()
    lib = folder / f"{fn.name()}_{key}.so"
    if not lib.exists():
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=folder) as tmp:
            src = Path(tmp) / f"{fn.name()}.c"
            src.write_text(code)
            out = Path(tmp) / lib.name
            cc = os.environ.get("CC", "gcc")
            try:
                subprocess.run([cc, *flags, "-fPIC", "-shared", str(src), "-o", str(out), "-lm"], check=True,
                               capture_output=True, text=True)
            except (OSError, subprocess.CalledProcessError) as err:  # no compiler: CasADi's virtual machine
                detail = getattr(err, "stderr", "") or str(err)
                warnings.warn(f"compiling {fn.name()} failed, running it uncompiled: {detail[:300]}")
                return fn
            os.replace(out, lib)  # atomic: concurrent processes never load a half-written library
    return ca.external(fn.name(), str(lib))


def initial_state(prim: CompiledPrimitive, x0: np.ndarray, t0: float) -> np.ndarray:
    """z at switch-in: clock t0, zero time since switch, x_sw = x0."""
    return np.concatenate([x0, [t0, 0.0], x0])
