"""LQR from the linearisation at a fixed setpoint (continuous algebraic Riccati equation)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from ...errors import SpecError
from ...spec.controllers import LQRController
from .base import ControlContext


def _matrix(v, n: int, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 1:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"{what} must be {n} numbers (diagonal) or a {n}x{n} matrix; got shape {a.shape}")
    return a


def _lqr_error(ctx: ControlContext, message: str, path: tuple = (), *, expected: str, found: str,
               hint: str = "") -> SpecError:
    where = ("controller",) + path
    return SpecError(message, location=ctx.ec.locate(where), key=f"{ctx.ec.owner}: " + ".".join(map(str, where)),
                     expected=expected, found=found, hint=hint, code="MPG111")


def _weights(ctx: ControlContext, value, n: int, name: str, definite: bool) -> np.ndarray:
    """Q (positive semidefinite) or R (positive definite) as a symmetric n x n matrix."""
    try:
        M = _matrix(value, n, name)
    except ValueError as err:
        raise SpecError(str(err), location=ctx.ec.locate(("controller", name)), key=f"{ctx.ec.owner}: controller.{name}",
                        expected=f"{n} numbers (diagonal) or a {n}x{n} matrix", found="another shape",
                        code="MPG106") from None
    if not np.allclose(M, M.T, rtol=1e-10, atol=1e-12):
        raise _lqr_error(ctx, f"LQR weight {name} must be symmetric", (name,), expected="a symmetric matrix",
                         found=f"{name} != {name}^T")
    low = float(np.linalg.eigvalsh(M).min()) if n else 1.0
    scale = max(float(np.abs(M).max()) if n else 1.0, 1e-300)
    if (definite and low <= 1e-12 * scale) or (not definite and low < -1e-12 * scale):
        kind = "positive definite" if definite else "positive semidefinite"
        raise _lqr_error(ctx, f"LQR weight {name} must be {kind}", (name,), expected=f"a {kind} matrix",
                         found=f"smallest eigenvalue {low:.3g}")
    return M


def lqr_law(c: LQRController, ctx: ControlContext) -> ca.SX:
    """Continuous-time LQR at the fixed setpoint; K, u*, and closed-loop eigenvalues go to info.

    An ill-posed problem (weights not symmetric / definite, non-finite dynamics at the setpoint,
    (A, B) not stabilisable, no stabilising Riccati solution) is a SpecError at the controller.
    """
    sys = ctx.sys
    if not ctx.fixed:
        raise SpecError("LQR needs a fixed setpoint", location=ctx.ec.locate(("controller", "type")),
                        key=f"{ctx.ec.owner}: controller.type", expected="class: fixed", found="a time-varying setpoint",
                        code="MPG108")
    if sys.nu == 0:
        raise _lqr_error(ctx, "LQR needs at least one input", ("type",), expected="a system with inputs",
                         found="no inputs")
    xs = np.array(ctx.x_star_fn(0.0)).ravel()
    Q = _weights(ctx, c.Q, sys.nx, "Q", definite=False)
    R = _weights(ctx, c.R, sys.nu, "R", definite=True)
    xdot = sys.xdot if ctx.xdot is None else ctx.xdot
    f = ca.Function("f", [sys.x, sys.u], [xdot])
    A_fn = ca.Function("A", [sys.x, sys.u], [ca.jacobian(xdot, sys.x), ca.jacobian(xdot, sys.u)])
    if not np.isfinite(xs).all():
        raise _lqr_error(ctx, "LQR setpoint is not finite", expected="a finite setpoint x*",
                         found=f"x* = {xs.tolist()}")
    us = _equilibrium_input(c, ctx, xs, f, A_fn)
    resid = float(np.linalg.norm(np.array(f(xs, us)).ravel()))
    A, B = (np.array(m, dtype=float) for m in A_fn(xs, us))
    if not (np.isfinite(A).all() and np.isfinite(B).all() and np.isfinite(resid)):
        raise _lqr_error(ctx, "LQR: the dynamics are not finite at the setpoint", expected="finite xdot and "
                         "Jacobians at (x*, u*)", found=f"x* = {np.round(xs, 6).tolist()}, u* = {np.round(us, 6).tolist()}",
                         hint="check parameters (e.g. a zero mass) and the setpoint")
    unstab = _unstabilisable_modes(A, B)
    if unstab:
        raise _lqr_error(ctx, "LQR: (A, B) is not stabilisable at the setpoint", ("type",),
                         expected="inputs that act on every unstable or marginal mode of the linearisation",
                         found=f"modes with eigenvalues {unstab} that no input moves (B = {np.round(B, 6).tolist()})",
                         hint="an input gain that is zero at the setpoint (e.g. a zero mass or length) makes B "
                              "vanish; use another controller or fix the parameters")
    try:
        with np.errstate(all="ignore"):
            import scipy.linalg  # imported when used: scipy's start-up is a process's slowest
            P = scipy.linalg.solve_continuous_are(A, B, Q, R)
            K = np.linalg.solve(R, B.T @ P)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise _lqr_error(ctx, "LQR: the Riccati equation has no stabilising solution", ("type",),
                         expected="a stabilising solution of the continuous algebraic Riccati equation",
                         found=str(err)[:200]) from None
    eig = np.linalg.eigvals(A - B @ K) if np.isfinite(K).all() else np.array([np.nan])
    if not (np.isfinite(P).all() and np.isfinite(eig).all() and eig.real.max(initial=-1.0) < 0):
        raise _lqr_error(ctx, "LQR: the Riccati solution does not stabilise the linearisation", ("type",),
                         expected="closed-loop eigenvalues with negative real parts",
                         found=f"eigenvalues {np.round(eig, 6).tolist()}",
                         hint="Q must weigh every unstable mode (detectability) and (A, B) be stabilisable")
    ctx.info["lqr"] = {
        "K": K.tolist(),
        "u_eq": us.tolist(),
        "equilibrium_residual": resid,
        "closed_loop_eigenvalues": [[float(z.real), float(z.imag)] for z in eig],
    }
    dx = sys.wrapped_error(sys.x - ctx.x_star)
    return ca.DM(us) - ca.mtimes(ca.DM(K), dx)


def _equilibrium_input(c: LQRController, ctx: ControlContext, xs: np.ndarray, f: ca.Function,
                       A_fn: ca.Function) -> np.ndarray:
    """u* with xdot(x*, u*) = 0: the spec's u_eq, else Gauss-Newton from u = 0 (at most 20 steps)."""
    sys = ctx.sys
    if c.u_eq is not None:
        if len(c.u_eq) != sys.nu:
            raise SpecError("u_eq needs one value per input", location=ctx.ec.locate(("controller", "u_eq")),
                            key=f"{ctx.ec.owner}: controller.u_eq", expected=f"{sys.nu} values",
                            found=f"{len(c.u_eq)}", code="MPG106")
        env = {k: float(v2) for k, v2 in ctx.env.items() if isinstance(v2, (int, float))}
        return np.array([ctx.ec.number(v, ("controller", "u_eq", i), env, finite=True) for i, v in enumerate(c.u_eq)])
    us = np.zeros(sys.nu)
    for _ in range(20):
        r = np.array(f(xs, us)).ravel()
        B = np.array(A_fn(xs, us)[1])
        if not (np.isfinite(r).all() and np.isfinite(B).all()):
            break
        step, *_ = np.linalg.lstsq(B, -r, rcond=None)
        if not np.isfinite(step).all():
            break
        us = us + step
        if np.linalg.norm(step) < 1e-12:
            break
    return us


def _unstabilisable_modes(A: np.ndarray, B: np.ndarray) -> list[str]:
    """Eigenvalues with Re >= 0 that fail the PBH test rank [A - lambda I, B] = n."""
    n = A.shape[0]
    out = []
    scale = max(float(np.abs(A).max(initial=0.0)), float(np.abs(B).max(initial=0.0)), 1.0)
    for lam in np.linalg.eigvals(A):
        if lam.real < -1e-9 * scale:
            continue
        M = np.hstack([A - lam * np.eye(n), B.astype(complex)])
        sv = np.linalg.svd(M, compute_uv=False)
        if sv.size < n or sv[n - 1] <= 1e-9 * scale:
            out.append(f"{lam.real:.4g}{lam.imag:+.4g}j" if abs(lam.imag) > 1e-12 else f"{lam.real:.4g}")
    return out
