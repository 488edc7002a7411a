"""The region of a level-set verifier as the level set {V(x - x*) <= rho} and as the largest W-ball
inside it, and E as the level set itself when the spec asks for it (`roa.options.region: level_set`).

V is read from the verifier's evidence: a polynomial (`V`: monomials and coefficients, degree >= 2)
or the quadratic y'Py (`P`). As E, the level set gets the margin

    m(x, t) = r (1 - sqrt(V(y) / rho)),   y = x - x*(t) (wrapped states the short way round),

positive exactly inside {V < rho}; for V = y'Wy r^2 / rho it is the ball's margin r - ||y||_W, so the
oracle's margins and error bounds keep their scale. The compiled margin is checked in float64
against V evaluated by numpy, and the certified ball against the level set, before it is used.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..compile.primitive import CompiledPrimitive


@dataclass(frozen=True)
class LevelSet:
    """{y : V(y) <= rho} with V = sum_k c_k prod_i y_i^m_ki (y = x - x*)."""

    monomials: np.ndarray  # (K, n) exponents
    coefficients: np.ndarray  # (K,)
    rho: float

    @property
    def degree(self) -> int:
        return int(self.monomials.sum(axis=1).max(initial=0))

    def value(self, Y: np.ndarray) -> np.ndarray:
        """V at the rows of Y (float64)."""
        Y = np.atleast_2d(np.asarray(Y, float))
        return (np.prod(Y[:, None, :] ** self.monomials[None], axis=2) * self.coefficients).sum(axis=1)

    def expr(self, y):
        """V as a CasADi expression of y."""
        out = 0
        for m, c in zip(self.monomials, self.coefficients):
            term = float(c)
            for i, e in enumerate(m):
                if e:
                    term = term * y[i] ** int(e)
            out = out + term
        return out

    def to_dict(self) -> dict:
        return {"rho": self.rho, "degree": self.degree, "coordinates": "y = x - x*",
                "V": {"monomials": self.monomials.tolist(), "coefficients": self.coefficients.tolist()}}


def level_set_of(evidence: dict) -> LevelSet | None:
    """The level set a verifier's evidence describes (polynomial V or quadratic P, and rho), else None."""
    rho = evidence.get("rho")
    if not isinstance(rho, (int, float)) or not np.isfinite(rho) or rho <= 0:
        return None
    V = evidence.get("V")
    if isinstance(V, dict) and V.get("monomials"):
        return LevelSet(np.asarray(V["monomials"], int), np.asarray(V["coefficients"], float), float(rho))
    P = evidence.get("P")
    if P is None:
        return None
    P = np.asarray(P, float)
    n = len(P)
    mons, coef = [], []
    for i in range(n):
        for j in range(i, n):
            m = [0] * n
            m[i] += 1
            m[j] += 1
            mons.append(m)
            coef.append(P[i, i] if i == j else P[i, j] + P[j, i])
    return LevelSet(np.asarray(mons, int), np.asarray(coef, float), float(rho))


def level_set_margin(prim: CompiledPrimitive, ls: LevelSet, scale: float) -> ca.Function:
    """(x, t) -> scale (1 - sqrt(V(y) / rho)), the margin of E = {V <= rho} (see the module docstring)."""
    sys = prim.system
    sym = ca.SX if prim.setpoint.is_a("SXFunction") else ca.MX
    x, t = sym.sym("x", sys.nx), sym.sym("t")
    y = sys.wrapped_error(x - prim.setpoint(t))
    margin = scale * (1 - ca.sqrt(ca.fmax(ls.expr(y), 0) / ls.rho))
    return ca.Function(f"{prim.roa_margin.name()}_levelset", [x, t], [margin], ["x", "t"], ["margin"])


def validate(prim: CompiledPrimitive, margin: ca.Function, ls: LevelSet, W: np.ndarray, r: float,
             samples: int = 4000, seed: int = 0) -> dict:
    """Float64 checks of E = {V <= rho}: the compiled margin against V by numpy at random points
    around x* (inside, outside and near the boundary), and the certified W-ball inside the level set."""
    n = prim.system.nx
    rng = np.random.default_rng(seed)
    xs = prim.x_star(0.0)
    w, U = np.linalg.eigh(np.asarray(W, float))
    L = U / np.sqrt(np.clip(w, 1e-300, None))  # unit W-norm directions -> state offsets
    D = rng.normal(size=(samples, n))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    Y = (D @ L.T) * (r * rng.uniform(0.0, 4.0, samples))[:, None]
    F = margin.map(samples)
    got = np.asarray(F((xs[:, None] + Y.T), np.zeros((1, samples))), float).ravel()
    period = np.asarray(prim.system.wrap, float)
    Yw = np.where(period > 0, Y - period * np.floor((Y + period / 2) / np.where(period > 0, period, 1.0)), Y)
    want = r * (1 - np.sqrt(np.maximum(ls.value(Yw), 0) / ls.rho))
    err = float(np.abs(got - want).max()) if samples else 0.0
    ball = (D @ L.T) * r * (1 - 1e-9)
    v_ball = float(ls.value(ball).max() / ls.rho) if samples else 0.0
    ok = err <= 1e-9 * max(1.0, r) and v_ball <= 1 + 1e-9 and float(margin(xs, 0.0)) > 0
    return {"ok": bool(ok), "points": samples, "max_margin_error": err, "max_V_over_rho_on_ball": v_ball}


def use_level_set(prim: CompiledPrimitive, evidence: dict, r: float) -> tuple[CompiledPrimitive | None, dict]:
    """prim with E = the level set of its evidence, and the region record; None when the level set is
    missing or fails its float64 checks (the record says why)."""
    ls = level_set_of(evidence)
    if ls is None or not r > 0:
        return None, {"E": "ball", "reason": "no level set {V <= rho} in the verifier's evidence"}
    W = np.asarray(prim.W, float)
    margin = level_set_margin(prim, ls, r)
    check = validate(prim, margin, ls, W, r)
    if not check["ok"]:
        return None, {"E": "ball", "reason": "the level set failed its float64 check", "check": check}
    return dataclasses.replace(prim, roa_margin=margin, cache={}), {"E": "level_set", "check": check}
