"""Sample-and-hold of an optimisation-based control law, as a robot's controller runs it.

The law is solved at sample instants and its input held in between (a zero-order hold). The
oracle's step must divide the control period, so that every sample falls on a step's start: a
Runge-Kutta step cannot integrate across a jump of the input. Solves are warm-started from the
previous one: `solve` takes the previous solution w and returns the next.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from ..errors import Location, SpecError

RATE_TOLERANCE = 1e-6
"""Relative slack of `period / dt` from a whole number."""


@dataclass(frozen=True)
class SampledLaw:
    """A law k(x, t, s, x_sw) solved every `period` seconds (None: at every oracle step's start).

    solve (x, t, s, x_sw, w) -> (u_raw, w): one solve from the warm start w (nw numbers; zeros are
    a cold start). location and key name the spec entry that sets the rate.
    """

    period: float | None
    solve: ca.Function
    nw: int
    location: Location
    key: str

    def steps(self, dt: float) -> int:
        """Oracle steps of dt per control period; a period that is not a whole number of them is a
        spec error."""
        if self.period is None:
            return 1
        n = self.period / dt
        m = round(n)
        if m < 1 or abs(n - m) > RATE_TOLERANCE * max(1.0, n):
            raise SpecError("the control period must be a whole number of oracle steps", location=self.location,
                            key=self.key, expected=f"1/rate a multiple of the oracle step {dt:g} s "
                            f"(a rate of {1 / dt:g} Hz divided by a whole number)",
                            found=f"1/rate = {self.period:g} s ({n:.4g} steps)", code="MPG104",
                            hint="set the rate to 1/(k dt) for a whole k, or the oracle's dt to a divisor of 1/rate")
        return m

    def describe(self) -> str:
        return "once per oracle step" if self.period is None else f"{1 / self.period:g} Hz"


def warm_or_cold(w):
    """w where every entry is finite, else zeros (a failed solve restarts cold)."""
    ok = ca.sum1(ca.fabs(w) < ca.inf) == w.shape[0]  # false for NaN and inf
    return ca.if_else(ok, w, ca.DM.zeros(w.shape[0]))
