"""Generated non-smooth closed loops with closed-form truths: the oracle on laws that switch, saturate
and pulse between samples (oracle/pieces.py).

One project serves every case: x' = u on the first state, and seven parameter states of zero
dynamics (a, v1, v2, c, P, w, k) that set each case's law and safety function through x0. E is the
ball of radius R around x = 2 (the parameter states weigh 1e-30: P reaches 5e9). The safety function c - x is
required on the clock window [0, T); x rises on every path, so its largest value on the window is
x(T) and the exact answer is: unsafe iff x(T) > c (E lies beyond x(T), and every path reaches it).
c = x(T) -+ delta with delta log-uniform in [1e-7, 1e-2].

Families (x(T) in closed form; every kink at a random place inside a step):
  state   u = if_else(x < a, v1, v2): rate v1 until x = a at t* in [0.05, 0.55], then v2;
          x(T) = a + v2 (T - t*).
  clock   u = if_else(t < a, v1, v2) with a = t*: the same path, switched by the clock.
  sat     u = clip(-k (x - 2), -1, 1), k in [2, 5]: the input saturated at 1 until x = 2 - 1/k at
          t_k in [0.35, 0.55], then x = 2 - e^(-k (t - t_k)) / k.
  pulse   u = v1 + P (if_else(t > a, 1, 0) - if_else(t > a + w, 1, 0)): a kick of width w (log-
          uniform in [1e-10, 1e-3], so some are below MIN_PIECE) and area P w in [0.01, 0.5];
          x(T) = v1 T + P w.

Every case runs at every preset with both error estimates ('local', 'doubling'), batched: one
oracle call per family, preset and estimate; the first SCIPY_PER_FAMILY cases of each family also
through the scipy reference backend. With --large every loop is stepped as a robot's large loop is
(oracle/pieces.py: through MX graphs, clock guards met at step boundaries, Illinois location).
"""
from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mpgspec.api import compile_project
from mpgspec.oracle import SafetyOracle
from mpgspec.settings import OracleSettings
from mpgspec.spec.loader import load_project

T = 0.6
R = 0.05
DT = 0.01
PRESETS = ("low", "medium", "high", "very_high")
ERRORS = ("local", "doubling", "scipy")  # rk4 with either error estimate; the scipy reference backend
SCIPY_PER_FAMILY = 10  # the scipy backend runs one rollout at a time in Python: the first cases of each family
FAMILIES = ("state", "clock", "sat", "pulse")
LAWS = {
    "state": "if_else(x < a, v1, v2)",
    "clock": "if_else(t < a, v1, v2)",
    "sat": "clip(-k*(x - 2), -1, 1)",
    "pulse": "v1 + P*(if_else(t > a, 1, 0) - if_else(t > a + w, 1, 0))",
}
STATES = ("x", "a", "v1", "v2", "c", "P", "w", "k")


def project_yaml() -> str:
    n = len(STATES)
    f = ", ".join(["0"] * n)
    g = ", ".join(["[1]"] + ["[0]"] * (n - 1))
    weights = ", ".join(["1"] + ["1e-30"] * (n - 1))
    setpoint = ", ".join(["2"] + ["0"] * (n - 1))
    prims = "".join(textwrap.dedent(f"""\
        - name: {fam}
          class: fixed
          setpoint: {{expr: [{setpoint}]}}
          controller: {{type: expression, u: ["{law}"]}}
          safe_set:
            - {{name: cap, h: "c - x", when: [0, {T}]}}
          roa: {{radius: {R}, weights: [{weights}]}}
        """) for fam, law in LAWS.items())
    return textwrap.dedent(f"""\
        project: pieces
        system:
          name: line_with_parameters
          kind: analytic
          states: [{", ".join(STATES)}]
          inputs: [u]
          dynamics: {{f: [{f}], g: [{g}]}}
        primitives:
        """) + textwrap.indent(prims, "  ")


@dataclass
class Case:
    family: str
    x0: np.ndarray
    x_T: float
    c: float
    status: dict = field(default_factory=dict)  # (error, preset) -> the oracle's status

    @property
    def unsafe(self) -> bool:
        return self.x_T > self.c


def draw(family: str, n: int, rng: np.random.Generator) -> list[Case]:
    """n cases of a family, half of them truly unsafe."""
    cases = []
    for i in range(n):
        a = v1 = v2 = P = w = k = 0.0
        x0 = 0.0
        if family in ("state", "clock"):
            ts, v1, v2 = rng.uniform(0.05, 0.55), rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0)
            a = v1 * ts if family == "state" else ts
            x_T = v1 * ts + v2 * (T - ts)
        elif family == "sat":
            k, tk = rng.uniform(2.0, 5.0), rng.uniform(0.35, 0.55)
            x0 = 2 - 1 / k - tk
            x_T = 2 - math.exp(-k * (T - tk)) / k
        else:
            a, v1 = rng.uniform(0.05, 0.5), rng.uniform(0.5, 2.0)
            w = 10 ** rng.uniform(-10, -3)
            P = rng.uniform(0.01, 0.5) / w
            x_T = v1 * T + P * w
        delta = 10 ** rng.uniform(-7, -2)
        c = x_T - delta if i % 2 == 0 else x_T + delta
        cases.append(Case(family, np.array([x0, a, v1, v2, c, P, w, k]), x_T, c))
    return cases


def run(tmp: Path, per_family: int, seed: int = 20261202, jit: bool = True, scipy: int = SCIPY_PER_FAMILY) -> list[Case]:
    """Draw per_family cases of every family and judge each at every preset and error estimate (the
    first `scipy` of each family also through the scipy backend)."""
    (tmp / "project.yaml").write_text(project_yaml())
    prims = compile_project(load_project(tmp / "project.yaml"))
    rng = np.random.default_rng(seed)
    cases = []
    for fam in FAMILIES:
        batch = draw(fam, per_family, rng)
        for err in ERRORS:
            some = batch[:scipy] if err == "scipy" else batch
            X = np.array([c.x0 for c in some])
            kw = {"method": "scipy"} if err == "scipy" else {"error": err}
            for preset in PRESETS:
                s = OracleSettings.with_accuracy(preset, horizon=5.0, dt=DT, jit=jit, **kw)
                for c, e in zip(some, SafetyOracle(prims[fam], s).evaluate(X, np.zeros(len(some)))):
                    c.status[(err, preset)] = e.status
        cases += batch
    return cases


def table(cases: list[Case]) -> str:
    """Per family, error estimate and preset: cases, false safe, false unsafe, inconclusive share."""
    lines = [f"{'family':7} {'error':9} {'preset':10} {'cases':>5} {'false safe':>10} {'false unsafe':>12} "
             f"{'inconclusive':>12}"]
    for fam in FAMILIES:
        cs = [c for c in cases if c.family == fam]
        for err in ERRORS:
            for p in PRESETS:
                st = [(c.unsafe, c.status[(err, p)]) for c in cs if (err, p) in c.status]
                fs = sum(u and s == "safe" for u, s in st)
                fu = sum((not u) and s == "unsafe" for u, s in st)
                inc = sum(s == "inconclusive" for _, s in st) / max(len(st), 1)
                lines.append(f"{fam:7} {err:9} {p:10} {len(st):5d} {fs:10d} {fu:12d} {inc:12.0%}")
    return "\n".join(lines)


if __name__ == "__main__":
    import argparse
    import tempfile

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases-per-family", type=int, default=600)
    ap.add_argument("--large", action="store_true", help="step every loop as a large one (a robot's: called "
                    "from MX graphs, clock guards split off and met at step boundaries)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        if args.large:
            from mpgspec.oracle import integrator, looplib

            looplib.INLINE_NODES = integrator.INLINE_NODES = 0
        print(table(run(Path(d), args.cases_per_family)))
