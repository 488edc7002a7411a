"""Lohner sets {m + B r}: a point m, an orthogonal float matrix B and a ball vector r.

Carrying the set in the coordinates of B (the midpoint of the flow's Jacobian times the last B,
re-orthogonalised by QR with columns ordered by length when it becomes ill-conditioned) keeps a
rotating box from growing into the box around it: the wrapping effect that makes plain interval
boxes explode within seconds. All arithmetic on r is in arb balls; B and m are
exact floats, and B's inverse is enclosed rigorously (arb_mat.inv).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from flint import arb, arb_mat


COND = 1e3
"""The set's matrix B follows the flow's Jacobian (the parallelepiped method: no wrapping at all for
a linear flow) while its condition number stays below this; beyond, it is re-orthogonalised by QR."""


@dataclass
class LohnerSet:
    m: list  # exact float points as arb
    B: np.ndarray  # invertible, well conditioned (COND)
    Binv: arb_mat  # an enclosure of B^-1
    r: arb_mat  # n x 1 balls

    @classmethod
    def box(cls, center, radius) -> "LohnerSet":
        """The box center +- radius (per state)."""
        n = len(center)
        m = [arb(float(c)) for c in center]
        r = arb_mat([[arb(0, float(q)) if q > 0 else arb(0)] for q in np.broadcast_to(radius, (n,))])
        return cls(m, np.eye(n), arb_mat(np.eye(n).tolist()), r)

    def hull(self) -> list:
        """The ball vector enclosing the set."""
        Br = arb_mat(self.B.tolist()) * self.r
        return [self.m[i] + Br[i, 0] for i in range(len(self.m))]

    def through(self, image: list, C: arb_mat) -> "LohnerSet":
        """The set {y + C B r}: the image of this set under a map whose value at m is enclosed by
        `image` (balls) and whose Jacobian over the set, times B, is enclosed by C."""
        n = len(self.m)
        A = np.array([[float(C[i, j].mid()) for j in range(n)] for i in range(n)])
        Q = A if np.all(np.isfinite(A)) and np.linalg.cond(A) < COND else _orthonormal(A)
        m = [arb(float(v.mid())) for v in image]
        Qinv = arb_mat(Q.tolist()).inv()
        rest = arb_mat([[image[i] - m[i]] for i in range(n)])
        r = (Qinv * C) * self.r + Qinv * rest
        return LohnerSet(m, Q, Qinv, r)

    def shifted(self, delta: list) -> "LohnerSet":
        """The set plus every vector of the ball vector delta (a first-order hull step)."""
        n = len(self.m)
        m = [arb(float((self.m[i] + delta[i]).mid())) for i in range(n)]
        rest = arb_mat([[self.m[i] + delta[i] - m[i]] for i in range(n)])
        return LohnerSet(m, self.B, self.Binv, self.r + self.Binv * rest)

    def width(self) -> float:
        """The largest width of the hull."""
        return max(2 * float(v.rad()) for v in self.hull())


def _orthonormal(A: np.ndarray) -> np.ndarray:
    """Q of the QR decomposition of A with its columns sorted by decreasing length (Lohner's
    choice: the longest direction of the set is kept exactly); I when A is singular."""
    norms = np.linalg.norm(A, axis=0)
    if not np.all(np.isfinite(A)) or norms.min() == 0:
        return np.eye(A.shape[0])
    Q, R = np.linalg.qr(A[:, np.argsort(-norms)])
    return Q
