"""Adversarial soundness campaign for the safety oracle (Definition 4), with exact reference answers.

Definition 4: from x0 at primitive clock t0 the closed loop of B is run; the answer is safe iff some
tau <= T has x(tau) in E = {x : r - ||x - x*||_W > 0} while every active safety function keeps
h >= 0 on [0, tau] (a `when: [a, b]` function is active while the clock t0 + s is in [a, b)).
The oracle may answer "safe", "unsafe" or "inconclusive"; only "safe" is a claim, and a FALSE SAFE
(a "safe" where the exact answer is unsafe) must never happen.

One compiled project serves every case. Its system is a double integrator p'' = u with five
parameter states of zero dynamics, x = [p, v, om, ze, c, w, sg]: the control law
u = -om^2 p - 2 ze om v makes (p, v) a linear damped oscillator whose frequency and damping are
set per case through x0, and c, w, sg set the safety function per case. The parameter states
carry roa weights of 1e-12, so E is (almost) the weighted ball in (p, v); the reference uses the
same formula, weights included. Window offsets are set per case through the start clock t0.

Families (each case randomised with a seeded numpy RNG, positions random w.r.t. the step grid):
  window  h = sg (p - c), active only on a window of width 0.1..0.9 dt (one of five windows, one
          per width, 10 s apart on the clock), at a random offset before (mostly) or after the
          entry into E; violated inside the window by 1e-7..1e-1, or cleared by as much.
  slab    h = |p - c| - w: a keep-out slab the path crosses in 0.1..5 ms at a random point
          before E, or misses by 1e-6..1e-1, or placed uniformly at random.
  graze   h = sg (p - c): a ceiling (floor) a hair below or above the global peak (trough) of a
          damped oscillation before E: 1e-7..1e-3 (80 %) or 1e-3..3e-2 (20 %).
  fast    the same on a lightly damped fast loop (om 80..450 rad/s, zeta 0.03..0.3): the first
          undershoot crosses a floor (ceiling) for 0.3..5 ms, or stays clear of it by as much.

Exact reference (no mpgspec): the closed form of the linear loop through its eigenvalues
(p(s) = Re(c1 e^{l1 s} + c2 e^{l2 s}); checked against scipy.linalg.expm in the tests). Every
extremum of p, and every critical point of the E margin, is a zero of a damped sinusoid
alpha p + beta v; those are bracketed on a grid of at most a twelfth of a half period (so no two
lie in one cell) and bisected to machine precision. Between consecutive critical points p and the
E margin are monotone, so the entry time into E (bisection in the bracketing monotone piece) and
the minimum of every safety function over its active part of [0, tau_E] (at the extrema of p or
the ends; -w when the path crosses the slab's centre) are exact. Cases whose truth is within 1e-9
of a tie (|min h| < 1e-9, a pre-entry approach to E within 1e-9, entry within 1e-9 of T, a window
whose verdict changes when its ends move by 1e-11 s) are discarded and redrawn.

Backends and presets: every case runs through "rk4" at low, medium, high and very_high. The
"scipy" backend integrates one rollout at a time in Python, so it runs a fixed random subset of
SCIPY_PER_FAMILY cases per family (SCIPY_PER_FAMILY * 4 >= 300 cases per preset), the same subset
for every preset.

Run stand-alone: python tests/oracle/adversarial.py [--cases-per-family N] [--backends rk4,scipy]
"""
from __future__ import annotations

import argparse
import concurrent.futures
import math
import multiprocessing
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

# ----------------------------------------------------------------------------- configuration
DT = 0.005  # base step of the presets (high: DT/2, very_high: DT/4)
HORIZON = 2.5
PRESETS = ("low", "medium", "high", "very_high")
BACKENDS = ("rk4", "rk4:doubling", "scipy")  # rk4:doubling is rk4 with error: doubling
FAMILIES = ("window", "slab", "graze", "fast")
CASES_PER_FAMILY = 600
SCIPY_PER_FAMILY = 75
SEED = 20260517

STATES = ("p", "v", "om", "ze", "c", "w", "sg")
PARAM_WEIGHT = 1e-12
WINDOW_FRACTIONS = (0.1, 0.3, 0.5, 0.7, 0.9)  # window widths as fractions of DT
WINDOW_CLOCK0, WINDOW_SPACING = 5.0, 10.0
TIE = 1e-9  # truths closer than this to a tie are discarded
WINDOW_EDGE_JITTER = 1e-11  # a window's verdict must not change when its ends move this much (s)


def window_bounds(k: int) -> tuple[float, float]:
    a = WINDOW_CLOCK0 + WINDOW_SPACING * k
    return a, a + WINDOW_FRACTIONS[k] * DT


# E of each primitive: radius and the weights of p and v (the parameter states weigh PARAM_WEIGHT)
E_SPEC = {
    "Window": (0.03, 1.0, 0.01),
    "Slab": (0.03, 1.0, 0.01),
    "Level": (0.03, 1.0, 0.01),
    "Fast": (0.01, 1.0, 1e-4),
}
PRIM_OF = {"window": "Window", "slab": "Slab", "graze": "Level", "fast": "Fast"}


def project_yaml() -> str:
    """The project under test; the reference below re-implements it by hand."""
    zeros = "[" + ", ".join(["0"] * len(STATES)) + "]"
    out = [
        "project: adversarial",
        "system:",
        "  name: osc_with_parameters",
        "  kind: analytic",
        f"  states: [{', '.join(STATES)}]",
        "  inputs: [u]",
        "  dynamics:",
        "    f: [v, 0, 0, 0, 0, 0, 0]",
        "    g: [[0], [1], [0], [0], [0], [0], [0]]",
        "primitives:",
    ]
    for name, (r, wp, wv) in E_SPEC.items():
        weights = [wp, wv] + [PARAM_WEIGHT] * (len(STATES) - 2)
        out += [
            f"  - name: {name}",
            "    class: fixed",
            f"    setpoint: {{expr: {zeros}}}",
            '    controller: {type: expression, u: ["-om^2*p - 2*ze*om*v"]}',
            "    safe_set:",
        ]
        if name == "Window":
            for k in range(len(WINDOW_FRACTIONS)):
                a, b = window_bounds(k)
                out.append(f'      - {{name: win{k}, h: "sg*(p - c)", when: [{a!r}, {b!r}]}}')
        elif name == "Slab":
            out.append('      - {name: slab, h: "abs(p - c) - w"}')
        else:
            out.append('      - {name: limit, h: "sg*(p - c)"}')
        out.append(f"    roa: {{radius: {r!r}, weights: [{', '.join(repr(x) for x in weights)}]}}")
    out += ["oracle:", f"  horizon: {HORIZON!r}", f"  dt: {DT!r}", "  accuracy: low"]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- exact reference
class Loop:
    """Exact solution of p'' = -om^2 p - 2 ze om p' from (p0, v0) (ze != 1), on [0, horizon]."""

    def __init__(self, om: float, ze: float, p0: float, v0: float, horizon: float = HORIZON):
        assert om > 0 and abs(ze - 1.0) > 1e-3
        root = np.sqrt(complex(ze * ze - 1.0))
        self.l1, self.l2 = om * (-ze + root), om * (-ze - root)
        self.c1 = (v0 - self.l2 * p0) / (self.l1 - self.l2)
        self.c2 = p0 - self.c1
        self.om, self.ze, self.T = om, ze, horizon
        wd = om * math.sqrt(max(1.0 - ze * ze, 0.0))
        half = math.pi / wd if wd > 0 else horizon
        self.ds = min(horizon / 400.0, half / 12.0)  # zeros of a damped sinusoid are `half` apart: one per cell at most
        n = int(math.ceil(horizon / self.ds)) + 1
        self.grid = np.linspace(0.0, horizon, n)
        self.P, self.V = self.pv(self.grid)
        self._zeros: dict = {}

    def pv(self, s):
        s = np.asarray(s, float)
        e1, e2 = self.c1 * np.exp(self.l1 * s), self.c2 * np.exp(self.l2 * s)
        return np.real(e1 + e2), np.real(self.l1 * e1 + self.l2 * e2)

    def p(self, s):
        return self.pv(s)[0]

    def v(self, s):
        return self.pv(s)[1]

    def zeros(self, alpha: float, beta: float) -> np.ndarray:
        """All zeros of f = alpha p + beta v in [0, T], to machine precision.

        Each sign change on the grid brackets one simple zero; a secant start and safeguarded
        Newton steps (f' = alpha v + beta p'', exact) converge to it, vectorised over the brackets.
        """
        key = (alpha, beta)
        if key not in self._zeros:
            f = alpha * self.P + beta * self.V
            exact = self.grid[f == 0.0]
            i = np.flatnonzero(f[:-1] * f[1:] < 0.0)
            a, b, fa, fb = self.grid[i], self.grid[i + 1], f[i], f[i + 1]
            x = a - fa * (b - a) / (fb - fa)
            k2, k1 = -self.om * self.om, -2.0 * self.ze * self.om  # p'' = k2 p + k1 v
            for _ in range(6):
                P, V = self.pv(x)
                fx, dfx = alpha * P + beta * V, alpha * V + beta * (k2 * P + k1 * V)
                done = fx == 0.0
                left = np.sign(fx) == np.sign(fa)  # shrink the bracket [a, b] around the zero
                a, fa = np.where(left, x, a), np.where(left, fx, fa)
                b = np.where(left | done, b, x)
                with np.errstate(divide="ignore", invalid="ignore"):
                    xn = x - fx / dfx
                ok = np.isfinite(xn) & (xn >= a) & (xn <= b)
                x = np.where(done, x, np.where(ok, xn, 0.5 * (a + b)))
            self._zeros[key] = np.sort(np.concatenate([exact, x]))
        return self._zeros[key]

    def extrema(self, lo: float, hi: float) -> np.ndarray:
        """Times where p may take its extremes on [lo, hi]: the ends and the zeros of v inside."""
        z = self.zeros(0.0, 1.0)
        return np.concatenate([[lo, hi], z[(z > lo) & (z < hi)]])

    def p_range(self, lo: float, hi: float) -> tuple[float, float]:
        P = self.p(self.extrema(lo, hi))
        return float(P.min()), float(P.max())

    def margin(self, s, r: float, wp: float, wv: float, K: float):
        P, V = self.pv(s)
        return r - np.sqrt(wp * P * P + wv * V * V + K)

    def entry(self, r: float, wp: float, wv: float, K: float) -> tuple[float | None, bool]:
        """(first time in E or None by T, whether the answer is within TIE of a tie).

        The margin's critical points are the zeros of v and of wp p + wv p''; it is monotone in
        between, so the first entry is in the first piece that ends inside E.
        """
        om, ze = self.om, self.ze
        crit = np.concatenate([[0.0, self.T], self.zeros(0.0, 1.0),
                               self.zeros(wp - wv * om * om, -2.0 * wv * ze * om)])
        crit = np.unique(crit[(crit >= 0.0) & (crit <= self.T)])
        m = self.margin(crit, r, wp, wv, K)
        pos = np.flatnonzero(m > 0.0)
        if m[0] > -TIE:
            return (0.0 if m[0] > 0 else None), True
        if not pos.size:
            return None, bool((m > -TIE).any())
        k = pos[0]
        tie = bool((m[:k] > -TIE).any() or m[k] < TIE)
        tau = brentq(lambda x: float(self.margin(x, r, wp, wv, K)), crit[k - 1], crit[k], xtol=1e-15, rtol=1e-15)
        return float(tau), tie or abs(tau - self.T) < TIE


def h_min(loop: Loop, kind: str, sg: float, c: float, w: float, lo: float, hi: float) -> float:
    """Exact min of a safety function of p over [lo, hi]."""
    d = loop.p(loop.extrema(lo, hi)) - c
    if kind == "slab":  # |p - c| - w: -w where the path meets c, else at an extremum of |p - c|
        return -w if d.min() <= 0.0 <= d.max() else float(np.abs(d).min() - w)
    return float((sg * d).min())


@dataclass
class Truth:
    safe: bool
    tau_E: float | None
    h_min: float  # over the active part of [0, tau_E] (inf when nothing was active)
    tie: bool
    why: str


def reference(prim: str, x0, t0: float, horizon: float = HORIZON) -> Truth:
    """Exact answer of Definition 4 (h_tolerance 0), independent of mpgspec."""
    p0, v0, om, ze, c, w, sg = (float(v) for v in x0)
    r, wp, wv = E_SPEC[prim]
    K = PARAM_WEIGHT * (om * om + ze * ze + c * c + w * w + sg * sg)  # setpoint 0 for the parameters
    loop = Loop(om, ze, p0, v0, horizon)
    tau, tie = loop.entry(r, wp, wv, K)
    end = tau if tau is not None else horizon
    kind = "slab" if prim == "Slab" else "level"
    if prim == "Window":
        hm, why = math.inf, "no window before E"
        for k in range(len(WINDOW_FRACTIONS)):
            a, b = window_bounds(k)
            vals = []
            for jitter in (0.0, WINDOW_EDGE_JITTER, -WINDOW_EDGE_JITTER):  # shrunk and grown windows
                lo, hi = max(a - t0 + jitter, 0.0), min(b - t0 - jitter, end)
                vals.append(h_min(loop, kind, sg, c, w, lo, hi) if hi > lo else math.inf)
            if np.isfinite(vals).any():
                if len({v < 0 for v in vals}) > 1:
                    tie = True
                if vals[0] < hm:
                    hm, why = vals[0], f"win{k}"
    else:
        hm, why = h_min(loop, kind, sg, c, w, 0.0, end), kind
    if np.isfinite(hm) and abs(hm) < TIE:
        tie = True
    safe = tau is not None and hm > 0.0
    reason = "entered E" if safe else ("left C (%s)" % why if hm <= 0.0 else "E not reached")
    return Truth(safe, tau, hm, tie, reason)


# ----------------------------------------------------------------------------- families
@dataclass
class Case:
    family: str
    kind: str
    prim: str
    x0: np.ndarray
    t0: float
    truth: Truth
    status: dict = field(default_factory=dict)  # (backend, preset) -> "safe" | "unsafe" | "inconclusive" | "error"

    def describe(self) -> str:
        p0, v0, om, ze, c, w, sg = self.x0
        t = self.truth
        return (f"{self.family}/{self.kind} {self.prim} x0=[p={p0:.6g}, v={v0:.6g}, om={om:.6g}, ze={ze:.6g}, "
                f"c={c:.10g}, w={w:.6g}, sg={sg:g}] t0={self.t0:.9g}: truth "
                f"{'safe' if t.safe else 'unsafe'} ({t.why}, min h={t.h_min:.3g}, tau_E={t.tau_E})")


def log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _loop_params(rng, om_lo, om_hi, ze_lo, ze_hi, min_sigma):
    while True:
        om = log_uniform(rng, om_lo, om_hi)
        lo = max(ze_lo, min_sigma / om)
        if lo < ze_hi:
            return om, float(rng.uniform(lo, ze_hi))


def _start(rng, prim, om, ze, p_lo, p_hi, v_scale):
    p0 = float(rng.choice([-1.0, 1.0]) * rng.uniform(p_lo, p_hi))
    v0 = float(rng.normal(0.0, v_scale * om * abs(p0)))
    loop = Loop(om, ze, p0, v0)
    r, wp, wv = E_SPEC[prim]
    tau, _ = loop.entry(r, wp, wv, PARAM_WEIGHT * (om * om + ze * ze))  # design only; truth recomputes
    return p0, v0, loop, tau


def gen_window(rng):
    om, ze = _loop_params(rng, 5.0, 30.0, 0.15, 0.9, 5.0)
    p0, v0, loop, tau = _start(rng, "Window", om, ze, 0.3, 1.2, 0.5)
    if tau is None or tau < 0.05:
        return None
    k = int(rng.integers(len(WINDOW_FRACTIONS)))
    a, b = window_bounds(k)
    width = b - a
    if rng.random() < 0.85:
        s_w, kind = float(rng.uniform(0.002, tau - width)), "before_E"
    else:
        s_w, kind = float(rng.uniform(tau + 0.005, HORIZON - 0.01)), "after_E"
    sg = float(rng.choice([-1.0, 1.0]))
    qmin = min(sg * x for x in loop.p_range(s_w, s_w + width))
    delta = log_uniform(rng, 1e-7, 1e-1)
    if rng.random() < 0.5:
        c, kind = sg * (qmin + delta), kind + "_violated"
    else:
        c, kind = sg * (qmin - delta), kind + "_clear"
    return kind, [p0, v0, om, ze, c, 0.0, sg], a - s_w


def gen_slab(rng):
    om, ze = _loop_params(rng, 3.0, 20.0, 0.2, 0.9, 5.0)
    p0, v0, loop, tau = _start(rng, "Slab", om, ze, 0.3, 1.5, 0.3)
    if tau is None or tau < 0.1:
        return None
    g = loop.grid <= tau
    vmax = float(np.abs(loop.V[g]).max())
    cross = log_uniform(rng, 1e-4, 5e-3)  # time to cross the slab
    u = rng.random()
    if u < 0.5:
        ok = np.flatnonzero(g & (loop.grid > 0.01) & (np.abs(loop.V) >= 0.3 * vmax))
        if not ok.size:
            return None
        s_c = float(loop.grid[ok[rng.integers(ok.size)]] + rng.uniform(0, loop.ds))
        c, w, kind = float(loop.p(s_c)), abs(float(loop.v(s_c))) * cross / 2, "crossed"
    else:
        w = vmax * rng.uniform(0.3, 1.0) * cross / 2
        pmin, pmax = loop.p_range(0.0, tau)
        if u < 0.85:
            delta = log_uniform(rng, 1e-6, 1e-1)
            c, kind = (pmax + w + delta, "missed") if rng.random() < 0.5 else (pmin - w - delta, "missed")
        else:
            c, kind = float(rng.uniform(pmin - 0.1, pmax + 0.1)), "uniform"
    return kind, [p0, v0, om, ze, c, w, 1.0], float(rng.uniform(0.0, 1.0))


def _global_extrema(loop: Loop, lo: float, hi: float):
    """Interior global max and min of p on [lo, hi] (None where the extreme is at an end)."""
    z = loop.extrema(lo, hi)
    P = loop.p(z)
    out = []
    for sign, i in ((1.0, int(np.argmax(P))), (-1.0, int(np.argmin(P)))):
        if i >= 2:  # not one of the two ends
            out.append((sign, float(z[i]), float(P[i])))
    return out


def gen_graze(rng):
    om, ze = _loop_params(rng, 4.0, 40.0, 0.08, 0.6, 5.0)
    p0, v0, loop, tau = _start(rng, "Level", om, ze, 0.2, 1.5, 0.3)
    if tau is None or tau < 0.05:
        return None
    ext = _global_extrema(loop, 0.0, tau)
    if not ext:
        return None
    sign, s_pk, p_pk = ext[rng.integers(len(ext))]
    sg = -sign  # a ceiling above a maximum (h = c - p), a floor below a minimum (h = p - c)
    delta = log_uniform(rng, 1e-7, 1e-3) if rng.random() < 0.8 else log_uniform(rng, 1e-3, 3e-2)
    if rng.random() < 0.5:
        c, kind = p_pk - sign * delta, "exceeded"
    else:
        c, kind = p_pk + sign * delta, "cleared"
    return kind, [p0, v0, om, ze, c, 0.0, sg], float(rng.uniform(0.0, 1.0))


def gen_fast(rng):
    om, ze = _loop_params(rng, 80.0, 450.0, 0.03, 0.3, 6.0)
    p0, v0, loop, tau = _start(rng, "Fast", om, ze, 0.03, 0.3, 0.2)
    if tau is None or tau < 0.01:
        return None
    z = loop.zeros(0.0, 1.0)
    z = z[(z > 5e-4) & (z < tau)]
    P = loop.p(z)
    opp = np.flatnonzero(np.sign(P) == -np.sign(p0))
    if not opp.size:
        return None
    s1, p1 = float(z[opp[0]]), float(P[opp[0]])  # the first (deepest) undershoot
    sign = 1.0 if p1 > 0 else -1.0  # a maximum gets a ceiling, a minimum a floor
    wd = om * math.sqrt(1 - ze * ze)
    dur = min(log_uniform(rng, 3e-4, 5e-3), 0.8 * math.pi / wd)
    depth = max(abs(float(loop.p(s1 - dur / 2)) - p1), abs(float(loop.p(s1 + dur / 2)) - p1))
    if rng.random() < 0.5:
        c, kind = p1 - sign * depth, "undershoot_crosses"
    else:
        c, kind = p1 + sign * depth, "undershoot_clear"
    return kind, [p0, v0, om, ze, c, 0.0, -sign], float(rng.uniform(0.0, 1.0))


GENERATORS = {"window": gen_window, "slab": gen_slab, "graze": gen_graze, "fast": gen_fast}


def generate(n_per_family: int = CASES_PER_FAMILY, seed: int = SEED) -> tuple[list[Case], dict]:
    """Cases of every family with their exact answers; ties are discarded and counted."""
    rng = np.random.default_rng(seed)
    cases, discarded = [], {}
    for fam in FAMILIES:
        prim, got, tries = PRIM_OF[fam], 0, 0
        discarded[fam] = 0
        while got < n_per_family:
            tries += 1
            assert tries < 50 * n_per_family, f"family {fam}: generator keeps failing"
            g = GENERATORS[fam](rng)
            if g is None:
                continue
            kind, x0, t0 = g
            x0 = np.asarray(x0, float)
            truth = reference(prim, x0, t0)
            if truth.tie:
                discarded[fam] += 1
                continue
            cases.append(Case(fam, kind, prim, x0, float(t0), truth))
            got += 1
    return cases, discarded


def scipy_subset(cases: list[Case], per_family: int = SCIPY_PER_FAMILY, seed: int = SEED + 1) -> list[int]:
    rng = np.random.default_rng(seed)
    out = []
    for fam in FAMILIES:
        idx = [i for i, c in enumerate(cases) if c.family == fam]
        out += sorted(rng.choice(idx, size=min(per_family, len(idx)), replace=False).tolist())
    return out


# ----------------------------------------------------------------------------- running the oracle
def compile_adversarial_project():
    """Compile the project (all four primitives) once; returns (primitives by name, spec)."""
    from mpgspec.api import compile_project
    from mpgspec.spec.loader import load_project

    with tempfile.TemporaryDirectory(prefix="mpg_adversarial_") as folder:
        path = Path(folder) / "project.yaml"
        path.write_text(project_yaml())
        spec = load_project(path)
        return compile_project(spec), spec


def status_of(e) -> str:
    s = getattr(e, "status", None)
    s = getattr(s, "value", s)
    return str(s) if s else ("safe" if e.verdict == 1 else "unsafe")


def oracle_statuses(prims: dict, backend: str, preset: str, prim: str, X: np.ndarray, T0: np.ndarray) -> list[str]:
    """Statuses of one batch of start points of one primitive; an oracle crash is an 'error' status."""
    from mpgspec.oracle import SafetyOracle
    from mpgspec.settings import OracleSettings

    method, _, error = backend.partition(":")
    settings = OracleSettings.with_accuracy(preset, dt=DT, horizon=HORIZON, method=method, error=error or "local")
    try:
        return [status_of(e) for e in SafetyOracle(prims[prim], settings).evaluate(X, T0)]
    except Exception as err:  # reported per case, never counted as 'safe'
        return [f"error: {type(err).__name__}: {str(err)[:200]}"] * len(X)


_WORKER_PRIMS: dict = {}


def _run_job(job: tuple) -> tuple:
    """One (backend, preset, primitive, rows) job, in a worker process or in this one."""
    backend, preset, prim, idx, X, T0 = job
    if not _WORKER_PRIMS:
        _WORKER_PRIMS.update(compile_adversarial_project()[0])
    t = time.process_time()
    sts = oracle_statuses(_WORKER_PRIMS, backend, preset, prim, X, T0)
    return backend, preset, idx, sts, time.process_time() - t


def default_workers() -> int:
    """ADVERSARIAL_WORKERS, else 1 inside a pytest-xdist worker (the suite already runs one worker
    per core: spawning more only adds their start-up), else up to 2 processes."""
    if "ADVERSARIAL_WORKERS" in os.environ:
        return int(os.environ["ADVERSARIAL_WORKERS"])
    return 1 if os.environ.get("PYTEST_XDIST_WORKER") else min(2, os.cpu_count() or 1)


def run_campaign(n_per_family: int = CASES_PER_FAMILY, backends=BACKENDS, presets=PRESETS,
                 scipy_per_family: int = SCIPY_PER_FAMILY, workers: int | None = None) -> dict:
    """Generate the cases, run every (backend, preset) on them, return cases with their statuses.

    Jobs (one per backend, preset and primitive) run in `workers` processes (spawned; each
    compiles the project once, the JIT cache is shared on disk), longest first.
    """
    workers = default_workers() if workers is None else workers
    t0 = time.perf_counter()
    cases, discarded = generate(n_per_family)
    t1 = time.perf_counter()
    sub = set(scipy_subset(cases, scipy_per_family))
    cost = {"low": 1, "medium": 1.5, "high": 2.5, "very_high": 3.5}
    jobs = []
    for backend in backends:
        for preset in presets:
            for prim in E_SPEC:
                idx = [i for i, c in enumerate(cases) if c.prim == prim and (backend != "scipy" or i in sub)]
                if idx:
                    X, T0 = np.array([cases[i].x0 for i in idx]), np.array([cases[i].t0 for i in idx])
                    weight = len(idx) * cost.get(preset, 1) * (50 if backend == "scipy" else 1)
                    jobs.append((weight, (backend, preset, prim, idx, X, T0)))
    jobs = [j for _, j in sorted(jobs, key=lambda wj: -wj[0])]
    if workers <= 1:
        outs = [_run_job(j) for j in jobs]
    else:
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
            outs = list(pool.map(_run_job, jobs))
    seconds: dict = {}
    for backend, preset, idx, sts, secs in outs:
        seconds[(backend, preset)] = seconds.get((backend, preset), 0.0) + secs
        for i, st in zip(idx, sts):
            cases[i].status[(backend, preset)] = st
    import mpgspec

    return {"cases": cases, "discarded": discarded, "seconds": seconds, "reference_s": t1 - t0,
            "mpgspec": str(Path(mpgspec.__file__).parent),
            "oracle_wall_s": time.perf_counter() - t1, "workers": workers,
            "backends": tuple(backends), "presets": tuple(presets)}


# ----------------------------------------------------------------------------- summaries
@dataclass
class Tally:
    cases: int = 0
    truly_safe: int = 0
    false_safe: int = 0
    inconclusive: int = 0
    errors: int = 0
    agree: int = 0
    safe_found: int = 0  # truly safe cases called safe
    false_unsafe: int = 0  # truly safe cases called unsafe (not a soundness failure; inconclusive is the honest answer)

    def add(self, case: Case, status: str) -> None:
        self.cases += 1
        self.truly_safe += case.truth.safe
        if status == "safe":
            self.false_safe += not case.truth.safe
            self.safe_found += case.truth.safe
        elif status == "inconclusive":
            self.inconclusive += 1
        elif status == "unsafe":
            self.false_unsafe += case.truth.safe
        elif status != "unsafe":
            self.errors += 1
        self.agree += (status == "safe") == case.truth.safe and status in ("safe", "unsafe")

    @property
    def recall(self) -> float:
        return self.safe_found / self.truly_safe if self.truly_safe else float("nan")


def tallies(result: dict) -> dict:
    """(family | 'all', backend, preset) -> Tally."""
    out: dict = {}
    for c in result["cases"]:
        for (b, p), s in c.status.items():
            for fam in (c.family, "all"):
                out.setdefault((fam, b, p), Tally()).add(c, s)
    return out


def false_safes(result: dict, backend: str, preset: str) -> list[Case]:
    return [c for c in result["cases"] if c.status.get((backend, preset)) == "safe" and not c.truth.safe]


def summary_table(result: dict) -> str:
    """family x backend x preset: cases, truly safe, false safe, false unsafe, inconclusive, errors,
    agreement (status equals the exact answer), safe-recall (truly safe cases called safe)."""
    tl = tallies(result)
    lines = [f"{'family':8} {'backend':7} {'preset':9} {'cases':>5} {'tru-safe':>8} {'FALSE-SAFE':>10} "
             f"{'false-unsafe':>12} {'inconcl':>7} {'errors':>6} {'agree':>6} {'safe-recall':>11} {'cpu s':>6}"]
    for fam in FAMILIES + ("all",):
        for b in result["backends"]:
            for p in result["presets"]:
                t = tl.get((fam, b, p))
                if t is None:
                    continue
                secs = f"{result['seconds'].get((b, p), float('nan')):.1f}" if fam == "all" else ""
                lines.append(f"{fam:8} {b:7} {p:9} {t.cases:5d} {t.truly_safe:8d} {t.false_safe:10d} "
                             f"{t.false_unsafe:12d} {t.inconclusive / t.cases:7.1%} {t.errors:6d} "
                             f"{t.agree / t.cases:6.1%} {t.recall:11.1%} {secs:>6}")
    counts = ", ".join(f"{f}: {sum(c.family == f for c in result['cases'])}" for f in FAMILIES)
    lines.append(f"{len(result['cases'])} cases ({counts}); ties discarded: {result['discarded']}; exact reference "
                 f"{result['reference_s']:.1f} s; oracle runs {result['oracle_wall_s']:.1f} s wall on "
                 f"{result['workers']} worker(s); mpgspec from {result.get('mpgspec')}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases-per-family", type=int, default=CASES_PER_FAMILY)
    ap.add_argument("--scipy-per-family", type=int, default=SCIPY_PER_FAMILY)
    ap.add_argument("--backends", default=",".join(BACKENDS))
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--show", type=int, default=3, help="false safes to print per backend and preset")
    a = ap.parse_args(argv)
    res = run_campaign(a.cases_per_family, a.backends.split(","), a.presets.split(","), a.scipy_per_family,
                       a.workers)
    print(summary_table(res))
    bad = 0
    for b in res["backends"]:
        for p in res["presets"]:
            fs = false_safes(res, b, p)
            bad += len(fs)
            for c in fs[: a.show]:
                print(f"FALSE SAFE {b}/{p}: {c.describe()}")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
