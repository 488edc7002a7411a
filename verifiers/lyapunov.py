"""Quadratic Lyapunov level set as the explicit safe region of attraction of a fixed primitive.

V(y) = y'Py with y = x - x* and P from A'P + PA = -Q at the linearisation. The level rho is the
largest with Vdot < 0 on {0 < V <= rho} for the nonlinear closed loop and {V <= rho} inside C;
then {V <= rho} is invariant, safe and attracted to x*, and E is the largest W-ball inside it.

Each part is certified by a checked SOS certificate (sos_certificates.py) when its polynomial is exact (the
closed loop, or h_i, read as a polynomial from CasADi); otherwise it is estimated by dense
sampling plus local optimisation and labelled 'empirical'. The result's level is the weakest.
With `require_certified` (set when the spec says `require: certified`) the sampled parts are then
proved at the sampled level or a fraction of it by interval branch-and-bound over boxes in ball
arithmetic (lyapunov_bnb.py), and the result fails unless every part is certified.
With `degree` > 2 (polynomial loops and h only) V is a polynomial of that degree found by V-rho
alternation from y'Py (polyv.py).
"""
from __future__ import annotations

import time

import casadi as ca
import cvxpy as cp
import numpy as np
from scipy.optimize import minimize

from mpgspec.certify.problem import RoAProblem, RoAResult, weakest

from . import lyapunov_bnb, polyv
from .roa_common import ball_radius, batch, bisect, linearise, lyapunov_P, unit_sphere
from .sos_certificates import LevelSetProgram, NotPolynomial, Poly, from_casadi, padd, pmul, quadratic


class LyapunovVerifier:
    name = "lyapunov"
    description = "quadratic Lyapunov level set from the linearisation: SOS-certified for polynomial closed " \
                  "loops and safety functions, sampled and locally optimised otherwise"

    @staticmethod
    def is_installed() -> bool:
        return "CLARABEL" in cp.installed_solvers() or "SCS" in cp.installed_solvers()

    def estimate(self, problem: RoAProblem, options: dict | None = None) -> RoAResult:
        o = dict(options or {})
        method = o.get("method_name", self.name)
        n, xs = problem.nx, np.asarray(problem.x_star, float).ravel()
        lin = _linear_lyapunov(problem, xs, o, method)
        if isinstance(lin, RoAResult):
            return lin
        A, P, Qdec, ev = lin
        y = ca.SX.sym("y", n)
        fy = problem.f(ca.DM(xs) + y)
        vdot = 2 * ca.mtimes([y.T, ca.DM(P), fy])
        hy = problem.h(ca.DM(xs) + y) if problem.h is not None else ca.SX(0, 1)
        h0 = np.array(ca.Function("h0", [y], [hy])(np.zeros(n)), float).ravel()
        ev["h_at_x_star"] = h0
        if (h0 <= 0).any():
            return RoAResult(0.0, "failed", method, ev, "x_star is not strictly inside C: h(x*) = "
                             f"{h0.tolist()}")
        need_cert = bool(o.get("require_certified", False))
        fpoly = _polys(ca.Function("fy", [y], [fy]), o.get("polynomial"))
        hpoly = [_polys(ca.Function("hy", [y], [hy[i]]), None) for i in range(hy.numel())]
        boxes = None
        if need_cert and (isinstance(fpoly, str) or any(isinstance(p, str) for p in hpoly)):
            why = fpoly if isinstance(fpoly, str) else next(p for p in hpoly if isinstance(p, str))
            boxes = lyapunov_bnb.tapes(problem.f, problem.h) if o.get("branch_and_bound", True) else why
            if isinstance(boxes, str):
                return RoAResult(0.0, "failed", method, ev, f"no certificate possible: {boxes}")
        if o.get("polynomial") and isinstance(fpoly, str):
            return RoAResult(0.0, "failed", method, ev, f"closed loop declared polynomial but {fpoly}")
        degree = o.get("degree", 2)
        if degree != 2 or isinstance(degree, bool):
            why = fpoly if isinstance(fpoly, str) else next((p for p in hpoly if isinstance(p, str)), None)
            if why is not None:
                return RoAResult(0.0, "failed", method, ev, f"degree {degree} needs polynomial loop and h: {why}")
            return polyv.estimate(problem, {k: v for k, v in o.items() if k != "rho"}, fpoly, [hp[0] for hp in hpoly],
                                  P, A, ev, method, _certified)
        Vp = quadratic(P)
        scale = float(np.linalg.eigvalsh(P).max())
        cap = float(o.get("rho_max", 1e4 * scale))
        rng = np.random.default_rng(o.get("seed", 0))
        fixed = o.get("rho")
        parts, levels, t0 = [], [], time.perf_counter()
        rho_safe = float("inf")
        for i, hp in enumerate(hpoly):
            if isinstance(hp, str):
                g = ca.Function("g", [y], [-hy[i]])
                r, info = _empirical(g, P, rho_safe, cap, rng, o)
                lev = "empirical"
            else:
                r, lev, info = _certified(hp[0], Vp, n, rho_safe, scale, cap, o)
            parts.append({"part": f"h[{i}]", "level": lev, "rho": r, **info})
            levels.append(lev)
            rho_safe = min(rho_safe, r)
            if rho_safe <= 0:
                return RoAResult(0.0, "failed", method, ev | {"parts": parts},
                                 f"no validated level set inside C: h[{i}]: {info.get('reason', 'rho = 0')}")
        if isinstance(fpoly, str):
            g = ca.Function("g", [y], [vdot / ca.mtimes([y.T, ca.DM(P), y])])
            rho_dyn, info = _empirical(g, P, rho_safe, cap, rng, o)
            lev = "empirical"
        else:
            eps = float(o.get("eps", 1e-4)) * float(np.linalg.eigvalsh(Qdec).min())
            p = padd(_vdot_poly(fpoly, P, n, -1.0), quadratic(eps * np.eye(n)), -1.0)
            rho_dyn, lev, info = _certified(p, Vp, n, rho_safe, scale, cap, o)
            info["eps"] = eps
        parts.append({"part": "Vdot", "level": lev, "rho": rho_dyn, **info})
        levels.append(lev)
        rho = min(rho_dyn, rho_safe)
        if fixed is not None:  # sampled parts do not veto a level the branch-and-bound will decide
            rho = float(fixed) if all(pt["rho"] >= float(fixed) for pt in parts
                                      if boxes is None or pt["level"] != "empirical") else 0.0
        proof = None
        if boxes is not None and rho > 0 and "failed" not in levels:
            proof, rho, levels, ev["branch_and_bound"] = _branch_and_bound(boxes, xs, P, rho, fixed, parts, o)
        ev.update(rho=rho, parts=parts, rho_capped=bool(rho >= cap), time_s=time.perf_counter() - t0)
        level = weakest(*levels)
        if rho <= 0 or level == "failed" or (need_cert and level != "certified"):
            why = "; ".join(f"{pt['part']}: {pt.get('reason', 'rho = 0')}" for pt in parts
                            if pt["level"] != "certified" or pt["rho"] <= 0)
            return RoAResult(0.0, "failed", method, ev, f"no validated level set: {why}")
        if proof is not None:
            r = lyapunov_bnb.inscribed_radius(P, rho, problem.W)
            return RoAResult(r, "certified", method, ev, _bnb_message(proof, parts, r))
        r = ball_radius(P, rho, problem.W)
        msg = f"{{V <= {rho:.6g}}} " + ("certified by SOS" if level == "certified" else
                                         "estimated by sampling for " +
                                         ", ".join(pt["part"] for pt in parts if pt["level"] == "empirical"))
        return RoAResult(r, level, method, ev, msg)


def _branch_and_bound(tapes, xs: np.ndarray, P: np.ndarray, rho: float, fixed,
                      parts: list[dict], o: dict):
    """(proof or None, rho, levels, attempts) after proving the sampled parts by interval
    branch-and-bound at rho (or `fixed`) or the first fraction of it that holds; the parts are
    relabelled in place."""
    sampled = [pt for pt in parts if pt["level"] == "empirical"]
    names = {pt["part"] for pt in sampled}
    h_rows = sorted(int(nm[2:-1]) for nm in names if nm.startswith("h["))
    prover = lyapunov_bnb.LevelProver(*tapes, xs, P, prove_vdot="Vdot" in names, h_rows=h_rows)
    proof, attempts = lyapunov_bnb.certify_level(prover, rho, fixed, int(o.get("boxes", 50_000)))
    for pt in sampled:
        if proof.ok:
            pt.update(level="certified", rho=proof.rho, estimated_rho=pt["rho"], certified_by="branch_and_bound")
        else:
            pt["reason"] = f"interval branch-and-bound failed: {proof.reason}"
    levels = [pt["level"] for pt in parts]
    return (proof, proof.rho, levels, attempts) if proof.ok else (None, rho, levels, attempts)


def _bnb_message(proof, parts: list[dict], r: float) -> str:
    what = " and ".join(w for w, on in (("Vdot < 0", "Vdot" in proof.parts), ("h > 0", "h" in proof.parts)) if on)
    sos = [pt["part"] for pt in parts if pt["level"] == "certified" and "certified_by" not in pt]
    near = ""
    if "Vdot" in proof.parts:
        near = f"; around x* by the interval Jacobian (P J + J'P < 0 on {proof.inner} boxes" + (
            f", outside ||x - x*||_2 <= {proof.eps:.2g}, the rounding of f(x*) = 0)" if proof.eps > 0 else ")")
    return (f"{{V <= {proof.rho:.6g}}} certified: {what} on it proved by interval branch-and-bound over "
            f"{proof.boxes} boxes{near}" + (f"; {', '.join(sos)} by SOS" if sos else "")
            + f"; the W-ball r = {r:.6g} lies inside it (checked in ball arithmetic)")


def _linear_lyapunov(problem: RoAProblem, xs: np.ndarray, o: dict, method: str):
    """(A, P, -(A'P + PA), evidence) of the linearisation at x*, or the failed RoAResult when x* is
    no equilibrium, A is not Hurwitz or P is not a Lyapunov matrix of it."""
    A, f0 = linearise(problem.f, xs)
    if not (np.isfinite(A).all() and np.isfinite(f0).all()):
        return RoAResult(0.0, "failed", method, {"equilibrium_defect": None},
                         "the closed loop or its Jacobian is not finite at x_star (inf or NaN)")
    ev: dict = {"A_eigenvalues": [[z.real, z.imag] for z in np.linalg.eigvals(A)],
                "equilibrium_defect": float(np.abs(f0).max(initial=0.0))}
    if ev["equilibrium_defect"] > o.get("equilibrium_tol", 1e-8):
        return RoAResult(0.0, "failed", method, ev, f"x_star is not an equilibrium: |f(x*)| = "
                         f"{ev['equilibrium_defect']:.3g}")
    if np.linalg.eigvals(A).real.max() >= 0:
        return RoAResult(0.0, "failed", method, ev, "linearisation is not Hurwitz: eigenvalues "
                         f"{np.round(np.linalg.eigvals(A), 6).tolist()}")
    P = np.asarray(o["P"], float) if "P" in o else lyapunov_P(A, o.get("Q"))
    Qdec = -(A.T @ P + P @ A)
    ev["P"] = P
    if np.linalg.eigvalsh(P).min() <= 0 or np.linalg.eigvalsh(Qdec).min() <= 0:
        return RoAResult(0.0, "failed", method, ev, "P is not a Lyapunov matrix of the linearisation "
                         "(needs P > 0 and A'P + PA < 0)")
    return A, P, Qdec, ev


def _polys(fn: ca.Function, declared: bool | None) -> list[Poly] | str:
    """Polynomials of fn's outputs, or the reason they are not polynomial."""
    if declared is False:
        return "closed loop declared non-polynomial"
    try:
        return from_casadi(fn)
    except NotPolynomial as e:
        return f"not polynomial ({e})"


def _vdot_poly(f: list[Poly], P: np.ndarray, n: int, sign: float) -> Poly:
    """sign * 2 y'P f(y), dropping f's constant terms (x* is an equilibrium to tolerance)."""
    out: Poly = {}
    zero = (0,) * n
    for i in range(n):
        for j in range(n):
            if P[i, j]:
                yi = {tuple(int(m == i) for m in range(n)): sign * 2 * P[i, j]}
                out = padd(out, pmul(yi, {k: v for k, v in f[j].items() if k != zero}))
    return out


def _certified(p: Poly, V: Poly, n: int, hi: float, guess: float, cap: float, o: dict):
    """Largest rho <= min(hi, cap) with a validated certificate of p >= 0 on {V <= rho}."""
    prog = LevelSetProgram(p, V, n, o.get("mult_half_degree"), o.get("solver", "CLARABEL"),
                               o.get("solver_opts"), o.get("tol_eig", 1e-8), o.get("tol_res", 1e-6),
                               interior=bool(o.get("interior", False)))
    last = {"ok": None, "bad": None}
    solve_s = 0.0

    def ok(rho: float) -> bool:
        nonlocal solve_s
        c = prog.solve(rho)
        if c.ok is False and c.status == "error" and prog.solver != "SCS" and "solver" not in o:
            prog.solver, prog.solver_opts = "SCS", {}
            c = prog.solve(rho)
        solve_s += c.solve_time
        last["ok" if c.ok else "bad"] = c
        return c.ok

    if o.get("rho") is not None:
        rho, calls = (float(o["rho"]) if ok(float(o["rho"])) else 0.0), 1
    elif hi >= cap:
        rho, _, calls = bisect(ok, 0.0, guess, cap, o.get("rtol", 1e-3))
    else:
        rho, _, calls = bisect(ok, 0.0, hi, hi, o.get("rtol", 1e-3))
    info = {"solves": calls, "solve_time_s": solve_s, "solver": prog.solver,
            "gram_sizes": [len(prog.B0), len(prog.B1)]}
    if last["ok"] is not None:
        info["certificate"] = last["ok"].summary()
        info["certificate"].update(Q0=last["ok"].grams["Q0"], Q1=last["ok"].grams["Q1"],
                                   B0=[list(m) for m in prog.B0], B1=[list(m) for m in prog.B1])
    if last["bad"] is not None:
        info["last_rejected"] = last["bad"].summary()
    if rho <= 0:
        info["reason"] = last["bad"].reason if last["bad"] is not None else "no feasible level"
        return 0.0, "failed", info
    return rho, "certified", info


def _empirical(g: ca.Function, P: np.ndarray, hi: float, cap: float, rng: np.random.Generator, o: dict):
    """Smallest V among sampled and locally optimised points with g >= 0, at most min(hi, cap), times a margin.

    Samples lie on rays through x* in V-coordinates (y = s L^-T u, V = s^2), linearly spaced up
    to a finite bound hi or log-spaced up to cap; the first bad sample of each ray is refined by
    bisection, then SLSQP minimises V over {g >= 0} from the lowest crossings.
    """
    n = len(P)
    L = np.linalg.cholesky(P)
    Li = np.linalg.inv(L).T
    total = int(o.get("samples", 20000))
    n_rad = int(o.get("radial", 40))
    n_dir = max(total // n_rad, 2 * n)
    top = min(hi, cap)
    frac = np.arange(1, n_rad + 1) / n_rad if hi < cap else np.logspace(-3, 0, n_rad)
    s = np.sqrt(top) * frac
    U = unit_sphere(n_dir, n, rng) @ Li.T  # rows with V = 1
    Y = (s[None, :, None] * U[:, None, :]).reshape(-1, n)
    gv = batch(g, len(Y))(Y.T).reshape(n_dir, n_rad)
    bad = ~(gv < 0)
    hit = np.flatnonzero(bad.any(axis=1))
    levels = np.full(n_dir, np.inf)
    if hit.size:  # refine the first crossing on each violating ray by bisection
        j = bad[hit].argmax(axis=1)
        lo, up = np.where(j > 0, s[np.maximum(j - 1, 0)], 0.0), s[j]
        gb = batch(g, hit.size)
        for _ in range(30):
            mid = 0.5 * (lo + up)
            b = ~(gb((mid[:, None] * U[hit]).T).ravel() < 0)
            up, lo = np.where(b, mid, up), np.where(b, lo, mid)
        levels[hit] = up ** 2
    best = float(levels.min())
    y = ca.SX.sym("y", n)
    gy = g(y)
    G = ca.Function("G", [y], [gy, ca.jacobian(gy, y)])
    starts = np.argsort(levels if hit.size else -gv[:, -1])[: int(o.get("local_starts", 8))]
    tol = float(o.get("boundary_tol", 1e-9))
    opt_calls = 0
    for k in starts:
        x0 = np.sqrt(levels[k]) * U[k] if np.isfinite(levels[k]) else s[-1] * U[k]
        res = minimize(lambda v: v @ P @ v, x0, jac=lambda v: 2 * P @ v, method="SLSQP",
                       constraints=[{"type": "ineq", "fun": lambda v: float(G(v)[0]),
                                     "jac": lambda v: np.array(G(v)[1], float).ravel()}],
                       options={"maxiter": 200, "ftol": 1e-12})
        opt_calls += 1
        v = res.x
        if np.isfinite(v).all() and float(G(v)[0]) >= -tol and v @ P @ v > 1e-12 * top:
            best = min(best, float(v @ P @ v))
    margin = float(o.get("empirical_margin", 0.99))
    rho = min(top, margin * best)
    return rho, {"samples": int(Y.shape[0]), "directions": n_dir, "local_optimisations": opt_calls,
                 "first_violation_level": best if np.isfinite(best) else None, "margin": margin}


verifier = LyapunovVerifier()
