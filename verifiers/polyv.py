"""Polynomial Lyapunov level sets of chosen degree by V-rho alternation, every accepted one checked in float64.

For a polynomial closed loop ydot = f(y) (y = x - x*) the region {V <= rho} is a certified safe
region of attraction when, with polynomial V of degree d >= 2 and V(0) = 0,

    V - epsV |y|^2              is SOS                                 (V positive definite, level sets bounded)
    -Vdot - eps |y|^2           >= 0 on {V <= rho}   (S-procedure)     (strict decrease)
    h_i                         >= 0 on {V <= rho}   (S-procedure)     (inside C)

and E, the largest W-ball inside it, has radius r with  rho - V >= 0 on {y'Wy <= r^2}  (S-procedure
again, so r is a proven lower bound and not a sampled estimate).

The search is bilinear in V and the multipliers; it alternates two convex steps:
  A (V fixed): the largest rho, then the largest ball, by bisection over checked certificates
    (LevelSetProgram with the most interior Gram matrix, whose float64 check decides acceptance);
  B (multipliers of A fixed, V rescaled to rho = 1): a new V whose level 1 still passes with those
    multipliers and that holds A's ball at the lowest level gamma - V - s (t - y'Wy) SOS, s SOS;
    the previous V is feasible at gamma = 1, so the next step A finds at least that ball.
Only step A's certificates are reported; step B merely proposes the next V. The best checked
(V, rho, r) over the iterations is the result.
"""
from __future__ import annotations

import itertools
import math
import time
import warnings

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from mpgspec.certify.problem import RoAResult, weakest
from mpgspec.streams import stdout_to_stderr

from .roa_common import inv_sqrt
from .sos_certificates import (LevelSetProgram, Poly, degree, gram_poly, monomials, padd, pconst, pmul, prove_sos,
                               quadratic)


def _unit(n: int, i: int) -> tuple[int, ...]:
    return tuple(int(k == i) for k in range(n))


def _derivative(m: tuple[int, ...], i: int) -> Poly:
    if m[i] == 0:
        return {}
    return {tuple(e - (k == i) for k, e in enumerate(m)): float(m[i])}


def lie_derivative(V: Poly, f: list[Poly]) -> Poly:
    """grad V . f, dropping f's constant terms (x* is an equilibrium to tolerance)."""
    n = len(f)
    zero = (0,) * n
    fz = [{k: v for k, v in fi.items() if k != zero} for fi in f]
    out: Poly = {}
    for m, c in V.items():
        for i in range(n):
            d = _derivative(m, i)
            if d:
                out = padd(out, pmul({k: c * v for k, v in d.items()}, fz[i]))
    return out


def quadratic_part(V: Poly, n: int) -> np.ndarray:
    """The symmetric P with y'Py the degree-2 part of V."""
    P = np.zeros((n, n))
    for m, c in V.items():
        if sum(m) == 2:
            idx = [i for i in range(n) for _ in range(m[i])]
            i, j = idx
            if i == j:
                P[i, i] += c
            else:
                P[i, j] += c / 2
                P[j, i] += c / 2
    return P


class _Identity:
    """Coefficient-wise polynomial identity  const + sum_k M_k var_k == 0  for cvxpy variables."""

    def __init__(self, n: int):
        self.n, self.const, self.terms = n, {}, []

    def add_poly(self, p: Poly, s: float = 1.0):
        self.const = padd(self.const, p, s)

    def add_gram(self, Q: cp.Variable, basis, mult: Poly | None = None, s: float = 1.0):
        """+ s * (z'Qz) * mult."""
        mult = mult or {(0,) * self.n: 1.0}
        m = len(basis)
        tr = [(tuple(x + y + z for x, y, z in zip(a, b, e)), i + j * m, s * v)
              for (i, a), (j, b) in itertools.product(enumerate(basis), enumerate(basis)) for e, v in mult.items()]
        self.terms.append((cp.vec(Q, order="F"), m * m, tr))

    def add_coeffs(self, v: cp.Variable, polys: list[Poly], s: float = 1.0):
        """+ s * sum_c v_c polys[c]."""
        tr = [(k, c, s * val) for c, p in enumerate(polys) for k, val in p.items()]
        self.terms.append((v, len(polys), tr))

    def constraint(self):
        monos = set(self.const) | {t[0] for _, _, tr in self.terms for t in tr}
        index = {m: i for i, m in enumerate(sorted(monos))}
        expr = np.zeros(len(index))
        for m, v in self.const.items():
            expr[index[m]] += v
        out = expr
        for var, size, tr in self.terms:
            rows = [index[t[0]] for t in tr]
            M = sp.csr_matrix(([t[2] for t in tr], (rows, [t[1] for t in tr])), shape=(len(index), size))
            out = out + M @ var
        return out == 0


def _gram_basis(n: int, lo_deg: int, hi_deg: int) -> list[tuple[int, ...]]:
    return monomials(n, math.ceil(lo_deg / 2), hi_deg // 2)


def _solve(problem: cp.Problem, solver: str, opts: dict) -> str:
    try:
        with warnings.catch_warnings(), stdout_to_stderr():
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=solver, **{**opts, "verbose": False})
    except cp.error.SolverError:
        return "error"
    return problem.status


class PolyLyapunov:
    """The alternation for one polynomial closed loop; see the module docstring."""

    def __init__(self, f: list[Poly], h: list[Poly], W: np.ndarray, A: np.ndarray, o: dict, certified):
        self.f, self.h, self.n = f, h, len(f)
        self.W, self.A = np.asarray(W, float), A
        self.d = int(o.get("degree", 4))
        # interior certificates, multipliers of degree d (near-singular Gram matrices otherwise fail the float64
        # check); a solver error counts as "no certificate at this level" (no slow fallback)
        self.o = {"mult_half_degree": self.d // 2, **o, "interior": True, "solver": o.get("solver", "CLARABEL")}
        self.certified = certified  # (p, V, n, hi, guess, cap, o) -> (rho, level, info), as lyapunov._certified
        self.solver = o.get("solver", "CLARABEL")
        self.solver_opts = dict(o.get("solver_opts") or {})
        self.mv = monomials(self.n, 2, self.d)  # monomials of V
        self.bv = monomials(self.n, 1, self.d // 2)  # Gram basis of V - epsV |y|^2
        self.ball = quadratic(self.W)
        self.deg_f = max(degree(fi) for fi in f)

    def eps(self, V: Poly) -> float:
        P = quadratic_part(V, self.n)
        Qd = -(self.A.T @ P + P @ self.A)
        return float(self.o.get("eps", 1e-4)) * float(np.linalg.eigvalsh(Qd).min())

    def step_a(self, V: Poly, guess: float, cap: float) -> dict | None:
        """Largest checked rho for V, then the largest checked W-ball inside {V <= rho}; None if none."""
        eps = self.eps(V)
        if not eps > 0:
            return None
        parts, levels, rho_safe = [], [], float("inf")
        for i, hp in enumerate(self.h):
            r, lev, info = self.certified(hp, V, self.n, rho_safe, guess, cap, self.o)
            parts.append({"part": f"h[{i}]", "level": lev, "rho": r, **info})
            levels.append(lev)
            rho_safe = min(rho_safe, r)
            if rho_safe <= 0:
                return None
        p = padd(padd({}, lie_derivative(V, self.f), -1.0), quadratic(eps * np.eye(self.n)), -1.0)
        rho, lev, info = self.certified(p, V, self.n, rho_safe, guess, cap, self.o)
        info["eps"] = eps
        parts.append({"part": "Vdot", "level": lev, "rho": rho, **info})
        levels.append(lev)
        rho = min(rho, rho_safe)
        if rho <= 0 or weakest(*levels) != "certified":
            return None
        Vn = {m: c / rho for m, c in V.items()}
        r2, ball = self.ball_level(V, rho)
        if r2 <= 0:
            return None
        return {"V": V, "rho": rho, "Vn": Vn, "r2": r2, "parts": parts, "ball": ball, "eps": eps}

    def ball_level(self, V: Poly, rho: float) -> tuple[float, dict]:
        """Largest checked t with rho - V >= 0 on {y'Wy <= t} (S-procedure, bisection on t)."""
        p = padd(pconst(rho, self.n), V, -1.0)
        Wi = inv_sqrt(self.W)
        P = quadratic_part(V, self.n) / rho
        t_lin = 1.0 / float(np.linalg.eigvalsh(Wi @ P @ Wi).max())  # ball inside the quadratic part's level
        rho, lev, info = self.certified(p, self.ball, self.n, float("inf"), t_lin, 1e3 * t_lin, self.o)
        return (rho if lev == "certified" else 0.0), info

    def positive(self, V: Poly) -> tuple[bool, dict]:
        """Checked SOS certificate of V - epsV |y|^2 (epsV tiny against V's quadratic part)."""
        P = quadratic_part(V, self.n)
        lo = float(np.linalg.eigvalsh(P).min())
        if not lo > 0:
            return False, {"reason": "quadratic part of V is not positive definite"}
        epsv = 1e-6 * lo
        cert = prove_sos(padd(V, quadratic(epsv * np.eye(self.n)), -1.0), self.n,
                             solver=self.solver, solver_opts=self.solver_opts,
                             tol_eig=self.o.get("tol_eig", 1e-8), tol_res=self.o.get("tol_res", 1e-6))
        return cert.ok, {"epsV": epsv, **cert.summary()}

    def step_b(self, a: dict) -> Poly | None:
        """A new V (level 1) holding step A's ball at the lowest level, under step A's multipliers."""
        n, rho = self.n, a["rho"]
        v = cp.Variable(len(self.mv))
        G = cp.Variable((len(self.bv),) * 2, PSD=True)
        gamma = cp.Variable()
        cons = [G >> 0]
        basis_polys = [{m: 1.0} for m in self.mv]
        Vn = a["Vn"]
        Pq = quadratic_part(Vn, n)
        epsv = 1e-3 * float(np.linalg.eigvalsh(Pq).min())
        ident = _Identity(n)  # V - epsV|y|^2 - z'Gz = 0
        ident.add_coeffs(v, basis_polys)
        ident.add_poly(quadratic(epsv * np.eye(n)), -1.0)
        ident.add_gram(G, self.bv, s=-1.0)
        cons.append(ident.constraint())
        one = pconst(1.0, n)
        for part in a["parts"]:
            cert = part["certificate"]
            # p - lam (rho - V) = SOS at level rho is p/rho - lam (1 - V/rho) for Vdot, p - rho lam (1 - V/rho) for h
            lam = gram_poly(np.asarray(cert["Q1"], float) * (1.0 if part["part"] == "Vdot" else rho),
                                [tuple(m) for m in cert["B1"]])
            ident = _Identity(n)
            if part["part"] == "Vdot":
                # -Vdot(v) - eps|y|^2 - lam (1 - V(v)) = z'Qz
                ident.add_coeffs(v, [lie_derivative({m: 1.0}, self.f) for m in self.mv], -1.0)
                ident.add_poly(quadratic(part["eps"] / rho * np.eye(n)), -1.0)
                deg = max(self.d - 1 + self.deg_f, degree(lam) + self.d, 2)
            else:
                hp = self.h[int(part["part"][2:-1])]
                ident.add_poly(hp)
                deg = max(degree(hp), degree(lam) + self.d)
            ident.add_poly(pmul(lam, one), -1.0)
            ident.add_coeffs(v, [pmul(lam, b) for b in basis_polys])
            basis = _gram_basis(n, 0, deg)
            Q = cp.Variable((len(basis),) * 2, PSD=True)
            ident.add_gram(Q, basis, s=-1.0)
            cons += [Q >> 0, ident.constraint()]
        # gamma - V(v) - s (t - y'Wy) = z'Qz with the ball t of step A and s SOS: the ball lies in {V <= gamma}
        t = a["r2"]
        sb = monomials(n, 0, max(self.d - 2, 0) // 2)
        S = cp.Variable((len(sb),) * 2, PSD=True)
        ident = _Identity(n)
        ident.add_coeffs(cp.reshape(gamma, (1,), order="F"), [one])
        ident.add_coeffs(v, basis_polys, -1.0)
        ident.add_gram(S, sb, padd(pconst(t, n), self.ball, -1.0), s=-1.0)
        basis = _gram_basis(n, 0, max(self.d, 2 * (max(self.d - 2, 0) // 2) + 2))
        Q = cp.Variable((len(basis),) * 2, PSD=True)
        ident.add_gram(Q, basis, s=-1.0)
        cons += [S >> 0, Q >> 0, ident.constraint()]
        prob = cp.Problem(cp.Minimize(gamma), cons)
        st = _solve(prob, self.solver, self.solver_opts)
        if st not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or v.value is None:
            return None
        top = float(np.abs(v.value).max())
        return {m: float(c) for m, c in zip(self.mv, v.value) if abs(c) > 1e-9 * top}

    def run(self, V0: Poly, cap: float) -> tuple[dict | None, list[dict]]:
        """Alternate up to `iterations` times; the best checked step-A result and the history."""
        iters = int(self.o.get("iterations", 10))
        tol = float(self.o.get("improve_tol", 1e-3))
        best, history, V, guess = None, [], V0, None
        for k in range(iters + 1):
            t0 = time.perf_counter()
            scale = max(abs(c) for c in V.values())
            a = self.step_a(V, guess if guess else scale, cap if k == 0 else 1e3)
            if a is None:
                history.append({"iteration": k, "accepted": False, "time_s": time.perf_counter() - t0})
                break
            ok, pos = self.positive(a["V"])
            a["positive"] = pos
            parts = a["parts"] + [a["ball"]]
            history.append({"iteration": k, "accepted": ok, "rho": a["rho"], "ball_radius": math.sqrt(a["r2"]),
                            "sos_solves": sum(p.get("solves", 0) for p in parts),
                            "sos_solve_s": sum(p.get("solve_time_s", 0.0) for p in parts),
                            "time_s": time.perf_counter() - t0})
            if not ok:
                break
            improved = best is None or a["r2"] > best["r2"] * (1 + tol)
            if best is None or a["r2"] > best["r2"]:
                best = a
            if not improved or k == iters:
                break
            Vb = self.step_b(a)
            if Vb is None:
                break
            V, guess = Vb, 1.0
        return best, history


def estimate(problem, o: dict, fpoly: list[Poly], hpoly: list[Poly], P: np.ndarray, A: np.ndarray, ev: dict,
             method: str, certified) -> RoAResult:
    """RoA of a polynomial closed loop from a degree-`degree` V, starting at the quadratic y'Py."""
    d = o.get("degree", 4)
    if isinstance(d, bool) or not isinstance(d, int) or d < 2 or d % 2:
        return RoAResult(0.0, "failed", method, ev, f"degree must be an even integer >= 2, got {d!r}")
    t0 = time.perf_counter()
    cap = float(o.get("rho_max", 1e4 * float(np.linalg.eigvalsh(P).max())))
    search = PolyLyapunov(fpoly, hpoly, problem.W, A, o, certified)
    best, history = search.run(quadratic(P), cap)
    ev.update(degree=d, iterations=history, time_s=time.perf_counter() - t0)
    if best is None:
        return RoAResult(0.0, "failed", method, ev, f"no validated degree-{d} level set")
    r = math.sqrt(best["r2"])
    ev.update(rho=best["rho"], V={"monomials": [list(m) for m in best["V"]], "coefficients": list(best["V"].values())},
              parts=best["parts"], ball={"radius": r, **best["ball"]},
              positivity=best["positive"])
    return RoAResult(r, "certified", method, ev,
                     f"{{V <= {best['rho']:.6g}}} with V of degree {d} certified by SOS; the W-ball inside it too")
