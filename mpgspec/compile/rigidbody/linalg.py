"""Symbolic SPD solves without pivoting, sized for CasADi SX graphs.

The mass matrix of a kinematic tree factorises as M = L^T D L with no fill-in when L follows
the dof-parent array (Featherstone, RBDA 6.5), which is far cheaper than a dense symbolic
factorisation. The small dense operational-space matrix J M^-1 J^T uses a plain LDL^T.
"""
from __future__ import annotations

from collections.abc import Sequence

import casadi as ca

from .model import RigidBodyModel


def dof_parents(model: RigidBodyModel) -> list[int]:
    """Parent dof of each velocity coordinate (-1 for the first dof of a root joint)."""
    parents = [-1] * model.nv
    for joint in model.joints:
        first = joint.idx_v
        if joint.parent >= 0:
            pj = model.joints[joint.parent]
            parents[first] = pj.idx_v + pj.nv - 1
        for k in range(1, joint.nv):
            parents[first + k] = first + k - 1
    return parents


def tree_ldl(M: ca.SX, parents: Sequence[int]) -> tuple[dict[tuple[int, int], ca.SX], list]:
    """Factor M = L^T D L; returns strictly-lower entries L[k, i] (i ancestor of k) and D."""
    n = M.shape[0]
    H = {(k, i): M[k, i] for k in range(n) for i in _ancestors(parents, k, self_too=True)}
    for k in range(n - 1, -1, -1):
        for i in _ancestors(parents, k):
            a = H[k, i] / H[k, k]
            for j in _ancestors(parents, i, self_too=True):
                H[i, j] = H[i, j] - a * H[k, j]
            H[k, i] = a
    D = [H[k, k] for k in range(n)]
    L = {key: val for key, val in H.items() if key[0] != key[1]}
    return L, D


def _ancestors(parents: Sequence[int], k: int, self_too: bool = False) -> list[int]:
    out = [k] if self_too else []
    i = parents[k]
    while i >= 0:
        out.append(i)
        i = parents[i]
    return out


def tree_solve_lt(L: dict, parents: Sequence[int], b: ca.SX) -> ca.SX:
    """Solve L^T y = b (b may have several columns)."""
    n = b.shape[0]
    rows = [b[k, :] for k in range(n)]
    for k in range(n - 1, -1, -1):
        for j in _ancestors(parents, k):
            rows[j] = rows[j] - L[k, j] * rows[k]
    return ca.vertcat(*rows)


def tree_solve_l(L: dict, parents: Sequence[int], z: ca.SX) -> ca.SX:
    """Solve L x = z (z may have several columns)."""
    n = z.shape[0]
    rows: list[ca.SX] = []
    for k in range(n):
        row = z[k, :]
        for j in _ancestors(parents, k):
            row = row - L[k, j] * rows[j]
        rows.append(row)
    return ca.vertcat(*rows)


def scale_rows(D: Sequence[ca.SX], x: ca.SX, inverse: bool = True) -> ca.SX:
    """diag(D)^-1 x (or diag(D) x)."""
    return ca.vertcat(*[x[k, :] / D[k] if inverse else x[k, :] * D[k] for k in range(len(D))])


def tree_solve(M: ca.SX, parents: Sequence[int], b: ca.SX) -> ca.SX:
    """M^-1 b for a tree-structured SPD mass matrix."""
    L, D = tree_ldl(M, parents)
    return tree_solve_l(L, parents, scale_rows(D, tree_solve_lt(L, parents, b)))


def dense_ldl_solve(A: ca.SX, b: ca.SX) -> ca.SX:
    """A^-1 b for a small dense SPD matrix via LDL^T without pivoting."""
    n = A.shape[0]
    L = [[None] * n for _ in range(n)]
    D: list[ca.SX] = []
    for j in range(n):
        d = A[j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
        D.append(d)
        for i in range(j + 1, n):
            s = A[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
            L[i][j] = s / d
    y: list[ca.SX] = []
    for i in range(n):
        y.append(b[i, :] - sum((L[i][k] * y[k] for k in range(i)), ca.SX.zeros(1, b.shape[1])))
    x: list[ca.SX] = [None] * n
    for i in range(n - 1, -1, -1):
        acc = y[i] / D[i]
        for k in range(i + 1, n):
            acc = acc - L[k][i] * x[k]
        x[i] = acc
    return ca.vertcat(*x)
