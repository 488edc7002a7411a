"""Three-valued, error-aware verdicts of the safety oracle from per-step rollout data.

A backend hands over, for a block of steps of many rollouts, each safety function at the samples
(`h`), a lower bound of it over each step (`lb`: from its values and rates along the flow at both
ends), the integration error mapped onto it (`dh`), the RoA margin, the local error norm, the
times and the inputs. The judge keeps the running error estimates and decides, in time order:

- C first at each sample: a value below -tol even after adding its error estimate is a certain
  violation (unsafe); a value within its error of -tol is a doubt;
- E next: the flow is inside E when the RoA margin exceeds its own error estimate (safe, unless a
  doubt came before: then inconclusive);
- then the step that follows: a lower bound within its error of -tol is a doubt.

A doubt does not end the rollout: a certain violation after it is still one (unsafe: the flow leaves
C whatever happened in the doubtful stretch), while E entered, the horizon reached or a non-finite
value after it leaves the call inconclusive, at the first doubt's time. A safe verdict therefore means
that every active safety function stayed above -tol by more than what the numerics can hide, between
samples as well as at them, until the flow was inside E.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compile.events import EventWindow
from ..compile.primitive import INACTIVE, CompiledPrimitive
from .evidence import OracleEvidence, Reason

SAFE, UNSAFE, INCONCLUSIVE = "safe", "unsafe", "inconclusive"


@dataclass
class Block:
    """K steps of m rollouts; h, lb, dh are (nh, m, K), u and u_raw (nu, m, K), the rest (m, K)."""

    h: np.ndarray
    lb: np.ndarray
    dh: np.ndarray
    margin: np.ndarray
    err: np.ndarray
    s: np.ndarray
    dt: np.ndarray
    u_raw: np.ndarray
    u: np.ndarray
    finite: np.ndarray  # (m, K): every output of the step (and, for the last, the end state) is finite
    ds: np.ndarray | None = None  # step doubling: absolute error of h at the samples (dh, err absolute too)
    span: float = 0.0  # step doubling: the envelope's decay length (s), ENVELOPE_STEPS oracle steps


class Carry:
    """What each rollout in flight has accumulated: error estimates, least values, peaks."""

    FIELDS = ("eh", "en", "en_env", "min_h", "low", "count", "best_m", "peak", "peak_raw", "sat", "nsteps", "doubted",
              "t_doubt", "maybe_e")

    def __init__(self, nh: int, nu: int, m: int = 0):
        self.eh = np.zeros((nh, m))  # integration error estimate of each h so far
        self.en = np.zeros(m)  # sum of local error norms so far
        self.en_env = np.zeros(m)  # step doubling: the margin's error envelope, decayed to the next sample
        self.min_h = np.full((nh, m), np.inf)  # least sampled value
        self.low = np.full((nh, m), np.inf)  # least error-aware lower bound
        self.count = np.zeros((nh, m), int)  # samples and steps at which each h was active
        self.best_m = np.full(m, -np.inf)
        self.peak = np.zeros((nu, m))
        self.peak_raw = np.zeros((nu, m))
        self.sat = np.zeros(m, bool)
        self.nsteps = np.zeros(m, int)  # steps judged so far
        self.doubted = np.zeros(m, bool)  # a margin of C was within its error at some sample or step
        self.t_doubt = np.full(m, np.nan)  # the time of the first doubt
        self.maybe_e = np.zeros(m, bool)  # some sample may have been inside E (within the margin's error)

    def extend(self, k: int) -> None:
        new = Carry(self.eh.shape[0], self.peak.shape[0], k)
        for f in self.FIELDS:
            setattr(self, f, np.concatenate([getattr(self, f), getattr(new, f)], axis=-1))

    def keep(self, mask: np.ndarray) -> None:
        for f in self.FIELDS:
            setattr(self, f, getattr(self, f)[..., mask])


@dataclass
class Decision:
    """Per rollout of a block: done, kind and the index of the deciding sample.

    kind: 'safe', 'left_C', 'non_finite', 'horizon', 'doubt' (a margin of C within its error),
    'doubt_E' (E perhaps entered before C was left or the horizon reached) or '' (undecided).
    """

    done: np.ndarray
    kind: np.ndarray
    k: np.ndarray


@dataclass
class _Errors:
    """Error-aware tests of one block, (m, K) per sample k (and per step k for doubt_t): a certain
    violation of C, a doubt at a sample, a doubt over a step; the least values (nh, m, K) minus
    their error estimates at the samples (low_s) and over the steps (low_t); the estimates of h's
    error at the steps' ends (eh_e) and their running sum (cdh), of the margin's error at the samples
    (en_s) and its running sum (cen). Without safety functions the h-parts are None."""

    viol: np.ndarray
    doubt_s: np.ndarray
    doubt_t: np.ndarray
    low_s: np.ndarray | None = None
    low_t: np.ndarray | None = None
    eh_e: np.ndarray | None = None
    cdh: np.ndarray | None = None
    en_s: np.ndarray | None = None
    cen: np.ndarray | None = None


def judge(b: Block, c: Carry, T: np.ndarray, tol: float, c_margin: float, lo: np.ndarray, hi: np.ndarray) -> Decision:
    """Decide what can be decided in this block and fold its judged part into the carry."""
    nh, m, K = b.lb.shape if b.lb.ndim == 3 else (0, *b.margin.shape)
    e = _errors(b, c, tol, nh, m)
    valid = b.s <= T[:, None] + 1e-9
    valid_t = b.s + b.dt <= T[:, None] + 1e-9
    kind, first, k, kc, horizon, big = _decide(b, c, e, valid, valid_t, c_margin)
    # judged part: samples up to the decision, steps before it (and the doubtful step itself)
    n_s = np.where(first < big, k + 1, valid.sum(axis=1))
    n_t = np.where(first < big, (first + 1) // 2, valid_t.sum(axis=1))
    _fold(b, c, e, n_s, n_t, lo, hi)
    return Decision(kind != "", kind, np.where(horizon, np.maximum(n_s - 1, 0), kc))


def _errors(b: Block, c: Carry, tol: float, nh: int, m: int) -> _Errors:
    """The block's error estimates (running on from the carry's, or absolute under step doubling)
    and the tests of C they give."""
    K = b.margin.shape[1]
    absolute = b.ds is not None  # step doubling: the estimates are absolute, not per step
    if absolute:
        env = envelope(b, c)
    if nh:
        if absolute:
            (eh_s, eh_e), cdh = env[:2], None
        else:
            cdh = np.cumsum(b.dh, axis=2)
            eh_s = c.eh[:, :, None] + cdh - b.dh  # error estimate at sample k
            eh_e = c.eh[:, :, None] + cdh  # at the end of step k
        # inactive functions hold INACTIVE (1e9): never binding, and left out of the reported least values
        low_s = b.h - eh_s
        low_t = b.lb - eh_e
        e = _Errors(((b.h + eh_s) < -tol).any(axis=0), (low_s < -tol).any(axis=0), (low_t < -tol).any(axis=0),
                    low_s, low_t, eh_e, cdh)
    else:
        e = _Errors(*(np.zeros((m, K), bool),) * 3)
    if absolute:
        e.en_s, e.cen = env[2:]
    else:
        e.cen = np.cumsum(b.err, axis=1)
        with np.errstate(invalid="ignore"):
            e.en_s = c.en[:, None] + e.cen - b.err
    return e


ENVELOPE_STEPS = 6
"""Under step doubling, the error estimate at a sample is the envelope of the two rollouts' differences:
the larger of this sample's and the previous estimate decayed by 1 - dt_step / (ENVELOPE_STEPS dt) per
step. The difference is signed in effect (the judged and companion errors cross where the flow turns),
so it passes through zero where the judged error does not; the envelope spans such dips (on the A1's
Stand -> Walk(in_place) the raw difference falls short of the error by 2x 10 ms after a lift ramp, the
envelope covers it with a factor 2.3 to spare), and decays where the loop contracts."""


def envelope(b: Block, c: Carry) -> tuple:
    """Step doubling's estimates of one block, (eh_s, eh_e, en_s, en_env): h's at the samples and the
    steps' ends, the margin's at the samples, and the margin's envelope decayed past each step, running
    on from the carry's (eh: at the last step's end; en_env)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        dec = np.maximum(0.0, 1.0 - b.dt / b.span)
    eh_s, eh_e = np.empty_like(b.ds), np.empty_like(b.dh)
    en_s, en_env = np.empty_like(b.err), np.empty_like(b.err)
    prev, prev_m = c.eh, c.en_env
    for k in range(b.err.shape[1]):
        if eh_s.size:
            eh_s[:, :, k] = np.fmax(b.ds[:, :, k], prev)
            eh_e[:, :, k] = prev = np.fmax(b.dh[:, :, k], eh_s[:, :, k] * dec[None, :, k])
        en_s[:, k] = np.fmax(b.err[:, k], prev_m)
        en_env[:, k] = prev_m = en_s[:, k] * dec[:, k]
    return eh_s, eh_e, en_s, en_env


def _decide(b: Block, c: Carry, e: _Errors, valid: np.ndarray, valid_t: np.ndarray, c_margin: float):
    """(kind, first event's position, its sample k, k within the block, reached the horizon, the
    position standing for none) of each rollout, in time order: C at a sample, then E, then the
    step after it. A doubt (at a sample or over a step) only marks the rollout (Carry.doubted): a
    certain violation after it decides unsafe, E, the horizon or a non-finite value inconclusive."""
    m, K = b.margin.shape
    viol, bad = e.viol, ~b.finite
    hard = (viol | bad) & valid
    enter = (b.margin - c_margin * e.en_s > 0) & valid
    big = 2 * K + 2
    pos_h = np.where(hard.any(axis=1), 2 * hard.argmax(axis=1), big)
    pos_e = np.where(enter.any(axis=1), 2 * enter.argmax(axis=1), big)
    soft_s, soft_t = e.doubt_s & ~viol & ~bad & valid, e.doubt_t & valid_t
    pos_d = np.minimum(np.where(soft_s.any(axis=1), 2 * soft_s.argmax(axis=1), big),
                       np.where(soft_t.any(axis=1), 2 * soft_t.argmax(axis=1) + 1, big))
    first = np.minimum(pos_h, pos_e)
    rows = np.arange(m)
    k = first // 2
    kc = np.minimum(k, K - 1)
    doubted = c.doubted | (pos_d <= np.minimum(first, big - 1))  # at a sample, C's doubt comes before E
    kind = np.full(m, "", dtype=object)
    is_h = (pos_h == first) & (first < big)
    # a violation after a sample that may have been inside E does not show the switch unsafe
    maybe = c.maybe_e[:, None] | np.logical_or.accumulate((b.margin + c_margin * e.en_s > 0) & valid, axis=1)
    maybe_v = maybe.copy()
    maybe_v[c.nsteps == 0, 0] = False  # at the switch-in instant, E cannot have been entered before C was left
    nf = is_h & bad[rows, kc]
    kind[nf] = np.where(doubted[nf], "doubt", "non_finite")
    kind[is_h & ~bad[rows, kc] & ~maybe_v[rows, kc]] = "left_C"
    kind[is_h & ~bad[rows, kc] & maybe_v[rows, kc]] = "doubt_E"
    is_e = ~is_h & (pos_e == first) & (first < big)
    kind[is_e] = np.where(doubted[is_e], "doubt", "safe")
    horizon = (first >= big) & ((~valid).any(axis=1) | ~valid_t[:, -1])
    kind[horizon] = np.where(doubted[horizon], "doubt", np.where(maybe[:, -1][horizon], "doubt_E", "horizon"))
    new = ~c.doubted & doubted
    c.t_doubt = np.where(new, b.s[rows, np.minimum(pos_d // 2, K - 1)], c.t_doubt)
    c.doubted = doubted
    c.maybe_e = maybe[:, -1]
    return kind, first, k, kc, horizon, big


LANES = 8


def lane_sum(a: np.ndarray) -> np.ndarray:
    """Sum over the last axis in LANES lanes: lane q adds the entries q, q + 8, ... one after the
    other, then ((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7)). For 64 entries this is numpy's
    own summation (pairwise, unrolled by 8); the compiled judge (judged.py) folds its lanes the same
    way, so a rollout's error sums depend on its own samples only, never on its batch."""
    K = a.shape[-1]
    pad = (-K) % LANES
    if pad or not K:
        a = np.concatenate([a, np.zeros(a.shape[:-1] + (pad or LANES,))], axis=-1)
    r = a[..., :LANES].copy()
    for q in range(LANES, a.shape[-1], LANES):
        r = r + a[..., q:q + LANES]
    return ((r[..., 0] + r[..., 1]) + (r[..., 2] + r[..., 3])) + ((r[..., 4] + r[..., 5]) + (r[..., 6] + r[..., 7]))


def _fold(b: Block, c: Carry, e: _Errors, n_s: np.ndarray, n_t: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    """Fold the first n_s samples and n_t steps of each rollout into the carry: least values, counts,
    error estimates, the best RoA margin and the input's peaks and saturation."""
    m, K = b.margin.shape
    ar, rows = np.arange(K), np.arange(m)
    absolute = b.ds is not None
    js = ar[None, :] < n_s[:, None]
    jt = ar[None, :] < n_t[:, None]
    if e.low_s is not None:
        low_s, low_t = e.low_s, e.low_t
        full_s, full_t = bool(js.all()), bool(jt.all())  # the common case: no rollout decided in this block
        with np.errstate(invalid="ignore"):
            hs = b.h if full_s else np.where(js[None], b.h, np.inf)
            ls = low_s if full_s else np.where(js[None], low_s, np.inf)
            lt = low_t if full_t else np.where(jt[None], low_t, np.inf)
            c.min_h = np.fmin(c.min_h, np.fmin.reduce(hs, axis=2))
            c.low = np.fmin(c.low, np.fmin(np.fmin.reduce(ls, axis=2), np.fmin.reduce(lt, axis=2)))
        c.count += (hs < INACTIVE / 2).sum(axis=2) + (lt < INACTIVE / 2).sum(axis=2)
        if absolute:
            last = np.clip(n_t - 1, 0, K - 1)
            c.eh = np.where(n_t > 0, e.eh_e[:, rows, last], c.eh)
        else:
            c.eh = c.eh + lane_sum(b.dh if full_t else np.where(jt[None], b.dh, 0.0))
    if absolute:  # the margin's error at the last judged sample, and its envelope after that step
        c.en = np.where(n_s > 0, e.en_s[rows, np.clip(n_s - 1, 0, K - 1)], c.en)
        c.en_env = np.where(n_s > 0, e.cen[rows, np.clip(n_s - 1, 0, K - 1)], c.en_env)
    else:
        c.en = c.en + lane_sum(np.where(jt, b.err, 0.0))
    c.nsteps = c.nsteps + n_t
    with np.errstate(invalid="ignore"):
        c.best_m = np.maximum(c.best_m, np.where(js & ~np.isnan(b.margin), b.margin, -np.inf).max(axis=1))
        if b.u.shape[0]:
            c.peak = np.maximum(c.peak, np.where(js[None] & np.isfinite(b.u), np.abs(b.u), 0.0).max(axis=2))
            c.peak_raw = np.maximum(c.peak_raw, np.where(js[None] & np.isfinite(b.u_raw), np.abs(b.u_raw), 0.0).max(axis=2))
            c.sat |= (((b.u_raw < lo[:, None, None]) | (b.u_raw > hi[:, None, None])) & js[None]).any(axis=(0, 2))


DOUBT = "a safety margin is within the numerical error bound"
AFTER_DOUBT = "certainly left C after a margin within its numerical error bound at"
DOUBT_E = ("the flow may have entered E (its margin is within the numerical error bound) "
           "but E was not entered beyond doubt before C was left or the horizon was reached")


def evidences(prim: CompiledPrimitive, b: Block, c: Carry, d: Decision, cols: np.ndarray, t0s, c_margin: float,
              messages: dict | None = None) -> list[OracleEvidence]:
    """Evidence of the decided rollouts `cols` of a block, built in bulk (columns of the carry and
    the block are converted to Python numbers once)."""
    if not len(cols):
        return []
    names = prim.h_names
    k = d.k[cols].astype(int)
    td = c.t_doubt[cols]
    t = np.where((d.kind[cols] == "doubt") & np.isfinite(td), td, b.s[cols, k]).tolist()  # a doubt: its first one's time
    doubted = np.isfinite(td).tolist()
    td_l = td.tolist()
    kinds = d.kind[cols].tolist()
    entry = b.margin[cols, k].tolist()
    entry_err = (c_margin * c.en[cols]).tolist()
    hv = np.where(b.h[:, cols, k] < INACTIVE / 2, b.h[:, cols, k], np.inf) if len(names) else None
    first_bad = np.argmin(hv, axis=0).tolist() if len(names) else []
    min_h, low, count = c.min_h[:, cols], c.low[:, cols], c.count[:, cols]
    with np.errstate(invalid="ignore"):
        ms = np.fmin.reduce(min_h, axis=0) if len(names) else np.full(len(cols), np.inf)
        lw = np.fmin.reduce(low, axis=0) if len(names) else np.full(len(cols), np.inf)
        worst = np.argmin(low, axis=0).tolist() if len(names) else []
    clean = bool((np.abs(min_h) < INACTIVE / 2).all() and (np.abs(low) < INACTIVE / 2).all())
    min_l, low_l = (min_h.T.tolist(), low.T.tolist()) if clean else (_or_none(min_h).T.tolist(), _or_none(low).T.tolist())
    windows = any(w is not None for w in prim.windows)
    check = (~count.all(axis=0) | windows).tolist() if len(names) else [False] * len(cols)
    ms_l, lw_l = _or_none(ms).tolist(), _or_none(lw).tolist()
    steps, best = c.nsteps[cols].tolist(), c.best_m[cols].tolist()
    peak, peak_raw, sat = c.peak[:, cols].T.tolist(), c.peak_raw[:, cols].T.tolist(), c.sat[cols].tolist()
    out = []
    for n, j in enumerate(cols.tolist()):
        kind, tn = kinds[n], t[n]
        if kind == "safe":
            ev = OracleEvidence(1, Reason.ENTERED_E, tn, t_enter=tn, status=SAFE, entry_margin=entry[n],
                                entry_error=entry_err[n])
        elif kind == "left_C":
            ev = OracleEvidence(0, Reason.LEFT_C, tn, violated=names[first_bad[n]], status=UNSAFE,
                                message=f"{AFTER_DOUBT} {td_l[n]:.6g} s" if doubted[n] else "")
        elif kind == "non_finite":
            ev = OracleEvidence(0, Reason.INTEGRATION_FAILED, tn, status=UNSAFE,
                                message=(messages or {}).get(j) or "non-finite value")
        elif kind in ("doubt", "doubt_E"):
            ev = OracleEvidence(0, Reason.INCONCLUSIVE, tn, status=INCONCLUSIVE, message=DOUBT if kind == "doubt" else DOUBT_E,
                                violated=names[worst[n]] if kind == "doubt" and names else None)
        else:
            ev = OracleEvidence(0, Reason.HORIZON, tn, status=UNSAFE)
        ev.steps = steps[n]
        ev.min_margins, ev.lower_bounds = dict(zip(names, min_l[n])), dict(zip(names, low_l[n]))
        if names:
            m0, l0 = ms_l[n], lw_l[n]
            if kind == "doubt":  # the doubted function's own least sample and bound (its lower bound is the least)
                m0, l0 = min_l[n][worst[n]], low_l[n][worst[n]]
            ev.margin = m0
            ev.error_bound = m0 - l0 if m0 is not None and l0 is not None else None
            if kind == "doubt" and ev.error_bound is not None and ev.error_bound > 1e3 * max(1.0, abs(m0)):
                ev.message = (f"the integration error estimate ({ev.error_bound:.3g}) dwarfs the margin ({m0:.3g}): "
                              "the step is too large for this closed loop (numerical blow-up); decrease dt")
        ev.best_roa_margin = best[n]
        ev.peak_input, ev.peak_demand, ev.saturated = peak[n], peak_raw[n], sat[n]
        missing = unevaluated(prim, float(t0s[n]), tn, count[:, n]) if check[n] else None
        if missing:
            ev = OracleEvidence(0, Reason.ERROR, tn, status=INCONCLUSIVE, violated=missing,
                                message=f"safety function {missing} was never evaluated in its active window")
        else:
            ev.checked = True
        out.append(ev)
    return out


def _or_none(a: np.ndarray) -> np.ndarray:
    """a as objects, None where a value is NaN, infinite or INACTIVE (a function never active)."""
    with np.errstate(invalid="ignore"):
        return np.where((a == a) & (np.abs(a) < INACTIVE / 2), a, None)


def evidence(prim: CompiledPrimitive, b: Block, c: Carry, d: Decision, j: int, t0: float, c_margin: float,
             message_nonfinite: str = "") -> OracleEvidence:
    """Evidence of rollout j of a decided block (carry and block columns j)."""
    return evidences(prim, b, c, d, np.array([j]), [t0], c_margin, {j: message_nonfinite})[0]


def unevaluated(prim: CompiledPrimitive, t0: float, t1: float, count: np.ndarray) -> str | None:
    """The first safety function whose window overlaps the rollout's clock span but was never evaluated.

    Windows anchored on a contact event are left out: whether and when the event happened is known
    from the rollout's states only (an `after` window is never open when it did not happen, and a
    `before` one is over after the first step when it happened there), and the edges of an open
    one are step ends (flow.step_length)."""
    for i, w in enumerate(prim.windows):
        if count[i] > 0 or t1 <= 0 or isinstance(w, EventWindow):
            continue
        if w is None or _overlaps(w, t0, t0 + t1, prim.period):
            return prim.h_names[i]
    return None


def _overlaps(w: tuple[float, float], a: float, b: float, period: float | None) -> bool:
    """Does [w0, w1) (repeated every period, if any) overlap (a, b) with positive length?"""
    if period is None:
        return min(w[1], b) - max(w[0], a) > 1e-12
    n0, n1 = int(np.floor((a - w[1]) / period)), int(np.ceil((b - w[0]) / period))
    return any(min(w[1] + n * period, b) - max(w[0] + n * period, a) > 1e-12 for n in range(n0, n1 + 1))
