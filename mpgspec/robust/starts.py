"""Start states of a robust edge on the boundary of the source's region of attraction E_A.

Algorithm 1 checks A -> B from x_A*(t_A) only, but a robot leaves A from anywhere in
E_A = {x : ||x - x_A*(t_A)||_W <= r_A}, and the worst start is usually on its boundary. The samples
lie on the weighted sphere ||x - x*||_W = r_A and move only W's weighted directions (its
positive-eigenvalue subspace; directions W leaves free, such as a rigid body's yaw, stay at x*).
On a rigid body each sample is projected onto the contact manifold of A's feet and kept only if it
still lies in E_A. Seeded samples: evidence (empirical, sampled), not a proof.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from ..check.assumptions import _contact_projection
from ..check.roa_samples import metric, sphere_offsets, weighted_distance
from ..compile.primitive import CompiledPrimitive

__all__ = ["INSIDE", "Start", "boundary_starts", "metric", "sphere_offsets", "weighted_distance"]

INSIDE = 1e-9
"""Relative slack of `distance <= r_A` when a projected sample is kept."""


@dataclass(frozen=True)
class Start:
    """A start state of a cell: x, its index among the drawn samples (None: x_A*(t_A) itself) and
    its weighted distance ||x - x_A*(t_A)||_W."""

    x: np.ndarray
    sample: int | None = None
    distance: float = 0.0


def boundary_starts(prim: CompiledPrimitive, t_A: float, n: int, seed: int) -> list[Start]:
    """The kept samples of E's boundary at x*(t_A) (indices 0..n-1 among the drawn ones).

    Sample k depends only on the seed, the primitive (its name, W and r), t_A and k, not on n or
    the target, so a worst case can be drawn again from its index. Empty when E is empty (r = 0)
    or W weighs no direction.
    """
    xs = prim.x_star(t_A)
    W = metric(prim)
    r = float(prim.radius_at(t_A))
    if n <= 0 or r <= 0 or not (np.linalg.eigvalsh(W) > 1e-12).any():
        return []
    rng = np.random.default_rng([int(seed), zlib.crc32(prim.name.encode("utf-8", "surrogatepass"))])
    X = xs[None, :] + sphere_offsets(W, r, n, rng)
    project = _contact_projection(prim, W)
    out = []
    for k, x in enumerate(X):
        if project is not None:
            x = project(x, xs, t_A)[0]
        d = weighted_distance(prim, x, xs)
        if np.all(np.isfinite(x)) and d <= r * (1 + INSIDE):
            out.append(Start(np.asarray(x, float), k, d))
    return out
