"""roa_in_safe_set on the contact manifold: E inside C where constrained flows can reach it.

Points of E are projected onto the contact manifold (feet on the ground and still) before h is
evaluated, and a local search looks for the worst boundary point. Every set of points the search
needs at once (the samples of a clock time, a forward-difference Jacobian, the steps of all starts)
is projected and evaluated in one batch (compile/rigidbody/projection.py, evaluate.h_many).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compile.contacts import held_feet
from ..compile.primitive import CompiledPrimitive
from .evaluate import active_rows, clock, fold_min, h_active, h_many, least, offsets


def contact_projection(p: CompiledPrimitive, W: np.ndarray):
    """(x, x*, t) -> (x on the contact manifold of the primitive's contact mode at x*, or of the
    feet its contact schedule holds at clock t; that mode), or None for systems without contacts.
    Its `.many(X, x*, t)` projects every row of X onto the same manifold."""
    sys = p.system
    if not sys.is_rigid_body or not sys.model.contact_frames:
        return None
    held = held_feet(p.contacts)

    def mode(xs, t):
        return held(t) if held is not None else sys.contact_mode(xs, p.contacts.feet)

    def project(x, xs, t=0.0):
        feet = mode(xs, t)
        return sys.project_to_contacts(x, feet, W), feet

    def many(X, xs, t=0.0):
        feet = mode(xs, t)
        return sys.project_to_contacts_many(X, feet, W), feet

    project.many = many
    return project


def _wnorms(W: np.ndarray, D: np.ndarray) -> list[float]:
    """||d||_W of every row of D, each as sqrt(max(d @ W @ d, 0)) of a single point."""
    v = ((D[:, None, :] @ W) @ D[:, :, None])[:, 0, 0]
    return np.sqrt(np.where(0.0 > v, 0.0, v)).tolist()


@dataclass
class _Search:
    """The state of the search on the manifold at one clock time t (x* = xs, ball coordinates z)."""

    p: CompiledPrimitive
    project: object
    L: np.ndarray
    r: float
    xs: np.ndarray
    t: float
    scale: np.ndarray
    worst: float = np.inf
    feet: set = field(default_factory=set)

    def h_projected(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x0 = x* + L z, its projection x, active h at x) for every row z of Z."""
        X0 = offsets(self.xs, self.L, Z)
        X, mode = self.project.many(X0, self.xs, self.t)
        self.feet.update(mode)
        V = h_many(self.p, X, self.t)
        self.worst = fold_min(self.worst, least(V))
        H = active_rows(V)
        if H.shape[1] != self.scale.size:
            raise ValueError("the active safety functions differ from those at x*")
        return X0, X, H

    def hv(self, Z: np.ndarray) -> np.ndarray:
        return self.h_projected(Z)[2]

    def rel(self, H: np.ndarray) -> list[float]:
        """The least relative margin h_i / h_i(x*) of every row of H."""
        return (H / self.scale).min(axis=1).tolist()

    def jac(self, Z: np.ndarray, H0: np.ndarray) -> list[np.ndarray]:
        """Forward-difference Jacobians d h / d z at every row of Z (whose h are H0), all in one batch."""
        k = self.L.shape[1]
        e = max(1e-7, 1e-4 * self.r)
        steps = (Z[:, None, :] + e * np.eye(k)).reshape(-1, k)
        H = self.hv(steps).reshape(Z.shape[0], k, -1)
        return [np.ascontiguousarray(((Hj - h0) / e).T) for Hj, h0 in zip(H, H0)]  # rows: the gradients of h_i

    def to_boundary(self, g: np.ndarray) -> np.ndarray | None:
        n = np.linalg.norm(g)
        return -self.r * g / n if n > 0 else None

    def descend(self, starts: list[tuple[float, np.ndarray, np.ndarray]], steps: int) -> None:
        """From each start (m, z, h at z): step to z = to_boundary(grad h_i) of the h_i with the least
        relative margin while that lowers m, at most `steps` times; all starts advance together."""
        run = list(starts)
        for _ in range(steps):
            if not run:
                return
            G = self.jac(np.array([z for _, z, _ in run]), [h for _, _, h in run])
            moved = [(c, self.to_boundary(g[int(np.argmin(c[2] / self.scale))])) for c, g in zip(run, G)]
            moved = [(c, z) for c, z in moved if z is not None]
            if not moved:
                return
            H = self.hv(np.array([z for _, z in moved]))
            run = [(m_new, z, h) for ((m, _, _), z), m_new, h in zip(moved, self.rel(H), H) if not m_new >= m - 1e-12]


def roa_on_contact_manifold(p, samples, rng, W, L, r, project, starts: int = 3, steps: int = 8) -> dict:
    """roa_in_safe_set on the contact manifold: the numbers of _manifold_check.

    Per clock time: `samples` points on E's boundary and as many inside (uniform in radius), each
    projected onto the manifold before h is evaluated; then a local worst-case search on E's
    boundary. The search linearises every h_i(project(x* + L z)) in the ball coordinates z (forward
    differences), steps to the boundary point z = -r grad h_i / |grad h_i| and repeats, from the
    `starts` points (those steps and the samples) nearest to leaving C. Nearness is the least
    h_i / h_i(x*): on the manifold the contact functions sit at their tolerance while forces (in
    newtons) vary, so the relative margin, unlike h itself, finds the functions that can fail.
    Distances are in E's norm ||.||_W.
    """
    k = L.shape[1]
    worst, raw_worst = np.inf, np.inf
    dist, spread, feet = [], [], set()
    for t in clock(p, 8):
        xs = p.x_star(t)
        scale = np.maximum(h_active(p, xs, t), 1e-9)
        if not scale.size:
            continue
        rt = r * float(p.radius_scale(t))  # E(t)'s radius (narrower before a touchdown)
        s = _Search(p, project, L, rt, xs, t, scale, worst, feet)
        d = rng.normal(size=(2 * samples, k))
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        d *= rt * np.r_[np.ones(samples), rng.uniform(size=samples)][:, None]
        X0, X, H = s.h_projected(d)
        dist += _wnorms(W, X - X0)
        spread += _wnorms(W, X - xs)
        raw_worst = fold_min(raw_worst, least(h_many(p, X0, t)))
        cands = list(zip(s.rel(H), d, H))
        if rt > 0:
            H0 = s.hv(np.zeros((1, k)))
            bounds = [z for z in (s.to_boundary(g) for g in s.jac(np.zeros((1, k)), H0)[0]) if z is not None]
            if bounds:
                Hb = s.hv(np.array(bounds))
                cands += list(zip(s.rel(Hb), bounds, Hb))
        cands.sort(key=lambda c: c[0])
        s.descend(cands[:starts], steps)
        worst = s.worst
    return {"worst": worst, "raw_worst": raw_worst, "dist": dist, "spread": spread, "feet": feet}
