"""The judge inside the compiled chunk: rollouts that carry their own verdict.

A judged chunk advances the augmented state [z; J] step by step, where z is the rollout's (as in
integrator.step_body) and J the judge's: the running error sums, the least values, the peaks, the
decision flag and what the evidence needs from the deciding sample. Every step applies the rules
of oracle/verdict.py to that step's outputs, in the same order and with the same floating-point
operations, so the verdicts and numbers are those of the judge on the full sample array; once a
rollout is decided, its decision and what its evidence reads stay as they were. Python then reads
the decision flags and the J of decided slots only, and a rollout may enter a slot at any chunk
boundary.

With the embedded ('local') error estimates, the judge's error sums run in blocks of B steps from
the rollout's start (B = settings.chunk): in a block, the estimate at a sample is the block's carry
plus the running sum; at the block's end, the carry grows by the block's sum taken in eight lanes
(verdict.lane_sum), as the Python judge folds it. Under step doubling the estimates are absolute;
the judge keeps their envelopes (verdict.envelope) in the slots of the sums.
"""
from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np

from ..compile.primitive import INACTIVE, CompiledPrimitive
from .integrator import Rows, step_body
from .jit import compile_cached, cse_sx, optimising, quick_compiler
from .looplib import attach, caller_flags, compile_callers, guarded, libs_of
from .verdict import ENVELOPE_STEPS, LANES, Block, Carry, Decision, evidences, lane_sum

KINDS = ("", "safe", "left_C", "non_finite", "horizon", "doubt", "doubt_E")
SAFE, LEFT_C, NON_FINITE, HORIZON, DOUBT, DOUBT_E = range(1, 7)
SCALARS = ("T", "zero", "i", "done", "kind", "t_stop", "entry", "why", "dbt", "t_dbt", "maybe", "en_c", "cen",
           "best_m", "sat", "nsteps")
WHY = ("any", "safety function", "RoA margin", "input", "state", "end")
"""Bits of `why` at a non-finite decision: some output, the h rows, the margin, the raw input, the
lower bounds, and the state after the block's last step."""


class Layout:
    """Where each part of J sits: the SCALARS (T the horizon, zero a constant 0 for _probe, i the
    chunk's first position in its block, ...), then hk (h at the deciding sample), eh_c (the block's
    carry of h's error), cdh (its running sum in the block), lh (its eight lanes, lane q at
    [q nh, (q + 1) nh)), min_h, low, count, le (the lanes of the error norms), peak, peak_raw.
    nz: the size of the rollout's z."""

    def __init__(self, nh: int, nu: int, nz: int = 0):
        self.nh, self.nu, self.nz = nh, nu, nz
        sizes = [(n, 1) for n in SCALARS] + [("hk", nh), ("eh_c", nh), ("cdh", nh), ("lh", LANES * nh),
                                              ("min_h", nh), ("low", nh), ("count", nh), ("le", LANES),
                                              ("peak", nu), ("peak_raw", nu)]
        self.parts: dict[str, tuple[int, int]] = {}
        o = 0
        for name, n in sizes:
            self.parts[name] = (o, o + n)
            o += n
        self.size = o

    def slice(self, name: str) -> slice:
        return slice(*self.parts[name])

    def start(self, T: np.ndarray) -> np.ndarray:
        """J at switch-in for horizons T: nothing judged, least values +inf, best margin -inf."""
        J = np.zeros((self.size, len(T)))
        J[self.slice("T")] = T
        for name in ("min_h", "low"):
            J[self.slice(name)] = np.inf
        J[self.slice("best_m")] = -np.inf
        return J


def _lanes_sum(r: list):
    """The sum of LANES lanes in verdict.lane_sum's order."""
    return ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))


def _any(v):
    return ca.DM(0) if v.shape[0] == 0 else ca.mmax(v)


def _probe(zero, *vs):
    """The sum of v * zero over the entries of the vectors vs, zero a state entry that stays 0 (a
    symbol, so that CasADi cannot simplify v * 0 away): 0 when every entry is finite, else NaN."""
    v = ca.vertcat(*[w for w in vs if w.shape[0]])
    return ca.DM(0) if v.shape[0] == 0 else ca.sum1(v * zero)


def _sel(c, a, b):
    """if_else(c, a, b), resolved when c is a Python bool (a static fact of the step's position)."""
    if c is True:
        return a
    if c is False:
        return b
    return ca.if_else(c, a, b)


def _and(a, b):
    """logic_and, resolved when either side is a Python bool."""
    if a is False or b is False:
        return False
    return b if a is True else a if b is True else ca.logic_and(a, b)


def _folded(g: dict, rows: Rows, o, fs, ft, eh_s, eh_e, lo, hi) -> dict:
    """The least values, counts, best margin, peaks and saturation after folding in the sample
    (when fs) and the step (when ft) of the outputs o, as verdict._fold does. A value left out is
    pushed to +-inf by subtracting a masked infinity, never selected with if_else: CasADi's if_else
    adds a zero, which would turn a -0.0 into 0.0 (fmin and fmax ignore the NaN of inf - inf)."""
    h, lb, margin, u_raw, u = o[rows.h], o[rows.lb], o[rows.margin], o[rows.u_raw], o[rows.u]
    low_s, low_t = h - eh_s, lb - eh_e
    off_s, off_t = ca.if_else(fs, 0, -ca.inf), ca.if_else(ft, 0, -ca.inf)
    au, aur = ca.fabs(u), ca.fabs(u_raw)
    out_lo = ca.logic_or(u_raw < ca.DM(lo), u_raw > ca.DM(hi)) if u.shape[0] else ca.DM.zeros(0)
    return {"min_h": ca.fmin(g["min_h"], h - off_s),
            "low": ca.fmin(ca.fmin(g["low"], low_s - off_s), low_t - off_t),
            "count": g["count"] + ca.logic_and(fs, h < INACTIVE / 2) + ca.logic_and(ft, low_t < INACTIVE / 2),
            "best_m": ca.fmax(g["best_m"], margin - ca.if_else(fs, 0, ca.inf)),
            "peak": ca.fmax(g["peak"], ca.if_else(ca.logic_and(fs, au < ca.inf), au, 0)),  # peaks are >= 0
            "peak_raw": ca.fmax(g["peak_raw"], ca.if_else(ca.logic_and(fs, aur < ca.inf), aur, 0)),
            "sat": ca.logic_or(g["sat"], ca.logic_and(fs, _any(out_lo)))}


def _error_sums(g: dict, nh: int, dh, err, fob) -> dict:
    """The running error estimates of the embedded ('local') error: at a block's start the lanes
    join the carry (eh_c, en_c); in the block cdh and cen sum dh and err; eh_s, eh_e and en_s are
    h's estimate at the sample and at the step's end and the margin's at the sample, as
    verdict._errors forms them (carry + cumulative sum - this step's)."""
    lh = [g["lh"][q * nh:(q + 1) * nh] for q in range(LANES)]
    le = [g["le"][q] for q in range(LANES)]
    fold = _and(fob, g["nsteps"] > 0)  # a block ended: its lanes join the carry
    eh_c = _sel(fold, g["eh_c"] + _lanes_sum(lh), g["eh_c"]) if nh else g["eh_c"]
    en_c = _sel(fold, g["en_c"] + _lanes_sum(le), g["en_c"])
    cdh = _sel(fob, dh, g["cdh"] + dh)
    cen = _sel(fob, err, g["cen"] + err)
    return {"eh_c": eh_c, "en_c": en_c, "cdh": cdh, "cen": cen, "eh_s": (eh_c + cdh) - dh, "eh_e": eh_c + cdh,
            "en_s": (en_c + cen) - err, "lh": [_sel(fold, 0, r) for r in lh] if nh else lh,
            "le": [_sel(fold, 0, r) for r in le]}


def judge_step(lay: Layout, rows: Rows, n_out: int, K: int, first: bool, B: int, tol: float, cm: float,
               lo, hi, span: float = 0.0) -> ca.Function:
    """(J, out, zend, last_k) -> J after judging a step of a chunk of K (its first when `first`; its
    last when last_k is 1), whose outputs are `out` (Rows order) and whose end state is zend; see
    verdict.judge for the rules this applies one step at a time.

    Chunks start at block positions i that are multiples of K (K divides B, 8 divides K), so a
    block starts only at a chunk's first step (when i = 0) and ends only at its last (i = B - K).
    The lanes rotate by one every step (R[0] is the current one: no arithmetic), so they are in
    lane order at every chunk's start and end. Two functions serve every step of a chunk, so the
    C of a large judge is generated twice, not K times. A decided rollout folds nothing more and
    keeps its decision (its running sums may run on; en_c + lane_sum of its lanes, which its
    evidence reads, stays). Under step doubling the estimates are the envelopes of the rows'
    differences, decaying over `span` seconds (verdict.envelope)."""
    J, o, zend = ca.SX.sym("J", lay.size), ca.SX.sym("o", n_out), ca.SX.sym("zend", lay.nz)
    last_k = ca.SX.sym("last_k")
    g = {n: J[lay.slice(n)] for n in lay.parts}
    h, lb, dh = o[rows.h], o[rows.lb], o[rows.dh]
    margin, err, s, dt, u_raw, u = o[rows.margin], o[rows.err], o[rows.s], o[rows.dt], o[rows.u_raw], o[rows.u]
    nh, i, live = lay.nh, g["i"], g["done"] < 0.5
    fob = i == 0 if first else False
    last = False if first else ca.logic_and(last_k, i == B - K)
    sums = _error_sums(g, nh, dh, err, fob) if not rows.doubling else {}
    if rows.doubling:  # the envelopes of the two rollouts' differences (verdict.envelope); cdh and cen carry them
        dec = ca.fmax(0, 1 - dt / span)
        eh_s = ca.fmax(o[rows.ds], g["cdh"])
        eh_e = ca.fmax(dh, eh_s * dec)
        en_s = ca.fmax(err, g["cen"])
    else:
        eh_s, eh_e, en_s = sums["eh_s"], sums["eh_e"], sums["en_s"]
    viol, doubt_s = _any((h + eh_s) < -tol), _any((h - eh_s) < -tol)
    doubt_t = _any((lb - eh_e) < -tol)
    probes = [_probe(g["zero"], v) for v in (h, margin, u_raw, lb)]
    any_bad = (probes[0] + probes[1] + probes[2] + probes[3] + _probe(g["zero"], dh, err, s, dt, u, o[rows.u.stop:])) != 0
    parts = [p != 0 for p in probes]
    end_bad = _and(last, _probe(g["zero"], zend) != 0)
    bad = any_bad if end_bad is False else ca.logic_or(any_bad, end_bad)
    lim = g["T"] + 1e-9
    valid, valid_t = s <= lim, (s + dt) <= lim
    ment, mmay = margin - cm * en_s > 0, margin + cm * en_s > 0
    maybe = ca.logic_or(g["maybe"], ca.logic_and(valid, mmay))
    at_switch_in = _and(fob, g["nsteps"] == 0)  # E cannot have been entered before C was left
    maybe_v = maybe if at_switch_in is False else ca.logic_and(maybe, ca.logic_not(at_switch_in))
    # kinds as sums of 0/1 flags times codes (exact small integers; fewer operations than if_else)
    # the judge's order at this sample: C (a certain violation or failure decides; a doubt marks), E,
    # the horizon; then the step, whose doubt marks too (verdict._decide)
    nbad = ca.logic_not(bad)
    hard = ca.logic_and(valid, ca.logic_or(viol, bad))
    soft_s = ca.logic_and(ca.logic_and(valid, doubt_s), ca.logic_and(ca.logic_not(viol), nbad))
    dbt = g["dbt"] > 0.5
    dbt_s = ca.logic_or(dbt, soft_s)
    entered = ca.logic_and(valid, ment)
    nhard = ca.logic_not(hard)
    is_e = ca.logic_and(nhard, entered)
    ends = ca.logic_and(ca.logic_and(nhard, ca.logic_not(entered)),
                        ca.logic_or(ca.logic_not(valid), ca.logic_not(valid_t)))
    h_kind = bad * (NON_FINITE + (DOUBT - NON_FINITE) * dbt) + nbad * (LEFT_C + (DOUBT_E - LEFT_C) * maybe_v)
    kind = hard * h_kind + is_e * (SAFE + (DOUBT - SAFE) * dbt_s) + \
        ends * (dbt_s * DOUBT + ca.logic_not(dbt_s) * (HORIZON + (DOUBT_E - HORIZON) * maybe))
    fs = ca.logic_and(live, valid)
    ft = ca.logic_and(ca.logic_and(live, valid_t), ca.logic_and(ca.logic_and(valid, nhard), ca.logic_not(entered)))
    step_doubt = ca.logic_and(ft, doubt_t)
    new_doubt = ca.logic_and(live, ca.logic_or(soft_s, step_doubt))  # a decided rollout keeps what it had
    t_dbt = ca.if_else(dbt, g["t_dbt"], ca.if_else(new_doubt, s, g["t_dbt"]))
    decided = ca.logic_and(live, kind > 0)
    new = dict(g)
    new.update({n: v for n, v in sums.items() if n in lay.parts}, maybe=maybe)
    if not first:
        new["i"] = ca.if_else(last_k, ca.if_else(i == B - K, 0, i + K), i)
    new["dbt"] = ca.logic_or(dbt, new_doubt)
    new["t_dbt"] = t_dbt
    new.update(_folded(g, rows, o, fs, ft, eh_s, eh_e, lo, hi))
    if rows.doubling:  # the margin's error at the last sample judged; the envelopes run on
        new["en_c"] = ca.if_else(fs, en_s, g["en_c"])
        new["cdh"], new["cen"] = eh_e, en_s * dec
    else:
        lh, le = sums["lh"], sums["le"]
        new["lh"] = ca.vertcat(*lh[1:], lh[0] + ca.if_else(ft, dh, 0)) if nh else g["lh"]
        new["le"] = ca.vertcat(*le[1:], le[0] + ca.if_else(ft, err, 0))
    new["nsteps"] = g["nsteps"] + ft
    new["done"] = ca.logic_or(g["done"], decided)
    why = [any_bad, *parts, end_bad]
    for n, v in (("kind", kind), ("t_stop", ca.if_else(kind == DOUBT, t_dbt, s)),
                 ("entry", margin), ("hk", h), ("why", sum(p * 2 ** b for b, p in enumerate(why) if p is not False))):
        new[n] = g[n] + ca.if_else(decided, v, 0)  # what the deciding sample left (0 until then)
    return ca.Function("judge_first" if first else "judge_step", [J, o, zend, last_k],
                       [ca.vertcat(*[new[n] for n in lay.parts])])


INLINE_CHUNK = 20000
"""A judged chunk whose body is SX and at most this many nodes over its K steps is one inlined SX
function; larger ones call the body and the judge's steps from an MX graph (each generated once)."""


class JudgedChunk:
    """K compiled judged steps of one primitive: run(Z) advances the columns of [z; J] (nz + J rows)."""

    def __init__(self, prim: CompiledPrimitive, dt: float, fn: ca.Function, nz: int, lay: Layout, K: int,
                 doubling: bool = False):
        self.prim, self.dt, self.fn, self.nz, self.lay, self.K = prim, dt, fn, nz, lay, K
        self.doubling = doubling
        self._buffers: dict = {}

    def bound(self, n: int) -> tuple:
        """(evaluate, z_in, z_final, None): the chunk for a batch of n bound to numpy arrays, as Chunk.bound."""
        return (*self._bound(n)[1:], None)

    def _bound(self, n: int) -> tuple:
        if n not in self._buffers:
            F = self.fn.map(n, "serial")
            buf, ev = F.buffer()
            zin, zf = np.zeros(F.nnz_in(0)), np.zeros(F.nnz_out(0))
            buf.set_arg(0, memoryview(zin))
            buf.set_res(0, memoryview(zf))
            self._buffers[n] = (buf, ev, zin, zf)  # buf keeps the bindings alive
        return self._buffers[n]

    def run(self, Z: np.ndarray) -> np.ndarray:
        """[z; J] of every column after K steps, as a view of an output buffer for this many columns
        (valid until the next call with as many); a failed evaluation raises and leaves the buffer holding
        this call's input: no earlier call's numbers, and a caller whose Z was that view keeps its states
        to run again from."""
        n = Z.shape[1]
        buf, ev, zin, zf = self._bound(n)
        zin.reshape(Z.shape[0], n, order="F")[:] = Z
        ev()
        if buf.ret():
            zf[:] = zin
            raise RuntimeError(f"the compiled rollout failed (status {buf.ret()}): an evaluation inside it "
                               "(e.g. an optimisation-based control law) returned an error")
        return zf.reshape(Z.shape[0], n, order="F")


def build_judged_chunk(prim: CompiledPrimitive, dt: float, K: int, B: int, tol: float, cm: float,
                       jit: bool = True, flags: tuple[str, ...] = ("-O1",), doubling: bool = False) -> JudgedChunk:
    """Compile K judged steps (error 'local', blocks of B steps, tolerance tol, margin gain cm);
    remembered on the primitive. K must divide B and be a multiple of 8 (see judge_step)."""
    if B % K or K % LANES:
        raise ValueError(f"a judged chunk of {K} steps needs blocks of a multiple of {K} and K a multiple of {LANES}")
    key = ("judged", dt, K, B, tol, cm, jit, tuple(flags), doubling)
    if key not in prim.cache:
        if jit:  # a large loop through its compiled library
            attach(prim)
        fn, nz, lay = _judged_function(prim, dt, K, B, tol, cm, doubling)
        fn = compile_cached(fn, caller_flags(prim, _flags(prim, flags)), libs_of(prim)) if jit else fn
        prim.cache[key] = JudgedChunk(prim, dt, fn, nz, lay, K, doubling)
    return prim.cache[key]


GUARDED_FLAGS = ("-O1",)
"""gcc flags (at least) of the chunk of a small loop with guards when no quick compiler (jit.QUICK_CC)
is installed: an MX graph of calls per step (the smooth step, the location in a conditional, the
judge), 73-101 KB of C on the pendulum; at -O1 gcc takes about 0.3 s more per primitive than at -O0
and the chunk runs in about a third of the time, faster than the unguarded loop's inlined chunk at
-O0 (bench/bench_pieces.py). With tcc the chunk keeps the project's flags: on the pendulum, cart and
ladder a cold verify took 11.6-12.5 s against 14.1-14.9 s, the pendulum's 4,930 oracle calls again
(compiled, `--no-cache`) 0.61-0.72 s against 0.50-0.57 s, the reports identical. A chunk that calls
a loop library is compiled at looplib.CALLER_FLAGS: its loop evaluations dominate, and its smooth
step, run at every step, is compiled at jit.HOT_LEVEL inside it (jit.hot_code)."""


def _flags(prim: CompiledPrimitive, flags: tuple[str, ...]) -> tuple[str, ...]:
    """The gcc flags of a judged chunk: `flags`, with GUARDED_FLAGS for a loop with guards where
    `flags` optimise less and gcc would compile it."""
    if not guarded(prim) or optimising(flags) or quick_compiler() is not None:
        return tuple(flags)
    return tuple(f for f in flags if not f.startswith("-O")) + GUARDED_FLAGS


def _judged_function(prim: CompiledPrimitive, dt: float, K: int, B: int, tol: float, cm: float,
                     doubling: bool) -> tuple[ca.Function, int, Layout]:
    """(Z -> [z; J] after K judged steps, nz, the layout of J), uncompiled."""
    body, nz = step_body(prim, dt, doubling=doubling)
    lay = Layout(len(prim.h_names), prim.system.nu, nz)
    n_out = body.size1_out(1)
    rows = Rows(lay.nh, lay.nu, doubling=doubling)
    steps = [judge_step(lay, rows, n_out, K, first, B, tol, cm, prim.system.u_lo, prim.system.u_hi,
                        ENVELOPE_STEPS * dt) for first in (True, False)]
    name = "judged_" + hashlib.sha1(f"{prim.name}{dt}{K}{B}{tol}{cm}{doubling}".encode()).hexdigest()[:10]
    return _chunk(body, steps, nz, lay, K, name), nz, lay


def _chunk(body: ca.Function, steps: list, nz: int, lay: Layout, K: int, name: str) -> ca.Function:
    """K judged steps of `body`."""
    inline = body.is_a("SXFunction") and body.n_nodes() * K <= INLINE_CHUNK
    Z = (ca.SX.sym if inline else ca.MX.sym)("Z", nz + lay.size)
    z, J = Z[:nz], Z[nz:]
    for k in range(K):
        zn, o = body(z)
        z, J = zn, steps[k > 0](J, o, zn, float(k == K - 1))
    fn = ca.Function(name, [Z], [ca.vertcat(z, J)])
    return cse_sx(fn) if inline else fn


def prebuild(prims: list[CompiledPrimitive], dt: float, K: int, B: int, tol: float, margins: dict, flags: tuple,
             doubling: bool = False) -> None:
    """build_judged_chunk with jit for several primitives at once (margins: name -> cm): the loop
    libraries first, then every chunk's C code generated here and gcc run side by side. A primitive
    that cannot be built here is left to its own runner, which reports the error."""
    key = lambda p: ("judged", dt, K, B, tol, margins[p.name], True, tuple(flags), doubling)  # noqa: E731
    new = [p for p in {id(p): p for p in prims}.values() if key(p) not in p.cache]
    for p in new:
        attach(p)  # attached libraries are found at once; build_all compiled the rest side by side
    built = [_judged_function(p, dt, K, B, tol, margins[p.name], doubling) for p in new]
    compiled = compile_callers(new, [b[0] for b in built], [_flags(p, flags) for p in new])
    for p, fn, (_fn, nz, lay) in zip(new, compiled, built):
        p.cache[key(p)] = JudgedChunk(p, dt, fn, nz, lay, K, doubling)


def decided_evidence(ch: JudgedChunk, J: np.ndarray, t0s, cm: float) -> list:
    """Evidence of decided rollouts from their frozen J columns (through verdict.evidences, so it
    reads exactly as the Python judge's)."""
    lay, m = ch.lay, J.shape[1]
    if not m:
        return []
    get = {n: J[lay.slice(n)] for n in lay.parts}
    kind = np.array([KINDS[int(k)] for k in get["kind"][0]], dtype=object)
    one = np.zeros((m, 1))
    b = Block(get["hk"][:, :, None], get["hk"][:, :, None], get["hk"][:, :, None], get["entry"].T.copy(), one,
              get["t_stop"].T.copy(), one, np.zeros((lay.nu, m, 1)), np.zeros((lay.nu, m, 1)), np.ones((m, 1), bool))
    c = Carry(lay.nh, lay.nu, m)
    c.en = get["en_c"][0] if ch.doubling else get["en_c"][0] + lane_sum(get["le"].T)
    c.min_h, c.low, c.count = get["min_h"], get["low"], get["count"].astype(int)
    c.best_m, c.peak, c.peak_raw = get["best_m"][0], get["peak"], get["peak_raw"]
    c.sat, c.nsteps = get["sat"][0] > 0.5, get["nsteps"][0].astype(int)
    c.doubted = get["dbt"][0] > 0.5
    c.t_doubt = np.where(c.doubted, get["t_dbt"][0], np.nan)
    d = Decision(np.ones(m, bool), kind, np.zeros(m, int))
    msgs = {b_: _message(int(w)) for b_, (w, k) in enumerate(zip(get["why"][0], kind)) if k == "non_finite"}
    return evidences(ch.prim, b, c, d, np.arange(m), t0s, cm, msgs)


def _message(why: int) -> str:
    """The non-finite message of the Python runner from the `why` bits."""
    if not why & 1:
        return "non-finite state" if why & 32 else "non-finite output"
    parts = [name for bit, name in enumerate(WHY[1:5], 1) if why & (1 << bit)]
    return "non-finite " + " and ".join(parts or ["state"])
