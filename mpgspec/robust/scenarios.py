"""The scenarios every switch cell and every target's own flow is run under.

The corners of the box of uncertain parameters and start errors (at most `corners`, seeded), its
centre and `samples` seeded random points, each with the disturbance at 0, +bound and -bound.
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np


@dataclass
class Scenarios:
    """What every cell is run under: per scenario the parameters TH (S, P), the start error ERR
    (S, nx), the disturbance's sign SG (S,) and its kind; the disturbance's bound per axis, its
    number of pieces K and the names of its axes."""

    names: list[str]
    TH: np.ndarray
    ERR: np.ndarray
    SG: np.ndarray
    KIND: list[str]
    bound: np.ndarray
    K: int
    dist_names: list[str]
    state_names: list[str]

    @property
    def S(self) -> int:
        return len(self.TH)

    def waves(self) -> list[np.ndarray]:
        """The scenarios in the order a cell runs them: the box's corners without disturbance first
        (where a cell's worst case lies most often), then the rest; a cell lost in the first wave
        runs no second. A box without corners is one wave."""
        first = np.array([k.startswith("corner") for k in self.KIND]) & (self.SG == 0)
        if not first.any() or first.all():
            return [np.arange(self.S)]
        return [np.flatnonzero(first), np.flatnonzero(~first)]

    @property
    def D1(self) -> np.ndarray:
        """Each scenario's constant disturbance, (S, axes, K)."""
        return (self.SG[:, None, None] * self.bound[None, :, None]) * np.ones((1, len(self.bound), self.K))


def scenarios(unc, sys, rng: np.random.Generator, nominal: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                           list[str]]:
    """(theta (S, P), start error (S, nx), disturbance sign (S,), kind) of every scenario of a cell."""
    names = list(unc.parameters)
    lo = [unc.parameters[n].range[0] for n in names]
    hi = [unc.parameters[n].range[1] for n in names]
    nom = [nominal[n] for n in names]
    states = [sys.state_names.index(s) for s in unc.initial_state]
    eb = [float(unc.initial_state[s]) for s in unc.initial_state]
    lo, hi = np.array(lo + [-b for b in eb], float), np.array(hi + eb, float)
    centre = np.array(nom + [0.0] * len(eb), float)
    dim = len(lo)
    pts, kinds = [centre], ["nominal"]
    if dim:
        if 2 ** dim <= unc.corners:
            corners = np.array(list(itertools.product((0, 1), repeat=dim)), float)
        else:
            corners = rng.integers(0, 2, (unc.corners, dim)).astype(float)
        pts += list(lo + corners * (hi - lo))
        kinds += ["corner"] * len(corners)
        pts += list(lo + rng.random((unc.samples, dim)) * (hi - lo))
        kinds += ["sample"] * unc.samples
    pts = np.array(pts, float).reshape(len(pts), dim)  # dim 0: the nominal scenario alone
    signs = [0.0, 1.0, -1.0] if unc.disturbance is not None else [0.0]
    th, err, sg, kd = [], [], [], []
    for sgn in signs:
        for p, k in zip(pts, kinds):
            th.append(p[: len(names)])
            e = np.zeros(sys.nx)
            e[states] = p[len(names):]
            err.append(e)
            sg.append(sgn)
            kd.append(k if sgn == 0 else f"{k}, constant disturbance {'+' if sgn > 0 else '-'}bound")
    return np.array(th).reshape(len(th), len(names)), np.array(err), np.array(sg), kd


def searched(unc) -> bool:
    """Whether the adversarial search runs (rounds and a disturbance): only then is a gradient built."""
    return bool(unc.search) and unc.disturbance is not None
