"""Samples of a region of attraction E = {x : ||x - x*||_W <= r}: its metric, distances measured as E's
margin measures them, and seeded points of its boundary (the robust stage's starts in E_A, robust/starts.py,
and roa_invariant's, roa_flows.py)."""
from __future__ import annotations

import numpy as np

from ..compile.primitive import CompiledPrimitive


def metric(prim: CompiledPrimitive) -> np.ndarray:
    """W of the primitive's E."""
    return np.array(prim.W, float)


def weighted_distance(prim: CompiledPrimitive, x: np.ndarray, xs: np.ndarray) -> float:
    """||x - xs||_W with wrapped states measured the short way round, as E's margin measures them."""
    return float(weighted_distances(prim, np.asarray(x, float)[:, None], xs)[0])


def weighted_distances(prim: CompiledPrimitive, X: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """weighted_distance of every column of X (inf where it is not finite)."""
    D = np.asarray(X, float) - np.asarray(xs, float).reshape(-1, 1)
    p = np.asarray(prim.system.wrap, float).reshape(-1, 1)
    with np.errstate(invalid="ignore", over="ignore"):  # a blown-up state is at distance inf, no warning
        D = np.where(p > 0, D - p * np.floor((D + p / 2) / np.where(p > 0, p, 1.0)), D)
        v = np.einsum("ij,ik,kj->j", D, metric(prim), D)
    return np.sqrt(np.where(np.isfinite(v), np.maximum(v, 0.0), np.inf))


def sphere_offsets(W: np.ndarray, radius: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """n offsets dx (n, nx) with dx' W dx = radius^2, uniform over the sphere in W's weighted
    subspace (directions of zero weight are not moved)."""
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])  # unit vectors of the weighted norm -> state offsets
    d = rng.normal(size=(n, L.shape[1]))
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    return radius * d @ L.T
