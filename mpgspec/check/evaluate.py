"""A primitive's closed loop and safety functions on numpy arrays, at one point or many, for the
Definition 1 checks.

The loop is evaluated after any motion profile has ended (s large, x_sw = x). Many points go
through CasADi maps of the same Functions (compile/numeric.py), so every point gets the bits it
would get alone.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..compile.numeric import numeric, numeric_map
from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..spec.models import PrimitiveClass

S_SETTLED = 1e3  # time since switch-in at which every motion profile has finished


def clock(p: CompiledPrimitive, n: int) -> np.ndarray:
    """n clock times over p's domain (t = 0 alone for fixed primitives), and the middle of each phase interval
    where E(t) is narrower (CompiledPrimitive.narrow)."""
    a, b = p.t_range
    if p.cls is PrimitiveClass.FIXED:
        return np.zeros(1)
    ts = np.linspace(a, b, n, endpoint=False)
    return np.sort(np.r_[ts, [0.5 * (lo + hi) for lo, hi in p.narrow]]) if p.narrow else ts


def _cached(p: CompiledPrimitive, key: tuple, make):
    if key not in p.cache:
        p.cache[key] = make()
    return p.cache[key]


def numeric_fn(p: CompiledPrimitive, name: str):
    """p's Function `name` on numpy arrays, kept with p's compiled chunks (compile/numeric.py)."""
    return _cached(p, ("numeric", name), lambda: numeric(getattr(p, name)))


def f_cl(p: CompiledPrimitive, x: np.ndarray, t: float) -> np.ndarray:
    """The closed loop's xdot at (x, t)."""
    return numeric_fn(p, "f_cl")(x, t, S_SETTLED, x)[0]


def f_cl_many(p: CompiledPrimitive, X: np.ndarray, t: float) -> np.ndarray:
    """The closed loop's xdot at every row of X (n, nx), at clock t: (n, nx)."""
    fn = _cached(p, ("numeric_map", "f_cl"), lambda: numeric_map(p.f_cl, shared=(1, 2)))
    return fn(X, t, S_SETTLED, X)[0]


def h_active(p: CompiledPrimitive, x: np.ndarray, t: float) -> np.ndarray:
    """The safety functions active at (x, t): those below INACTIVE / 2 (a parked one sits at INACTIVE;
    a value far below zero is active, however large)."""
    v = numeric_fn(p, "h")(x, t, S_SETTLED, x)[0]
    return v[v < INACTIVE / 2]


def h_many(p: CompiledPrimitive, X: np.ndarray, t) -> np.ndarray:
    """h at every row of X (n, nx), at clock t (one time, or one per row): (n, nh), inactive
    functions at INACTIVE."""
    X = np.atleast_2d(X)
    T = np.broadcast_to(np.asarray(t, float).reshape(-1, 1), (X.shape[0], 1))
    fn = _cached(p, ("numeric_map", "h"), lambda: numeric_map(_merged(p.h), shared=(2,)))
    return fn(X, T, S_SETTLED, X)[0]


def _merged(fn: ca.Function) -> ca.Function:
    """An SX Function with its common subexpressions merged (a third fewer instructions for a
    robot's h; each value is still the same operation on the same operands, so the same bits)."""
    if not fn.is_a("SXFunction"):
        return fn
    a = fn.sx_in()
    return ca.Function(fn.name(), a, fn.call(a, True, False), fn.name_in(), fn.name_out(), {"cse": True})


def least(V: np.ndarray) -> np.ndarray:
    """Each row's least active h (n,) (active as in h_active; NaN is not), inf where none is active."""
    return np.where(V < INACTIVE / 2, V, np.inf).min(axis=1, initial=np.inf)


def active_rows(V: np.ndarray) -> np.ndarray:
    """The active h of every row of V (n, m), when every row has the same active set (as the
    checks that compare points need); raises ValueError otherwise."""
    act = V < INACTIVE / 2
    if V.shape[0] and not (act == act[0]).all():
        raise ValueError("the active safety functions differ between the points compared")
    return V[:, act[0]] if V.shape[0] else V[:, :0]


def fold_min(worst: float, values: np.ndarray) -> float:
    """min(worst, v) over values in turn as Python folds it (NaN values leave worst as it is)."""
    values = values[~np.isnan(values)]
    return min(worst, float(values.min())) if values.size else worst


def offsets(xs: np.ndarray, L: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """xs + L @ z for every row z of Z (n, k), each product the matrix-vector one of a single point."""
    return xs + (L @ Z[:, :, None])[:, :, 0]
