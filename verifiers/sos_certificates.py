"""Gram-matrix sum-of-squares certificates on cvxpy, checked in float64 after every solve.

Polynomials are dicts {exponent tuple: coefficient}, read exactly from the instruction list of a
CasADi SX Function (any non-polynomial operation on the state raises NotPolynomial). The one
certificate used by the RoA verifiers is the S-procedure for sublevel sets,

    p(y) - lam(y) (rho - V(y)) = z0(y)' Q0 z0(y),   lam = z1' Q1 z1,   Q0, Q1 PSD,

which proves p >= 0 on {V <= rho}. A solver answer is only a candidate: `LevelSetProgram.check`
projects Q1 onto the PSD cone, recomputes the identity, moves the leftover coefficients into Q0
and accepts only if that corrected Q0 is positive definite, so the certificate holds for the
float64 polynomials and not just up to the solver's tolerance.
"""
from __future__ import annotations

import itertools
import math
import time
import warnings
from dataclasses import dataclass, field

import casadi as ca
import cvxpy as cp
import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from mpgspec.streams import stdout_to_stderr

from .roa_common import validate_gram

Poly = dict[tuple[int, ...], float]
_OP_NAMES = {getattr(ca, a): a[3:].lower() for a in dir(ca) if a.startswith("OP_")}


class NotPolynomial(ValueError):
    """The expression uses a non-polynomial operation on the variables."""


def monomials(n: int, dmin: int, dmax: int) -> list[tuple[int, ...]]:
    """Exponent tuples of all monomials in n variables with total degree in [dmin, dmax]."""
    return [tuple(c.count(i) for i in range(n)) for d in range(max(dmin, 0), dmax + 1)
            for c in itertools.combinations_with_replacement(range(n), d)]


def padd(a: Poly, b: Poly, sb: float = 1.0) -> Poly:
    out = dict(a)
    for k, v in b.items():
        out[k] = out.get(k, 0.0) + sb * v
    return {k: v for k, v in out.items() if v != 0.0}


def pmul(a: Poly, b: Poly) -> Poly:
    out: Poly = {}
    for (ka, va), (kb, vb) in itertools.product(a.items(), b.items()):
        k = tuple(i + j for i, j in zip(ka, kb))
        out[k] = out.get(k, 0.0) + va * vb
    return {k: v for k, v in out.items() if v != 0.0}


def pconst(c: float, n: int) -> Poly:
    return {(0,) * n: float(c)} if c != 0 else {}


def degree(p: Poly) -> int:
    return max((sum(k) for k in p), default=0)


def min_degree(p: Poly) -> int:
    return min((sum(k) for k in p), default=0)


def quadratic(P: np.ndarray) -> Poly:
    """y' P y as a polynomial."""
    return {k: v for k, v in gram_poly(P, monomials(len(P), 1, 1)).items() if v != 0.0}


def newton_basis(basis: list[tuple[int, ...]], support) -> list[tuple[int, ...]]:
    """Monomials m of the basis with 2m in the convex hull of the support (Newton polytope).

    Any Gram representation puts zero rows on the other monomials, which would leave no
    positive definite Gram matrix to validate.
    """
    S = np.array(sorted(support), float).T
    if S.size == 0:
        return []
    keep = []
    for m in basis:
        A_eq = np.vstack([S, np.ones(S.shape[1])])
        b_eq = np.concatenate([2 * np.array(m, float), [1.0]])
        if linprog(np.zeros(S.shape[1]), A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs").status == 0:
            keep.append(m)
    return keep


def gram_poly(Q: np.ndarray, basis: list[tuple[int, ...]]) -> Poly:
    """z' Q z for the monomial vector z of `basis`."""
    out: Poly = {}
    for (i, a), (j, b) in itertools.product(enumerate(basis), enumerate(basis)):
        k = tuple(x + y for x, y in zip(a, b))
        out[k] = out.get(k, 0.0) + float(Q[i, j])
    return out


def from_casadi(fn: ca.Function, shift: np.ndarray | None = None) -> list[Poly]:
    """Each output entry of fn(shift + y) as a polynomial in y, read from the SX instructions."""
    n = fn.size1_in(0)
    y = ca.SX.sym("y", n)
    x0 = np.zeros(n) if shift is None else np.asarray(shift, float)
    out = fn(ca.DM(x0) + y)
    g = ca.Function("g", [y], [ca.vec(out)])
    work: dict[int, Poly] = {}
    res: list[Poly] = [{} for _ in range(g.size1_out(0))]
    bin_ops = {ca.OP_ADD, ca.OP_SUB, ca.OP_MUL, ca.OP_DIV, ca.OP_POW, ca.OP_CONSTPOW}
    for k in range(g.n_instructions()):
        op, i, o = g.instruction_id(k), g.instruction_input(k), g.instruction_output(k)
        if op == ca.OP_CONST:
            work[o[0]] = pconst(g.instruction_constant(k), n)
        elif op == ca.OP_INPUT:
            work[o[0]] = {tuple(int(m == i[1]) for m in range(n)): 1.0}
        elif op == ca.OP_OUTPUT:
            res[o[1]] = work[i[0]]
        elif op == ca.OP_ASSIGN:
            work[o[0]] = work[i[0]]
        elif op == ca.OP_NEG:
            work[o[0]] = {m: -v for m, v in work[i[0]].items()}
        elif op == ca.OP_SQ:
            work[o[0]] = pmul(work[i[0]], work[i[0]])
        elif op == ca.OP_TWICE:
            work[o[0]] = {m: 2 * v for m, v in work[i[0]].items()}
        elif op in bin_ops:
            work[o[0]] = _binary(op, work[i[0]], work[i[1]], n)
        else:
            work[o[0]] = _constant_op(op, [work[j] for j in i], n, k)
    return res


def _is_const(p: Poly) -> bool:
    return all(sum(m) == 0 for m in p)


def _cval(p: Poly) -> float:
    return next(iter(p.values()), 0.0)


def _binary(op: int, a: Poly, b: Poly, n: int) -> Poly:
    if op == ca.OP_ADD:
        return padd(a, b)
    if op == ca.OP_SUB:
        return padd(a, b, -1.0)
    if op == ca.OP_MUL:
        return pmul(a, b)
    if not _is_const(b):
        raise NotPolynomial("division by or power of a state-dependent expression")
    c = _cval(b)
    if op == ca.OP_DIV:
        if c == 0:
            raise NotPolynomial("division by zero")
        return {m: v / c for m, v in a.items()}
    if _is_const(a):
        return pconst(_cval(a) ** c, n)
    if c < 0 or c != int(c):
        raise NotPolynomial(f"power {c} of a state-dependent expression")
    out = pconst(1.0, n)
    for _ in range(int(c)):
        out = pmul(out, a)
    return out


def _constant_op(op: int, args: list[Poly], n: int, k: int) -> Poly:
    if not all(_is_const(a) for a in args):
        raise NotPolynomial(f"{_OP_NAMES.get(op, op)} of a state-dependent expression")
    vals = [ca.SX(_cval(a)) for a in args]
    v = ca.SX.unary(op, vals[0]) if len(vals) == 1 else ca.SX.binary(op, vals[0], vals[1])
    return pconst(float(ca.evalf(v)), n)


@dataclass
class Certificate:
    """Outcome of one solve and its float64 check; `ok` only if the check passed."""

    ok: bool
    reason: str
    rho: float
    status: str = ""
    solver: str = ""
    solve_time: float = 0.0
    gram_min_eig: dict = field(default_factory=dict)
    residual: float = float("nan")
    grams: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"ok": self.ok, "reason": self.reason, "rho": self.rho, "status": self.status, "solver": self.solver,
                "solve_time_s": self.solve_time, "gram_min_eig": self.gram_min_eig, "max_residual": self.residual}


class LevelSetProgram:
    """Certificates of p(y) >= 0 on {V(y) <= rho}, compiled once with rho as a cvxpy Parameter.

    lam gets monomials of degree ceil(mindeg(p)/2) .. half of deg(p) - deg(V) (rounded up), so
    lam(0) = 0 whenever p(0) = 0. With V = None it certifies p SOS. `interior` maximises the least
    eigenvalue of Q0 instead of taking any feasible point, for programs whose feasible Gram matrices
    are nearly singular (higher-degree V), so that the float64 check has room.
    """

    def __init__(self, p: Poly, V: Poly | None, n: int, mult_half_degree: int | None = None,
                 solver: str = "CLARABEL", solver_opts: dict | None = None, tol_eig: float = 1e-8,
                 tol_res: float = 1e-6, newton: bool = True, interior: bool = False):
        self.p, self.V, self.n = p, V or {}, n
        self.solver, self.solver_opts = solver, dict(solver_opts or {})
        self.tol_eig, self.tol_res = tol_eig, tol_res * max(1.0, max(map(abs, p.values()), default=1.0))
        dV = degree(self.V) if V else 0
        lo = math.ceil(min_degree(p) / 2)
        hi = mult_half_degree if mult_half_degree is not None else math.ceil(max(degree(p) - dV, 0) / 2)
        self.B1 = monomials(n, lo, hi) if V else []
        dmin = min(min_degree(p), 2 * lo) if self.B1 else min_degree(p)
        dmax = max(degree(p), 2 * hi + dV) if self.B1 else degree(p)
        lam = gram_poly(np.ones((len(self.B1),) * 2), self.B1)
        support = set(p) | set(lam) | set(pmul(lam, {m: 1.0 for m in self.V}))
        self.B0 = monomials(n, math.ceil(dmin / 2), dmax // 2)
        self.B0 = newton_basis(self.B0, support) if newton else self.B0
        self.rho = cp.Parameter(nonneg=True, value=1.0)
        self.Q0 = cp.Variable((len(self.B0),) * 2, PSD=True)
        self.Q1 = cp.Variable((len(self.B1),) * 2, PSD=True) if self.B1 else None
        monos = support | set(gram_poly(np.ones((len(self.B0),) * 2), self.B0))
        self.index = {m: k for k, m in enumerate(sorted(monos))}
        c = np.zeros(len(self.index))
        for m, v in p.items():
            c[self.index[m]] = v
        lhs = c - self._gram_map(self.B0, {}) @ cp.vec(self.Q0, order="F")
        if self.B1:
            q1 = cp.vec(self.Q1, order="F")
            lhs = lhs - self.rho * (self._gram_map(self.B1, {}) @ q1) + self._gram_map(self.B1, self.V) @ q1
        if interior:
            tau = cp.Variable()
            top = max(map(abs, p.values()), default=1.0)
            self.problem = cp.Problem(cp.Maximize(tau), [lhs == 0, self.Q0 - tau * np.eye(len(self.B0)) >> 0,
                                                         tau <= top])
        else:
            self.problem = cp.Problem(cp.Minimize(0), [lhs == 0])

    def _gram_map(self, basis, mult: Poly) -> sp.csr_matrix:
        """Sparse map vec(Q) -> coefficients of (z'Qz) * mult (mult = {} means 1)."""
        mult = mult or {(0,) * self.n: 1.0}
        m = len(basis)
        rows, cols, vals = [], [], []
        for (i, a), (j, b) in itertools.product(enumerate(basis), enumerate(basis)):
            for e, v in mult.items():
                rows.append(self.index[tuple(x + y + z for x, y, z in zip(a, b, e))])
                cols.append(i + j * m)
                vals.append(v)
        return sp.csr_matrix((vals, (rows, cols)), shape=(len(self.index), m * m))

    def solve(self, rho: float) -> Certificate:
        """Solve at this rho and check the answer; a failed check gives ok=False and the reason."""
        self.rho.value = float(rho)
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings(), stdout_to_stderr():
                warnings.simplefilter("ignore", UserWarning)
                # never verbose: solver logs would end up in the report's stdout (see roa_common)
                self.problem.solve(solver=self.solver, **{**self.solver_opts, "verbose": False})
        except cp.error.SolverError as e:
            return Certificate(False, f"solver error: {e}", rho, "error", self.solver, time.perf_counter() - t0)
        dt = time.perf_counter() - t0
        st = self.problem.status
        if st not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self.Q0.value is None:
            return Certificate(False, f"solver status {st}", rho, st, self.solver, dt)
        Q1 = self.Q1.value if self.Q1 is not None else np.zeros((0, 0))
        cert = self.check(rho, self.Q0.value, Q1)
        cert.status, cert.solver, cert.solve_time = st, self.solver, dt
        return cert

    def check(self, rho: float, Q0: np.ndarray, Q1: np.ndarray) -> Certificate:
        """Float64 check of p - lam (rho - V) = z0'Q0z0 with lam = z1'Q1z1; names every failed check."""
        Q0, Q1 = 0.5 * (Q0 + Q0.T), 0.5 * (Q1 + Q1.T)
        ok1, e1 = validate_gram(Q1, self.tol_eig)
        ok0, e0 = validate_gram(Q0, self.tol_eig)
        eigs, fails = {"multiplier": e1, "sigma0": e0}, []
        if not ok1:
            fails.append(f"Gram eigenvalue check failed: multiplier min eigenvalue {e1:.3g} < -{self.tol_eig:.1g}")
        if not ok0:
            fails.append(f"Gram eigenvalue check failed: sigma0 min eigenvalue {e0:.3g} < -{self.tol_eig:.1g}")
        if not (np.isfinite(Q0).all() and np.isfinite(Q1).all()):
            return Certificate(False, "; ".join(fails) or "non-finite Gram matrix", rho, gram_min_eig=eigs)
        target = dict(self.p)
        if len(Q1):
            w, U = np.linalg.eigh(Q1)
            Q1 = (U * np.clip(w, 0, None)) @ U.T  # exactly-PSD multiplier
            target = padd(target, pmul(gram_poly(Q1, self.B1), padd(pconst(rho, self.n), self.V, -1.0)), -1.0)
        r = padd(target, gram_poly(Q0, self.B0), -1.0)
        res = max(map(abs, r.values()), default=0.0)
        grams = {"Q0": Q0, "Q1": Q1}
        where: dict = {}
        for (i, a), (j, b) in itertools.product(enumerate(self.B0), enumerate(self.B0)):
            where.setdefault(tuple(x + y for x, y in zip(a, b)), (i, j))
        if res > self.tol_res:
            fails.append(f"residual check failed: max coefficient residual {res:.3g} > {self.tol_res:.1g}")
        if any(m not in where for m in r):
            fails.append("residual check failed: residual on monomials outside the Gram support")
        if fails:
            return Certificate(False, "; ".join(fails), rho, gram_min_eig=eigs, residual=res, grams=grams)
        E = np.zeros_like(Q0)  # move the leftover coefficients into Q0, then Q0 + E must be PD
        for m, v in r.items():
            i, j = where[m]
            E[i, j] += v / 2
            E[j, i] += v / 2
        ec = float(np.linalg.eigvalsh(Q0 + E).min()) if len(Q0) else float("inf")
        eigs["sigma0_corrected"] = ec
        margin = 1e-10 * max(1.0, float(np.abs(Q0).max(initial=0.0)))
        if not ec > margin:
            return Certificate(False, f"Gram eigenvalue check failed: sigma0 min eigenvalue {ec:.3g} after absorbing "
                               f"residuals (needs > {margin:.1g})", rho, gram_min_eig=eigs, residual=res, grams=grams)
        return Certificate(True, "validated", rho, gram_min_eig=eigs, residual=res, grams=grams)


def prove_sos(p: Poly, n: int, **kw) -> Certificate:
    """Try to certify that p is a sum of squares (Gram basis from its degree range)."""
    return LevelSetProgram(p, None, n, **kw).solve(0.0)
