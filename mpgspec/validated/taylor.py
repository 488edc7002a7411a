"""Taylor coefficients of the closed loop's solution, enclosed over balls of start states.

The solution x(t_j + tau) of xdot = f(x, t, s, x_sw) is expanded in tau by Picard iteration on
truncated power series: X <- x0 + integral f(X, t_j + tau, s_j + tau); after k rounds its first
k + 1 coefficients are exact (here: enclosed, in arb arithmetic). From a ball x0 the coefficients
enclose those of every start in it; from jets (jet.py) also their derivatives in the start state.
A non-smooth operation replays the branch decided over the whole step, so every expansion is one
of a smooth function (tape.py); None means the step crosses a switch or kink.
"""
from __future__ import annotations

from flint import arb, arb_series, ctx

from .jet import Jet
from .tape import UNDECIDED, Tape

ctx.cap = max(ctx.cap, 40)  # series lengths up to the largest order used (flint truncates at cap)


def constant(v, L: int):
    """v as a series of length L (a jet of series for a jet)."""
    if isinstance(v, Jet):
        return Jet(constant(v.v, L), [constant(d, L) for d in v.d])
    return arb_series([v], prec=L)


def clock(t0: arb, L: int):
    """t0 + tau as a series of length L."""
    return arb_series([t0, arb(1)], prec=L)


def integral(v):
    if isinstance(v, Jet):
        return Jet(v.v.integral(), [d.integral() for d in v.d])
    return v.integral()


def solution(tape: Tape, x0: list, t0: arb, s0: arb, x_sw: list, decisions: dict, length: int) -> list | None:
    """The first `length` Taylor coefficients of x(t0 + tau) from x0 (balls or jets of balls), as
    series (or jets of series); None when a needed branch is undecided over the step."""
    L = length
    start = [constant(v, L) for v in x0]
    X = list(start)
    t, s = clock(t0, L), clock(s0, L)
    for _ in range(L - 1):
        (F, *_), _ = tape([X, [t], [s], x_sw], decisions)
        if any(v is UNDECIDED for v in F):
            return None
        X = [a + integral(_lift(f, a, L)) for a, f in zip(start, F)]
    return X


def _lift(f, like, L: int):
    """f as a series (a constant rate is a ball), and as a jet when the state is one (a rate that
    does not depend on the state has no gradient)."""
    if isinstance(f, Jet):
        return Jet(_series(f.v, L), [_series(d, L) for d in f.d])
    if isinstance(like, Jet):
        return Jet(_series(f, L), [arb_series([0], prec=L) for _ in like.d])
    return _series(f, L)


def _series(v, L: int):
    return v if isinstance(v, arb_series) else arb_series([v], prec=L)


def coefficient(v, k: int):
    """The k-th coefficient of a series (0 past its stored length)."""
    c = v.coeffs()
    return c[k] if k < len(c) else arb(0)


def horner(v, tau: arb, upto: int):
    """sum_{k < upto} v_k tau^k for a series v, at the ball tau."""
    c = v.coeffs()[:upto]
    acc = arb(0)
    for a in reversed(c):
        acc = acc * tau + a
    return acc
