"""The region-of-attraction plug-in contract: what a verifier is given and what it answers.

A verifier sizes the explicit safe region of attraction E = {(x-x*)' W (x-x*) < r^2} of one
primitive (Definition 1), which the paper otherwise picks by hand. It is given an RoAProblem (a
fixed primitive) or a PeriodicProblem (a periodic one), built from the compiled primitive by
`from_primitive`, and returns an RoAResult whose `level` says how far the radius can be trusted:
'certified' (a checked certificate), 'empirical' (sampled rollouts, not proven), 'given' (the
spec author's choice) or 'failed'. Verifiers register through the `mpgspec.roa` entry points
(registry.py) and import this module; the core never imports them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import casadi as ca
import numpy as np

LEVELS = ("certified", "empirical", "given", "failed")
"""Levels of evidence of a radius, most trusted first."""


def weakest(*levels: str) -> str:
    """The least trusted of several levels."""
    order = {"failed": 0, "empirical": 1, "given": 2, "certified": 3}
    return min(levels, key=order.__getitem__)


def metric(weights: np.ndarray | None, nx: int) -> np.ndarray:
    """The SPD matrix W of E from a weight vector, a matrix, or None (identity)."""
    if weights is None:
        return np.eye(nx)
    w = np.asarray(weights, float)
    return np.diag(w) if w.ndim == 1 else w


@dataclass
class RoAProblem:
    """Autonomous closed loop xdot = f(x) of a fixed primitive with equilibrium x_star and h(x) >= 0 safe."""

    f: ca.Function
    x_star: np.ndarray
    h: ca.Function | None = None
    weights: np.ndarray | None = None
    name: str = ""

    @property
    def nx(self) -> int:
        return int(np.size(self.x_star))

    @property
    def W(self) -> np.ndarray:
        return metric(self.weights, self.nx)


@dataclass
class PeriodicProblem:
    """Time-varying closed loop xdot = f(x, t) tracking the T-periodic orbit x_star(t)."""

    f: ca.Function
    x_star: ca.Function
    period: float
    h: ca.Function | None = None  # (x, t) -> safety functions
    weights: np.ndarray | None = None
    name: str = ""
    source: object = None  # the compiled primitive, for loops whose state jumps (contact schedules)

    @property
    def nx(self) -> int:
        return int(self.f.size1_in(0))

    @property
    def W(self) -> np.ndarray:
        return metric(self.weights, self.nx)


@dataclass
class RoAResult:
    """Radius r of E in the W metric, how it was obtained, and JSON-serialisable evidence."""

    radius: float
    level: str
    method: str
    evidence: dict = field(default_factory=dict)
    message: str = ""

    def __post_init__(self):
        if self.level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {self.level!r}")
        self.radius = float(self.radius)
        self.evidence = jsonable(self.evidence)

    def to_dict(self) -> dict:
        return {"radius": self.radius, "level": self.level, "method": self.method,
                "evidence": self.evidence, "message": self.message}


@runtime_checkable
class RoAVerifier(Protocol):
    """What an `mpgspec.roa` entry point provides. It may also list the `roa.options` keys it
    reads in an `options` attribute (registry.py)."""

    name: str
    description: str

    def is_installed(self) -> bool:
        """Whether its solvers and libraries are present."""

    def estimate(self, problem: RoAProblem | PeriodicProblem, options: dict) -> RoAResult:
        """The radius of E for the problem, with its level of evidence."""


def jsonable(v):
    """Evidence values as plain lists, floats, ints, bools and strings."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else str(float(v))
    if isinstance(v, complex):
        return [v.real, v.imag]
    if v is None or isinstance(v, str):
        return v
    return str(v)


def from_primitive(prim, weights: np.ndarray | None = None, s: float = 1e6) -> RoAProblem | PeriodicProblem:
    """The RoA problem of a compiled primitive (duck-typed CompiledPrimitive) with x_sw = x*(0).

    s is the time since switch-in, by default long after any motion profile has finished, so the
    loop tracks x* itself and a fixed primitive's loop is autonomous. Transient primitives have
    no RoA problem here.
    """
    cls = getattr(prim.cls, "value", prim.cls)
    nx = prim.f_cl.size1_in(0)
    x, t = ca.SX.sym("x", nx), ca.SX.sym("t")
    xs0 = np.array(prim.setpoint(0.0), float).ravel()
    if cls == "fixed":
        return RoAProblem(ca.Function("f", [x], [prim.f_cl(x, 0.0, s, xs0)]), xs0,
                          ca.Function("h", [x], [prim.h(x, 0.0, s, xs0)]), weights, prim.name)
    if cls == "periodic":
        return PeriodicProblem(ca.Function("f", [x, t], [prim.f_cl(x, t, s, xs0)]), prim.setpoint,
                               float(prim.period), ca.Function("h", [x, t], [prim.h(x, t, s, xs0)]), weights,
                               prim.name, prim if getattr(prim, "hybrid", False) else None)
    raise ValueError(f"no region-of-attraction problem for a {cls} primitive")
