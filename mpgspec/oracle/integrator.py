"""Compiled fixed-step Runge-Kutta rollouts of a primitive's closed loop.

A chunk advances the augmented state z = [x; t; s; x_sw] by K steps with CasADi's mapaccum and
returns, for each step's start state, the safety functions h, the RoA margin and the raw input.
The chunk is jit-compiled once with the machine's C compiler; batches of start points are
evaluated by mapping the compiled chunk, so one Python call advances many rollouts. The step
itself (RK4, the jump, the step-end rule, the boundaries, the windows) is oracle/flow.py's; this
module adds the error estimates, the rates of h and the compiled chunks. With jit, a large closed
loop, its jump and a large RoA margin are called from the primitive's loop library (looplib.py),
compiled once and shared by every chunk; the chunks' own code then compiles at -O0.

A primitive whose law is sampled (compile/hold.py: an optimisation-based law with a control rate)
is rolled out under a zero-order hold: the law is solved at the start of every m-th step (m =
control period / dt) from the previous solve's warm start, and every stage, rate difference and
end evaluation of the step uses the open loop loop_u with that input. The input, the warm start
and the steps left until the next solve then ride in the augmented state (`hold_size`).
"""
from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..compile.primitive import INACTIVE, CompiledPrimitive
from .flow import active, jump_of, one_sided_rate, rk4, solve_or_keep, step_end, step_length, wrap
from .pieces import guarded, guarded_body, guarded_doubling_body
from .jit import compile_cached, cse_sx
from .looplib import (INLINE_NODES, attach, attached, build_all, caller_flags, compile_callers, libs_of, part,
                      plain_loop)


def _sym(f: ca.Function, prim: CompiledPrimitive | None = None):
    """SX for small SX loops (inlined); MX for large loops, for setpoints looked up in a table and for
    sampled laws."""
    table = prim is not None and (not prim.roa_margin.is_a("SXFunction") or prim.sampled is not None)
    return ca.SX.sym if f.is_a("SXFunction") and f.n_nodes() <= INLINE_NODES and not table else ca.MX.sym


@dataclass(frozen=True)
class Rows:
    """Row layout of a chunk's per-step output (one column per step, started at sample k).

    h: safety functions at sample k (INACTIVE outside their window); lb: a lower bound of each h
    over the step [s_k, s_k+1] from its values and rates at both ends; dh: |grad h . e_k|, the
    local integration error e_k mapped onto h; margin: RoA margin at sample k; err: ||e_k||;
    s, dt: time since switch-in at sample k and the step's length; u_raw, u: the input before and
    after saturation; x: the state (traces only).
    """

    nh: int
    nu: int
    nx: int = 0
    doubling: bool = False

    @property
    def h(self):
        return slice(0, self.nh)

    @property
    def lb(self):
        return slice(self.nh, 2 * self.nh)

    @property
    def dh(self):
        return slice(2 * self.nh, 3 * self.nh)

    @property
    def margin(self):
        return 3 * self.nh

    @property
    def err(self):
        return 3 * self.nh + 1

    @property
    def s(self):
        return 3 * self.nh + 2

    @property
    def dt(self):
        return 3 * self.nh + 3

    @property
    def u_raw(self):
        return slice(3 * self.nh + 4, 3 * self.nh + 4 + self.nu)

    @property
    def u(self):
        return slice(3 * self.nh + 4 + self.nu, 3 * self.nh + 4 + 2 * self.nu)

    @property
    def x(self):
        o = 3 * self.nh + 4 + 2 * self.nu
        return slice(o, o + self.nx)

    @property
    def ds(self):
        """Under step doubling: the error estimate of each h at sample k (dh is then the one at the
        step's end, err the RoA margin's at sample k; all absolute, not per step)."""
        o = 3 * self.nh + 4 + 2 * self.nu + self.nx
        return slice(o, o + (self.nh if self.doubling else 0))


@dataclass
class Chunk:
    """K compiled steps of one primitive's closed loop; `rows` names the rows of `out`."""

    prim: CompiledPrimitive
    dt: float
    K: int
    fn: ca.Function
    nh: int
    nu: int
    rows: Rows = None  # type: ignore[assignment]
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

    def start(self, x0s: np.ndarray, t0s: np.ndarray) -> np.ndarray:
        """Augmented start states (one column per row of x0s), as initial_state."""
        return start_states(self.prim, x0s, t0s, self.rows.doubling)

    def run(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Advance the columns of Z (nz x n) by K steps; out has shape (rows, n, K).

        Calls go through a FunctionBuffer bound once per batch size to numpy arrays (no copies
        through CasADi's DM type).
        """
        n = Z.shape[1]
        ev, zin, zf, out = self.bound(n)
        nz = zin.size // n
        zin.reshape(nz, n, order="F")[:] = Z
        ev()
        status = self._buffers[n][0].ret()
        if status:  # the outputs were not written: never judge the previous call's numbers again
            zf[:] = np.nan
            out[:] = np.nan
            raise RuntimeError(f"the compiled rollout failed (status {status}): an evaluation inside it "
                               "(e.g. an optimisation-based control law) returned an error")
        rows = out.size // (n * self.K)
        return (zf.reshape(nz, n, order="F").copy(),
                np.array(out.reshape(rows, n * self.K, order="F")).reshape(rows, n, self.K))


def build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool = True,
                flags: tuple[str, ...] = ("-O1",), with_state: bool = False, boundaries: bool = True,
                error: str = "local") -> Chunk:
    """Compile K steps of RK4 with per-step outputs for one primitive (and the states, if asked).

    With `boundaries`, a step never crosses a clock time where the safe set or the contact mode
    switches: it is shortened to end there. `error` is 'local' (embedded per-step estimates) or
    'doubling' (see _build_doubling). A sampled law is held over m steps (see the module's
    docstring); a control period that is not a whole number of steps of dt is a SpecError.
    Compiled chunks are remembered on the primitive, so oracles, traces and executions share them.
    """
    if prim.sampled is not None:
        prim.sampled.steps(dt)
    key = (dt, K, jit, tuple(flags), with_state, boundaries, error)
    if key not in prim.cache:
        if jit:  # a large loop through its compiled library
            attach(prim)
        build = _build_doubling if error == "doubling" else _build_chunk
        prim.cache[key] = build(prim, dt, K, jit, flags, with_state, boundaries)
    return prim.cache[key]


def build_chunks(prims: list[CompiledPrimitive], dt: float, K: int, flags: tuple[str, ...] = ("-O1",),
                 with_state: bool = False, boundaries: bool = True, error: str = "local") -> list[Chunk]:
    """build_chunk with jit for several primitives at once: their C code generated one after the
    other, then gcc run side by side (compile_many). Chunks remembered on a primitive are reused."""
    key = (dt, K, True, tuple(flags), with_state, boundaries, error)
    new = list({id(p): p for p in prims if key not in p.cache}.values())
    build_all(new)  # the large loops' libraries first, side by side
    raw = [build_chunk(p, dt, K, False, flags, with_state, boundaries, error) for p in new]
    for p, c, fn in zip(new, raw, compile_callers(new, [c.fn for c in raw], flags)):
        p.cache[key] = dataclasses.replace(c, fn=fn, _maps={}, _buffers={})
    return [p.cache[key] for p in prims]


def _ends(prim: CompiledPrimitive, held: bool = False) -> tuple[ca.Function, ca.Function, ca.Function]:
    """Functions for both ends of a step, and f_cl for the inner stages; `held`: of the open loop
    loop_u, each with the held input u as an argument after x_sw.

    start (x, t, s, x_sw) -> (k1, h, hdot, u_raw, u): the loop at the step's start with the rate
    of every (unwindowed) safety function along the flow, dh/dt = grad h . f + dh/dt + dh/ds.
    end (x, t, s, x_sw, k4, dt) -> (k5, h, hdot, |grad h . e|, e): the loop at the step's end
    (before any jump), with the embedded third-order error estimate e = dt/6 (k4 - k5) of the
    RK4 step (weights 1/6, 1/3, 1/3, 0, 1/6 on k1..k4 and k5 = f(x_next)).
    Small SX loops get exact directional derivatives, inlined with common subexpressions
    eliminated; large loops (called from an MX graph) get one-sided differences along the flow
    (see _rate) and h(x_next) - h(x_next - e), which reuse the one compiled loop instead of generating
    derivative code several times its size.
    """
    loop = loop_of(prim, held)
    f = _xdot_of(loop) if held else prim.f_cl
    if not loop.is_a("SXFunction") or f.n_nodes() > INLINE_NODES:
        a = loop.mx_in()  # the inner stages take xdot from the same loop: its code is generated once
        return (*_ends_differences(loop), ca.Function("f_of_loop", a, [loop.call(a)[0]]))
    a = loop.sx_in()
    x, t, s = a[0], a[1], a[2]
    xdot, hv, u_raw, u_sat = loop.call(a)
    arg, one = ca.vertcat(x, t, s), ca.DM([1.0, 1.0])
    hdot = ca.jtimes(hv, arg, ca.vertcat(xdot, one))
    start = ca.Function("start", a, [xdot, hv, hdot, u_raw, u_sat])
    k4, dt = ca.SX.sym("k4", x.shape[0]), ca.SX.sym("dt")
    e = dt / 6 * (k4 - xdot)
    D = ca.jtimes(hv, arg, ca.horzcat(ca.vertcat(xdot, one), ca.vertcat(e, ca.DM.zeros(2))))
    end = ca.Function("end", a + [k4, dt], [xdot, hv, D[:, 0], ca.fabs(D[:, 1]), e])
    return start, end, f


def _at_end(prim: CompiledPrimitive, start: ca.Function) -> ca.Function:
    """(x, t, s, x_sw) -> (h, dh/dt) at a step's end, as `start` gives them at its start."""
    a = start.mx_in() if start.is_a("MXFunction") else start.sx_in()
    r = start.call(a)
    return ca.Function("at_end", a, [r[1], r[2]])


def loop_of(prim: CompiledPrimitive, held: bool = False) -> ca.Function:
    """The closed loop (x, t, s, x_sw) -> (xdot, h, u_raw, u), or with `held` the open loop loop_u
    (x, t, s, x_sw, u_raw) -> (xdot, h, u_raw, u): from the primitive's loop library when one is
    attached (looplib.py), else looplib.plain_loop."""
    ext = part(prim, "loop_u" if held else "loop")
    return ext if ext is not None else plain_loop(prim, held)


def compiled_jump(prim: CompiledPrimitive) -> ca.Function:
    """flow.jump_of, from the primitive's loop library when one is attached."""
    ext = part(prim, "jump")
    return ext if ext is not None else jump_of(prim)


def _margin(prim: CompiledPrimitive) -> ca.Function:
    """The RoA margin (x, t), from the primitive's loop library when it holds it."""
    ext = part(prim, "roa_margin")
    return ext if ext is not None else prim.roa_margin


def _sampled(prim: CompiledPrimitive):
    """The primitive's sampled law, its solve from the loop library when one is attached."""
    ext = part(prim, "solve")
    return prim.sampled if ext is None else dataclasses.replace(prim.sampled, solve=ext)


def _xdot_of(loop: ca.Function) -> ca.Function:
    a = loop.sx_in() if loop.is_a("SXFunction") else loop.mx_in()
    return ca.Function("f_of_loop", a, [loop.call(a)[0]])


def _rate(loop: ca.Function, a: list, xdot, hv):
    """dh/dt along the flow through the compiled loop (flow.one_sided_rate)."""
    x, t, s, xs, *held = a
    return one_sided_rate(lambda y, tt, ss: loop(y, tt, ss, xs, *held)[1], x, t, s, xdot, hv)


def _ends_differences(loop: ca.Function) -> tuple[ca.Function, ca.Function]:
    a = loop.mx_in()
    x = a[0]
    xdot, hv, u_raw, u_sat = loop.call(a)
    start = ca.Function("start", a, [xdot, hv, _rate(loop, a, xdot, hv), u_raw, u_sat])
    k4, dt = ca.MX.sym("k4", x.shape[0]), ca.MX.sym("dt")
    e = dt / 6 * (k4 - xdot)
    h_lower = loop(x - e, *a[1:])[1]
    end = ca.Function("end", a + [k4, dt], [xdot, hv, _rate(loop, a, xdot, hv), ca.fabs(hv - h_lower), e])
    return start, end


def hold_size(prim: CompiledPrimitive, doubling: bool = False) -> int:
    """Entries of the augmented state after [x; t; s; x_sw] (and x_c) that a sampled law needs: the
    steps left before its next solve, then the held input and the warm start of the judged rollout
    (and of the companion, under step doubling)."""
    if prim.sampled is None:
        return 0
    return 1 + (prim.system.nu + prim.sampled.nw) * (2 if doubling else 1)


def hold_start(prim: CompiledPrimitive, doubling: bool = False) -> np.ndarray:
    """The hold's entries at switch-in: a solve due at once, from a cold start."""
    return np.zeros(hold_size(prim, doubling))


def hold_inputs(prim: CompiledPrimitive, dt: float, block, rollouts: list) -> tuple[list, object]:
    """The input each rollout holds over this step, and the hold's entries after it.

    block = [c; u; w (; u_c; w_c)], c the steps left before the next solve; rollouts: (x, t, s, x_sw)
    of the judged rollout (and of the companion). When c is 0 the law is solved from the warm start w
    and c restarts at m - 1 (m steps per control period); otherwise u and w are kept.
    """
    law, nu = _sampled(prim), prim.system.nu
    if law is None:
        return [], block
    m, per = law.steps(dt), nu + law.nw
    c = block[0]
    if m > 1:
        sample = solve_or_keep(law, nu)
    us, after = [], []
    for i, (x, t, s, xs) in enumerate(rollouts):
        u, w = block[1 + i * per:1 + i * per + nu], block[1 + i * per + nu:1 + (i + 1) * per]
        u, w = law.solve(x, t, s, xs, w) if m == 1 else sample(c < 0.5, x, t, s, xs, w, u)
        us.append(u)
        after += [u, w]
    c_next = ca.if_else(c < 0.5, m - 1, c - 1) if m > 1 else c
    return us, ca.vertcat(c_next, *after)


def _build_chunk(prim: CompiledPrimitive, dt: float, K: int, jit: bool, flags: tuple[str, ...],
                 with_state: bool, boundaries: bool) -> Chunk:
    body, nz = step_body(prim, dt, with_state, boundaries)
    fn = _accumulate("chunk_", prim, dt, K, with_state, boundaries, body, nz)
    fn = compile_cached(fn, caller_flags(prim, flags), libs_of(prim)) if jit else fn
    return Chunk(prim, dt, K, fn, len(prim.h_names), prim.system.nu,
                 Rows(len(prim.h_names), prim.system.nu, prim.system.nx if with_state else 0))


def step_body(prim: CompiledPrimitive, dt: float, with_state: bool = False, boundaries: bool = True,
              doubling: bool = False) -> tuple[ca.Function, int]:
    """(z -> (z after one step, that step's outputs in Rows order), nz): one step of the chunk with
    error 'local' (or 'doubling'), remembered on the primitive so that every chunk built from it
    shares it (one body inlining the loop, one calling its library)."""
    key = ("body", dt, with_state, boundaries, doubling, attached(prim) is not None)
    if key not in prim.cache:
        prim.cache[key] = (_doubling_body if doubling else _step_body)(prim, dt, with_state, boundaries)
    return prim.cache[key]


def _step_body(prim: CompiledPrimitive, dt: float, with_state: bool, boundaries: bool) -> tuple[ca.Function, int]:
    if guarded(prim):
        return _guarded_body(prim, dt, with_state, boundaries)
    nx, nh = prim.system.nx, len(prim.h_names)
    start, end, f = _ends(prim, prim.sampled is not None)
    jump = compiled_jump(prim)
    nz = 2 * nx + 2 + hold_size(prim)
    z = _sym(prim.f_cl, prim)("z", nz)
    x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2]
    U, hold_next = hold_inputs(prim, dt, z[2 * nx + 2:], [(x, t, s, xs)])  # U: [u] of a sampled law, else []
    tc = wrap(prim, t)
    h, edge = step_length(prim, dt, tc, x, s, edge=True) if boundaries else (ca.DM(dt), None)
    k1, h0, d0, u_raw, u = start(x, t, s, xs, *U)
    te = step_end(prim, h, edge)
    x_end, k4 = rk4(lambda xx, tt, ss: f(xx, tt, ss, xs, *U), x, (t, s), h, te, k1)
    _k5, h1, d1, dh, e = end(x_end, t + te, s + te, xs, *U, k4, h)
    x_next = jump(x_end, u, t + h, s + h)
    act = active(prim, wrap(prim, t + h / 2), x, s, x_next, h)  # a step lies inside or outside each window
    out = ca.vertcat(*_masked(act, nh, h0, _sample_bound(h0, h1, d0, d1, h)), dh, _margin(prim)(x, t),
                     ca.norm_2(e), s, h, u_raw, u, *([x] if with_state else []))
    # small SX loops: cse saves 1-8 % of C; an MX graph around a large loop (itself with cse) gains
    # nothing measurable from it (bench/bench_jit.py)
    return cse_sx(ca.Function("body", [z], [ca.vertcat(x_next, t + h, s + h, xs, hold_next), out])), nz


def _guarded_body(prim: CompiledPrimitive, dt: float, with_state: bool, boundaries: bool) -> tuple:
    """_step_body for a loop with guards: the step ends where a guard first crosses (pieces.py)."""
    start, end, _f = _ends(prim)
    body = guarded_body(prim, dt, start, end, compiled_jump(prim), _margin(prim), with_state, boundaries,
                        _h_rows(len(prim.h_names)))
    return body, 2 * prim.system.nx + 2


def _h_rows(nh: int):
    """(h0, h1, d0, d1, h, act) -> the rows h and lb of a step (masked outside their windows)."""
    return lambda h0, h1, d0, d1, h, act: _masked(act, nh, h0, _sample_bound(h0, h1, d0, d1, h))


def _sample_bound(h0, h1, d0, d1, h):
    """The least value over a step of a function with |dh/dt| <= L taking h0 and h1 at its ends,
    L the largest of the end rates and the secant slope."""
    L = ca.fmax(ca.fmax(ca.fabs(d0), ca.fabs(d1)), ca.fabs(h1 - h0) / h)
    return (h0 + h1) / 2 - L * h / 2


def _masked(act, nh: int, *values):
    """Each of the h-rows `values` with INACTIVE where the step lies outside the function's window."""
    return [ca.if_else(act, v, INACTIVE) for v in values] if nh else list(values)


def _accumulate(prefix: str, prim: CompiledPrimitive, dt: float, K: int, with_state: bool, boundaries: bool,
                body: ca.Function, nz: int) -> ca.Function:
    """Z -> (Z after K steps of `body`, every step's outputs), named by what it was built from."""
    Z = ca.MX.sym("Z", nz)
    zs, outs = body.mapaccum("acc", K)(Z)
    name = prefix + hashlib.sha1(f"{prim.name}{dt}{K}{with_state}{boundaries}".encode()).hexdigest()[:10]
    return ca.Function(name, [Z], [zs[:, -1], outs])


def _build_doubling(prim: CompiledPrimitive, dt: float, K: int, jit: bool, flags: tuple[str, ...],
                    with_state: bool, boundaries: bool) -> Chunk:
    body, nz = step_body(prim, dt, with_state, boundaries, doubling=True)
    fn = _accumulate("chunk2_", prim, dt, K, with_state, boundaries, body, nz)
    fn = compile_cached(fn, caller_flags(prim, flags), libs_of(prim)) if jit else fn
    return Chunk(prim, dt, K, fn, len(prim.h_names), prim.system.nu,
                 Rows(len(prim.h_names), prim.system.nu, prim.system.nx if with_state else 0, doubling=True))


def _doubling_body(prim: CompiledPrimitive, dt: float, with_state: bool, boundaries: bool) -> tuple[ca.Function, int]:
    """One step of step doubling: the judged rollout takes two RK4 half steps per step while a
    companion rollout x_c takes one full step from its own state, both with the same clock, jumps
    and boundaries. RK4's global error shrinks 16x when the step halves, so |h(x) - h(x_c)| at each
    sample (and at each step's end, before the jump) estimates the judged rollout's error in h
    about 15 times over; likewise for the RoA margin. The estimate is the error the closed loop
    really propagates: it shrinks where the loop contracts instead of adding up step by step.
    The augmented state is [x; t; s; x_sw; x_c] and a sampled law's hold (hold_size)."""
    nx, nh = prim.system.nx, len(prim.h_names)
    if guarded(prim):
        start = _ends(prim)[0]
        body = guarded_doubling_body(prim, dt, start, _at_end(prim, start), loop_of(prim), compiled_jump(prim),
                                     _margin(prim), with_state, boundaries, _h_rows(nh))
        return body, 3 * nx + 2
    held = prim.sampled is not None
    start, _end, f = _ends(prim, held)
    loop = loop_of(prim, held)
    jump = compiled_jump(prim)
    nz = 3 * nx + 2 + hold_size(prim, doubling=True)
    z = _sym(prim.f_cl, prim)("z", nz)
    x, t, s, xs, xc = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2], z[2 * nx + 2:3 * nx + 2]
    # a sampled law: each rollout solves it at its own start state and holds it over the whole step
    U, hold_next = hold_inputs(prim, dt, z[3 * nx + 2:], [(x, t, s, xs), (xc, t, s, xs)])
    Uj, Uc = U[:1], U[1:]
    fj, fc = (lambda xx, tt, ss: f(xx, tt, ss, xs, *Uj)), (lambda xx, tt, ss: f(xx, tt, ss, xs, *Uc))
    tc = wrap(prim, t)
    h, edge = step_length(prim, dt, tc, x, s, edge=True) if boundaries else (ca.DM(dt), None)
    te = step_end(prim, h, edge)
    k1, h0, d0, u_raw, u = start(x, t, s, xs, *Uj)
    kc1, h0c, _uc_raw, uc = loop(xc, t, s, xs, *Uc)
    hh = h / 2
    x_mid, _ = rk4(fj, x, (t, s), hh, hh, k1)
    x_end, _ = rk4(fj, x_mid, (t + hh, s + hh), hh, te - hh)
    xc_end, _ = rk4(fc, xc, (t, s), h, te, kc1)
    h1, d1 = _at_end(prim, start)(x_end, t + te, s + te, xs, *Uj)  # h and its rate at the step's end
    h1c = loop(xc_end, t + te, s + te, xs, *Uc)[1]
    x_next, xc_next = jump(x_end, u, t + h, s + h), jump(xc_end, uc, t + h, s + h)
    act = active(prim, wrap(prim, t + h / 2), x, s, x_next, h)
    m_f, m_c = _margin(prim)(x, t), _margin(prim)(xc, t)
    out = ca.vertcat(*_masked(act, nh, h0, _sample_bound(h0, h1, d0, d1, h)), ca.fabs(h1 - h1c), m_f,
                     ca.fabs(m_f - m_c), s, h, u_raw, u, *([x] if with_state else []), ca.fabs(h0 - h0c))
    return cse_sx(ca.Function("body", [z], [ca.vertcat(x_next, t + h, s + h, xs, xc_next, hold_next), out])), nz


def start_states(prim: CompiledPrimitive, x0s: np.ndarray, t0s: np.ndarray, doubling: bool = False) -> np.ndarray:
    """Augmented start states z, one column per row of x0s switched in at the clock t0s."""
    X = np.asarray(x0s, float).T
    t = np.asarray(t0s, float)[None, :]
    block = np.repeat(hold_start(prim, doubling)[:, None], X.shape[1], axis=1)
    return np.vstack([X, t, np.zeros_like(t), X] + ([X] if doubling else []) + [block])


def build_first(prim: CompiledPrimitive, dt: float, jit: bool = True) -> ca.Function:
    """z -> (h at the start with step 0's windows, RoA margin, u_raw, u), mapped over many start
    points in one call: the data that decides rollouts already at their first sample. A large loop
    is not compiled here: it runs in CasADi's virtual machine, calling the loop library if attached."""
    key = ("first", dt, attached(prim) is not None)
    if key not in prim.cache:
        nx = prim.system.nx
        start, _end, _f = _ends(prim)
        z = _sym(prim.f_cl, prim)("z", 2 * nx + 2)
        x, t, s, xs = z[:nx], z[nx], z[nx + 1], z[nx + 2:]
        tc = wrap(prim, t)
        h = step_length(prim, dt, tc, x, s)
        _k1, h0, _d0, u_raw, u = start(x, t, s, xs)
        act = active(prim, wrap(prim, t + h / 2), x, s, h=h)
        hm = ca.if_else(act, h0, INACTIVE) if prim.h_names else h0
        fn = ca.Function("first_" + hashlib.sha1(f"{prim.name}{dt}".encode()).hexdigest()[:10], [z],
                         [hm, _margin(prim)(x, t), u_raw, u])
        small = prim.loop.is_a("SXFunction") and prim.f_cl.n_nodes() <= INLINE_NODES \
            and prim.roa_margin.is_a("SXFunction")
        # run once per start: unoptimised (tcc builds it in milliseconds); large loops: not worth a compile
        prim.cache[key] = compile_cached(fn, ("-O0",)) if jit and small else fn
    return prim.cache[key]


def initial_state(prim: CompiledPrimitive, x0: np.ndarray, t0: float) -> np.ndarray:
    """z at switch-in of a chunk with error 'local': clock t0, zero time since switch, x_sw = x0 (and
    a sampled law's hold, due at once)."""
    return np.concatenate([x0, [t0, 0.0], x0, hold_start(prim)])
