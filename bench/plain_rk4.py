"""The plain RK4 chunk the oracle compiled before its verdicts became error-aware, rebuilt for the
benchmarks only: timing it against integrator.build_chunk on the same start points gives what the
error-aware check costs in compiled work."""
from __future__ import annotations

import hashlib

import casadi as ca

from mpgspec.oracle.integrator import INLINE_NODES, Chunk, compile_cached


def build_plain_chunk(prim, dt: float, K: int, jit: bool = True, flags: tuple[str, ...] = ("-O1",)) -> Chunk:
    """A plain RK4 chunk as integrator.build_chunk made it before the error-aware verdicts.

    Per step: one evaluation of prim.loop at the step's start (xdot, h, u_raw, u), three f_cl
    evaluations for k2..k4, the jump map; outputs [h; roa_margin; u_raw] of the start state;
    mapaccum over K steps; jit-compiled with integrator.compile_cached. No step shortening at
    switching times, no rates of h, no error estimate. Only for timing against the new chunk.
    """
    nx = prim.system.nx
    f, loop = prim.f_cl, prim.loop
    sx = loop.is_a("SXFunction")
    a = loop.sx_in() if sx else loop.mx_in()
    xdot, hv, u_raw, u_sat = loop.call(a)
    big = sx and f.n_nodes() > INLINE_NODES
    stage1 = ca.Function("stage1", a, [xdot, ca.vertcat(hv, prim.roa_margin(a[0], a[1]), u_raw), u_sat],
                         {"cse": True} if big else {})
    if big:
        fa = f.sx_in()
        f = ca.Function(f.name(), fa, f.call(fa), f.name_in(), f.name_out(), {"cse": True})
    if prim.jump is not None:
        jump = prim.jump
    else:
        ju, jt, js = ca.SX.sym("u", prim.system.nu), ca.SX.sym("t"), ca.SX.sym("s")
        jump = ca.Function("jump", [prim.system.x, ju, jt, js], [prim.system.project(prim.system.x, ju, js)])
    sym = ca.SX.sym if prim.f_cl.is_a("SXFunction") and prim.f_cl.n_nodes() <= INLINE_NODES else ca.MX.sym
    z = sym("z", 2 * nx + 2)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:]
    k1, out, u = stage1(x, t, s, xs)
    k2 = f(x + dt / 2 * k1, t + dt / 2, s + dt / 2, xs)
    k3 = f(x + dt / 2 * k2, t + dt / 2, s + dt / 2, xs)
    k4 = f(x + dt * k3, t + dt, s + dt, xs)
    x_next = jump(x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), u, t + dt, s + dt)
    body = ca.Function("body", [z], [ca.vertcat(x_next, t + dt, s + dt, xs), out])
    Z = ca.MX.sym("Z", 2 * nx + 2)
    zs, outs = body.mapaccum("acc", K)(Z)
    name = "plain_" + hashlib.sha1(f"{prim.name}{dt}{K}".encode()).hexdigest()[:10]
    fn = ca.Function(name, [Z], [zs[:, -1], outs])
    return Chunk(prim, dt, K, compile_cached(fn, flags) if jit else fn, len(prim.h_names), prim.system.nu)
