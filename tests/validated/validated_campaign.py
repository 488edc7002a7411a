"""Generated cases with exact answers for the `validated` oracle backend, and the runner that judges them.

The validated backend (verifiers/validated.py) must never answer `safe` where the exact answer of
Definition 4 is unsafe, nor `unsafe` where it is safe; `inconclusive` is always allowed. The cases
come from the generators of the rk4 campaigns, imported, not copied:

  window, slab, graze, fast   tests/oracle/adversarial.py: a safety function active on a clock
                              window narrower than a step, a keep-out band crossed in 0.1..5 ms, a
                              grazing peak between samples, a fast undershoot (exact reference).
  clock, pulse, state, sat    tests/oracle/pieces_campaign.py: laws switching on the clock or the
                              state inside a step, a pulse narrower than a step, input saturation
                              with the margin c - x(T) after its kink (closed form).

and two families defined here:

  graze_tie   graze cases whose ceiling (floor) is moved to within 1e-12..1e-9 of the peak
              (trough), either side: the exact answer holds, but it is a tie for any numerical
              method, so `inconclusive` is expected; a decided verdict must still be the exact one.
  satosc      p'' = clip(-om^2 p - 2 ze om v, -U, U) started saturated: the kink at s1 in
              [2 ms, 0.3 s] is crossed inside a step, then a ceiling (floor) within 1e-7..3e-2 of
              the first global peak (trough) after it. Exact: the saturated arc is a parabola, the
              kink the first root of a quadratic, the rest the linear loop of adversarial.Loop;
              cases whose law saturates again, or which come near E on the parabola, are redrawn.

A case that raises is an `error` status (counted, never `safe`).
"""
from __future__ import annotations

import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parents[1] / "oracle"))
import adversarial as adv  # noqa: E402
import pieces_campaign as pc  # noqa: E402

ADV_FAMILIES = adv.FAMILIES  # window, slab, graze, fast
PIECE_FAMILIES = pc.FAMILIES  # state, clock, sat, pulse
FAMILIES = ADV_FAMILIES + ("graze_tie", "satosc") + PIECE_FAMILIES
GRAZING = 1e-9
"""A truth whose least safety margin is within this of 0 is grazing: inconclusive expected."""
PIECES_HORIZON = 5.0  # the horizon pieces_campaign runs its cases at
SAT_STATES = ("p", "v", "om", "ze", "c", "U", "sg")
SAT_E = (0.03, 1.0, 0.01)  # E of SatLevel: radius, weights of p and v (the parameters weigh adv.PARAM_WEIGHT)
SAT_NAME = "SatLevel"


@dataclass
class Item:
    """One generated case: where it runs (project, primitive, x0, t0, horizon) and its exact answer."""

    family: str
    kind: str
    project: str  # "adversarial" | "pieces" | "satosc"
    prim: str
    x0: np.ndarray
    t0: float
    horizon: float
    safe: bool
    margin: float  # the exact least value of the safety function before E (signed)
    detail: str
    status: str = ""
    message: str = ""
    seconds: float = 0.0

    @property
    def grazing(self) -> bool:
        return abs(self.margin) <= GRAZING

    def describe(self) -> str:
        return (f"{self.family}/{self.kind} project {self.project!r} primitive {self.prim!r} "
                f"x0={np.array2string(self.x0, precision=17, separator=', ', max_line_width=10**6)} "
                f"t0={self.t0!r} horizon={self.horizon!r}: truth {'safe' if self.safe else 'unsafe'} "
                f"(least margin {self.margin:.3g}; {self.detail}); validated said {self.status!r}")


# ----------------------------------------------------------------------------- satosc: exact answer
def sat_project_yaml() -> str:
    """The satosc project: the adversarial double integrator with its input clipped at +-U (a state)."""
    zeros = "[" + ", ".join(["0"] * len(SAT_STATES)) + "]"
    r, wp, wv = SAT_E
    weights = [wp, wv] + [adv.PARAM_WEIGHT] * (len(SAT_STATES) - 2)
    g = ", ".join(["[0]", "[1]"] + ["[0]"] * (len(SAT_STATES) - 2))
    return "\n".join([
        "project: satosc",
        "system:",
        "  name: clipped_osc_with_parameters",
        "  kind: analytic",
        f"  states: [{', '.join(SAT_STATES)}]",
        "  inputs: [u]",
        "  dynamics:",
        f"    f: [v, {', '.join(['0'] * (len(SAT_STATES) - 1))}]",
        f"    g: [{g}]",
        "primitives:",
        f"  - name: {SAT_NAME}",
        "    class: fixed",
        f"    setpoint: {{expr: {zeros}}}",
        '    controller: {type: expression, u: ["clip(-om^2*p - 2*ze*om*v, -U, U)"]}',
        "    safe_set:",
        '      - {name: limit, h: "sg*(p - c)"}',
        f"    roa: {{radius: {r!r}, weights: [{', '.join(repr(x) for x in weights)}]}}",
        "oracle:", f"  horizon: {adv.HORIZON!r}", f"  dt: {adv.DT!r}", "  accuracy: low",
    ]) + "\n"


@dataclass
class SatPath:
    """The exact path of a satosc case: the parabola on [0, s1], then adversarial.Loop from s1."""

    sigma: float  # the sign of the saturated input
    U: float
    s1: float
    p0: float
    v0: float
    loop: adv.Loop  # from (p(s1), v(s1)), clock s - s1

    def parabola(self, s):
        s = np.asarray(s, float)
        a = self.sigma * self.U
        return self.p0 + self.v0 * s + 0.5 * a * s * s, self.v0 + a * s

    def pv(self, s):
        s = np.asarray(s, float)
        pa, va = self.parabola(np.minimum(s, self.s1))
        pb, vb = self.loop.pv(np.maximum(s - self.s1, 0.0))
        return np.where(s <= self.s1, pa, pb), np.where(s <= self.s1, va, vb)

    def p_range_parabola(self) -> tuple[float, float]:
        ts = [0.0, self.s1]
        vertex = -self.v0 / (self.sigma * self.U)
        if 0.0 < vertex < self.s1:
            ts.append(vertex)
        P = self.parabola(np.array(ts))[0]
        return float(P.min()), float(P.max())


def sat_path(x0, horizon: float = adv.HORIZON) -> SatPath | None:
    """The exact path from x0, or None when it does not start saturated, leaves saturation after
    0.3 s or saturates again before the horizon."""
    p0, v0, om, ze, _c, U, _sg = (float(v) for v in x0)
    ulin = -om * om * p0 - 2 * ze * om * v0
    if abs(ulin) <= U:
        return None
    sig = math.copysign(1.0, ulin)
    # u_lin(s) - sig U = a s^2 + b s + c0 along the parabola p = p0 + v0 s + sig U s^2 / 2
    a, b, c0 = -0.5 * om * om * sig * U, -om * om * v0 - 2 * ze * om * sig * U, ulin - sig * U
    disc = b * b - 4 * a * c0
    if disc < 0:
        return None
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
    roots = [x for x in ((q / a) if a else math.inf, (c0 / q) if q else math.inf) if x > 0]
    if not roots or min(roots) > 0.3:
        return None
    s1 = min(roots)
    p1, v1 = p0 + v0 * s1 + 0.5 * sig * U * s1 * s1, v0 + sig * U * s1
    path = SatPath(sig, U, s1, p0, v0, adv.Loop(om, ze, p1, v1, horizon - s1))
    # u' = 2 ze om^3 p + (4 ze^2 - 1) om^2 v on the linear arc: it must point inward at s1, and
    # |u| must stay below U at every extremum of u and at the end
    k_p, k_v = 2 * ze * om ** 3, (4 * ze * ze - 1) * om * om
    if sig * (k_p * p1 + k_v * v1) >= 0:
        return None
    L = path.loop
    z = L.zeros(k_p, k_v)
    z = np.concatenate([z[z > 1e-12], [L.T]])
    P, V = L.pv(z)
    if np.any(np.abs(-om * om * P - 2 * ze * om * V) >= U * (1 - 1e-9)):
        return None
    return path


def sat_reference(x0, horizon: float = adv.HORIZON) -> adv.Truth | None:
    """Exact answer of Definition 4 for a satosc case (None: not a valid satosc start)."""
    path = sat_path(x0, horizon)
    if path is None:
        return None
    p0, v0, om, ze, c, U, sg = (float(v) for v in x0)
    r, wp, wv = SAT_E
    K = adv.PARAM_WEIGHT * (om * om + ze * ze + c * c + U * U + sg * sg)
    lo, hi = path.p_range_parabola()
    if min(abs(lo), abs(hi)) <= r / math.sqrt(wp) + 1e-3 or lo * hi <= 0:
        return None  # near E (|p| < r) on the parabola: not this family
    tau_b, tie = path.loop.entry(r, wp, wv, K)
    tau = None if tau_b is None else path.s1 + tau_b
    end_b = tau_b if tau_b is not None else path.loop.T
    h_a = min(sg * (lo - c), sg * (hi - c))
    h_b = adv.h_min(path.loop, "level", sg, c, 0.0, 0.0, end_b)
    hm = min(h_a, h_b)
    tie = tie or abs(hm) < adv.TIE
    safe = tau is not None and hm > 0.0
    why = "entered E" if safe else ("left C (limit)" if hm <= 0.0 else "E not reached")
    return adv.Truth(safe, tau, hm, tie, why)


def gen_satosc(rng):
    """(kind, x0, t0) of one satosc case, or None to draw again."""
    om = adv.log_uniform(rng, 8.0, 40.0)
    ze = float(rng.uniform(max(0.1, 4.0 / om), 0.7))
    p0 = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.5))
    v0 = float(rng.normal(0.0, 0.3 * om * abs(p0)))
    U = abs(-om * om * p0 - 2 * ze * om * v0) * float(rng.uniform(0.15, 0.9))
    x0 = [p0, v0, om, ze, 0.0, U, 1.0]
    path = sat_path(x0)
    if path is None or path.s1 < 2e-3:
        return None
    r, wp, wv = SAT_E
    tau_b, _ = path.loop.entry(r, wp, wv, adv.PARAM_WEIGHT * (om * om + ze * ze + U * U))
    if tau_b is None or tau_b < 0.02:
        return None
    L = path.loop
    z = L.extrema(0.0, tau_b)
    P = L.p(z)
    lo, hi = path.p_range_parabola()
    picks = [(s, i) for s, i in ((1.0, int(np.argmax(P))), (-1.0, int(np.argmin(P))))
             if i >= 2 and (P[i] > hi if s > 0 else P[i] < lo)]  # an interior extreme beyond the parabola's
    if not picks:
        return None
    sign, i = picks[int(rng.integers(len(picks)))]
    delta = adv.log_uniform(rng, 1e-7, 1e-3) if rng.random() < 0.8 else adv.log_uniform(rng, 1e-3, 3e-2)
    exceeded = rng.random() < 0.5
    c = float(P[i]) - sign * delta if exceeded else float(P[i]) + sign * delta
    return ("exceeded" if exceeded else "cleared"), [p0, v0, om, ze, c, U, -sign], float(rng.uniform(0.0, 1.0))


# ----------------------------------------------------------------------------- the families
def _adv_item(c: adv.Case, family: str | None = None) -> Item:
    t = c.truth
    return Item(family or c.family, c.kind, "adversarial", c.prim, np.asarray(c.x0, float), float(c.t0), adv.HORIZON,
                bool(t.safe), float(t.h_min), f"{t.why}, tau_E={t.tau_E}")


def _tie_item(c: adv.Case, rng) -> Item | None:
    """A graze case with its limit moved to a margin of +-(1e-12..1e-9) at the same peak."""
    x0 = np.array(c.x0, float)
    target = float(rng.choice([-1.0, 1.0])) * adv.log_uniform(rng, 1e-12, 1e-9)
    sg = x0[6]
    x0[4] += sg * (c.truth.h_min - target)  # h = sg (p - c): the least value moves by the same amount
    t = adv.reference(c.prim, x0, c.t0)
    if t.tau_E is None or not math.isfinite(t.h_min) or abs(t.h_min - target) > 1e-13:
        return None
    return Item("graze_tie", ("exceeded" if target < 0 else "cleared"), "adversarial", c.prim, x0, float(c.t0),
                adv.HORIZON, bool(t.safe), float(t.h_min), f"{t.why}, tau_E={t.tau_E}")


def _piece_item(c: pc.Case) -> Item:
    unsafe = c.unsafe
    return Item(c.family, "crosses" if unsafe else "clear", "pieces", c.family, np.asarray(c.x0, float), 0.0,
                PIECES_HORIZON, not unsafe, float(c.c - c.x_T), f"x(T)={c.x_T!r}, c={c.c!r}")


def _sat_items(n: int, rng) -> list[Item]:
    out, tries = [], 0
    while len(out) < n:
        tries += 1
        assert tries < 200 * n, "satosc: the generator keeps failing"
        g = gen_satosc(rng)
        if g is None:
            continue
        kind, x0, t0 = g
        x0 = np.asarray(x0, float)
        t = sat_reference(x0)
        if t is None or t.tie:
            continue
        out.append(Item("satosc", kind, "satosc", SAT_NAME, x0, t0, adv.HORIZON, bool(t.safe), float(t.h_min),
                        f"{t.why}, tau_E={t.tau_E}"))
    return out


def generate(counts: dict, seed: int) -> list[Item]:
    """counts[family] cases of each family (0 or missing: none), with their exact answers."""
    rng = np.random.default_rng(seed)
    out: list[Item] = []
    n_adv = max([counts.get(f, 0) for f in ADV_FAMILIES] + [counts.get("graze_tie", 0)])
    if n_adv:
        cases, _ = adv.generate(n_adv, seed=int(rng.integers(2**31)))
        for fam in ADV_FAMILIES:
            out += [_adv_item(c) for c in cases if c.family == fam][: counts.get(fam, 0)]
        ties = []
        for c in (c for c in cases if c.family == "graze"):
            if len(ties) >= counts.get("graze_tie", 0):
                break
            it = _tie_item(c, rng)
            if it is not None:
                ties.append(it)
        out += ties
    if counts.get("satosc", 0):
        out += _sat_items(counts["satosc"], rng)
    for fam in PIECE_FAMILIES:
        if counts.get(fam, 0):
            out += [_piece_item(c) for c in pc.draw(fam, counts[fam], rng)]
    return out


# ----------------------------------------------------------------------------- running the backend
_PRIMS: dict = {}


def primitives(project: str) -> dict:
    """The compiled primitives of one project, compiled once per process."""
    if project not in _PRIMS:
        if project == "adversarial":
            _PRIMS[project] = adv.compile_adversarial_project()[0]
        else:
            from mpgspec.api import compile_project
            from mpgspec.spec.loader import load_project

            text = pc.project_yaml() if project == "pieces" else sat_project_yaml()
            with tempfile.TemporaryDirectory(prefix=f"mpg_validated_{project}_") as folder:
                path = Path(folder) / "project.yaml"
                path.write_text(text)
                _PRIMS[project] = compile_project(load_project(path))
    return _PRIMS[project]


_RUNNERS: dict = {}


def runner(project: str, prim: str):
    """The ValidatedRunner of one primitive (default Options), built once per process."""
    if (project, prim) not in _RUNNERS:
        from mpgspec.settings import OracleSettings
        from verifiers.validated import ValidatedRunner

        s = OracleSettings.with_accuracy("low", dt=adv.DT, horizon=adv.HORIZON)
        _RUNNERS[(project, prim)] = ValidatedRunner(primitives(project)[prim], s)
    return _RUNNERS[(project, prim)]


def judge(items: list[Item]) -> list[Item]:
    """Run the validated backend on every item (status and wall seconds filled in)."""
    for it in items:
        r = runner(it.project, it.prim)
        t = time.perf_counter()
        try:
            ev = r.evaluate(it.x0[None, :], np.array([it.t0]), it.horizon)[0]
            it.status, it.message = str(getattr(ev.status, "value", ev.status)), ev.message or ""
            if it.status in ("safe", "unsafe") and ev.method != "certified":
                it.status = f"error: decided with method {ev.method!r}"
        except Exception as err:  # noqa: BLE001 - reported per case, never counted as safe
            it.status = f"error: {type(err).__name__}: {str(err)[:200]}"
        it.seconds = time.perf_counter() - t
    return items


# ----------------------------------------------------------------------------- tallies
@dataclass
class Tally:
    cases: int = 0
    safe: int = 0
    unsafe: int = 0
    inconclusive: int = 0
    errors: int = 0
    false_safe: int = 0
    false_unsafe: int = 0
    grazing: int = 0
    truly_safe: int = 0
    seconds: float = 0.0

    def add(self, it: Item) -> None:
        self.cases += 1
        self.truly_safe += it.safe
        self.grazing += it.grazing
        self.seconds += it.seconds
        if it.status == "safe":
            self.safe += 1
            self.false_safe += not it.safe
        elif it.status == "unsafe":
            self.unsafe += 1
            self.false_unsafe += it.safe
        elif it.status == "inconclusive":
            self.inconclusive += 1
        else:
            self.errors += 1


def tallies(items: list[Item]) -> dict[str, Tally]:
    """family (and 'all') -> Tally, in FAMILIES order."""
    out = {f: Tally() for f in FAMILIES if any(it.family == f for it in items)}
    out["all"] = Tally()
    for it in items:
        out[it.family].add(it)
        out["all"].add(it)
    return out


def table(items: list[Item]) -> str:
    """Per family: cases, truly safe, grazing truths, certified safe / unsafe, inconclusive (share),
    false safe, false unsafe, errors, seconds (sum of per-case wall times)."""
    head = (f"| {'family':9} | {'cases':>5} | {'truly safe':>10} | {'grazing':>7} | {'cert. safe':>10} | "
            f"{'cert. unsafe':>12} | {'inconclusive':>14} | {'false safe':>10} | {'false unsafe':>12} | "
            f"{'errors':>6} | {'seconds':>7} |")
    rule = "|" + "|".join("-" * (len(c)) for c in head.split("|")[1:-1]) + "|"
    lines = [head, rule]
    for fam, t in tallies(items).items():
        inc = f"{t.inconclusive} ({t.inconclusive / t.cases:.0%})"
        name = f"**{fam}**" if fam == "all" else fam
        lines.append(f"| {name:9} | {t.cases:5d} | {t.truly_safe:10d} | {t.grazing:7d} | {t.safe:10d} | "
                     f"{t.unsafe:12d} | {inc:>14} | {t.false_safe:10d} | {t.false_unsafe:12d} | {t.errors:6d} | "
                     f"{t.seconds:7.1f} |")
    return "\n".join(lines)


def false_verdicts(items: list[Item]) -> list[Item]:
    return [it for it in items if (it.status == "safe" and not it.safe) or (it.status == "unsafe" and it.safe)]
