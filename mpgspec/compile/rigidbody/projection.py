"""Projection of many states onto a contact manifold at once (Gauss-Newton on the configuration
manifold, then the velocities into the contacts' null space), for RigidBodyCompiledSystem.

Every point takes the steps it would take alone: the kinematics go through CasADi maps of the same
Functions, the linear algebra through numpy's stacked LAPACK and BLAS calls (the same routine per
point as on one point), and a point stops iterating when its heights converge.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np
from numpy.linalg import LinAlgError

from ..numeric import numeric_map

try:  # the gufunc behind np.linalg.lstsq: stacked least squares, dgelsd per point
    from numpy.linalg._umath_linalg import lstsq as _lstsq_gufunc
except ImportError:  # pragma: no cover - numpy < 2
    _lstsq_gufunc = None


def _raise_lstsq(err, flag):
    raise LinAlgError("SVD did not converge in Linear Least Squares")


def lstsq_many(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x[i] = np.linalg.lstsq(A[i], b[i], rcond=None)[0] for stacked A (n, m, k) and b (n, m)."""
    if _lstsq_gufunc is None or not A.shape[0]:
        return np.array([np.linalg.lstsq(a, y, rcond=None)[0] for a, y in zip(A, b)]).reshape(A.shape[0], A.shape[2])
    rcond = np.finfo(float).eps * max(A.shape[1:])
    with np.errstate(call=_raise_lstsq, invalid="call", over="ignore", divide="ignore", under="ignore"):
        x = _lstsq_gufunc(A, b[..., None], rcond, signature="ddd->ddid")[0]
    return x[..., 0]


def inverse_metric(block: np.ndarray) -> np.ndarray:
    """(B + 1e-3 max|B| I)^-1 of each stacked block B (n, k, k): W's block made invertible, so
    directions W leaves free are used only where weighted ones do not help."""
    big = np.abs(block).max(axis=(1, 2))
    big = np.where(big > 1e-12, big, 1e-12)
    return np.linalg.inv(block + (1e-3 * big)[:, None, None] * np.eye(block.shape[1]))


def _mv(M: np.ndarray, y: np.ndarray) -> np.ndarray:
    """M[i] @ y[i] for stacked matrices and vectors."""
    return (M @ y[..., None])[..., 0]


class ContactProjection:
    """(X (n, nx), contacts, W) -> X on the contact manifold of `contacts`, as
    RigidBodyCompiledSystem.project_to_contacts describes, for all rows at once."""

    def __init__(self, sys):
        self.sys = sys

    @cached_property
    def _maps(self) -> dict:
        s = self.sys
        return {"kinematics": numeric_map(s._manifold_kinematics), "normalize": numeric_map(s.dyn.normalize),
                "integrate": numeric_map(s.dyn.integrate, shared=(2,))}

    def kinematics(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Foot heights (n, nc), contact Jacobians (n, 3 nc, nv) and G = dq/dv (n, nq, nv) at rows of Q."""
        m = self.sys.model
        nc, nv, nq = len(m.contact_frames), m.nv, m.nq
        out = self._maps["kinematics"](Q)[0]
        n = out.shape[0]
        J = out[:, nc:nc + 3 * nc * nv].reshape((n, nv, 3 * nc)).transpose(0, 2, 1)
        G = out[:, nc + 3 * nc * nv:].reshape((n, nv, nq)).transpose(0, 2, 1)
        return out[:, :nc], J, G

    def __call__(self, X: np.ndarray, contacts, W: np.ndarray | None = None, tol: float = 1e-12,
                 max_iter: int = 50) -> np.ndarray:
        s, m = self.sys, self.sys.model
        nq, nv = m.nq, m.nv
        X = np.array(X, float).reshape(-1, s.nx)
        W = np.eye(s.nx) if W is None else np.asarray(W, float)
        rows = [m.contact_frames.index(f) for f in contacts]
        Q = self._maps["normalize"](X[:, :nq])[0]
        V = X[:, nq:nq + nv]
        if rows and X.shape[0]:
            J = self._heights_to_zero(Q, rows, W[:nq, :nq], tol, max_iter)
            Minv = inverse_metric(W[None, nq:nq + nv, nq:nq + nv])
            Jt = J.transpose(0, 2, 1)
            V = V - _mv(Minv @ Jt, lstsq_many(J @ Minv @ Jt, _mv(J, V)))
        out = np.concatenate([Q, V, X[:, nq + nv:]], axis=1)
        if s.events:
            for f in m.contact_frames:
                out[:, s.state_names.index(f"contact_{f}")] = float(f in contacts)
        return out

    def _heights_to_zero(self, Q: np.ndarray, rows: list[int], Wq: np.ndarray, tol: float,
                         max_iter: int) -> np.ndarray:
        """Gauss-Newton steps q (+) dv on the rows of Q (in place) until the heights of the feet in
        `rows` are within tol or max_iter steps; the held feet's Jacobians (n, 3 len(rows), nv) at
        the final q."""
        rows3 = [3 * i + k for i in rows for k in range(3)]
        z_rows = [3 * i + 2 for i in rows]
        J_held = np.empty((Q.shape[0], len(rows3), self.sys.model.nv))
        active = np.arange(Q.shape[0])
        for _ in range(max_iter):
            z, J, G = self.kinematics(Q[active])
            r = z[:, rows]
            done = np.abs(r).max(axis=1) <= tol
            J_held[active[done]] = J[done][:, rows3]
            go = ~done
            active, r, J, G = active[go], r[go], J[go], G[go]
            if not active.size:
                return J_held
            A = J[:, z_rows]
            Minv = inverse_metric(G.transpose(0, 2, 1) @ Wq @ G)
            MAt = -Minv @ A.transpose(0, 2, 1)
            dv = _mv(MAt, lstsq_many(A @ Minv @ A.transpose(0, 2, 1), r))
            Q[active] = self._maps["integrate"](Q[active], dv, 1.0)[0]
        J_held[active] = self.kinematics(Q[active])[1][:, rows3]
        return J_held
