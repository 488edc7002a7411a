"""Contact events as part of the state, and safe-set windows anchored on them (Section IV).

The paper's transient safe sets switch at event times, not clock times: Land's C(t) is C_aerial
until the first touchdown T_c, C_{q,qdot} on [T_c, T_c + eps) and C_ground after; Jump's switches
at the takeoff T_t. A system with contact events carries, for every ContactEvent E, an event clock
tau_E in its state: the time since E first happened after switch-in. It advances at rate 1 (at rest
at NEVER), and the jump at a step's end sets it to 0 when E happens and had not happened since
switch-in. A clock carried over from before the switch (or NEVER) is never below s, the time since
switch-in, so

    E happened since switch-in  <=>  tau_E < s,   at T_E = s - tau_E,

and nothing has to be reset when a primitive is switched in.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from ..spec.models import ContactEvent

NEVER = 1e6
"""Event clock of an event that has not happened: far beyond any horizon, and at rest there."""
CARRIED = 1e-9
"""A clock carried over from before switch-in equals s up to rounding (both advance by the same
steps); a recorded event is at least one step (>= 1e-6 s) old, so this separates the two."""


def clock_name(event: ContactEvent | str) -> str:
    """State name of the event clock of `event`: since_first_touchdown, since_takeoff."""
    return f"since_{ContactEvent(event).value}"


def happened(tau, s):
    """Whether the event of clock tau happened since switch-in, s ago."""
    return tau < s - CARRIED


def clock_rate(tau):
    """d tau / dt: 1, or 0 at rest at NEVER (so a setpoint holding NEVER is an equilibrium)."""
    return ca.if_else(tau < NEVER, 1, 0)


def record(tau, now, s):
    """The event clock after a step's jump, at time s since switch-in: 0 when the event happens now
    (`now` true) for the first time since switch-in, else unchanged."""
    return ca.if_else(ca.logic_and(now, ca.logic_not(happened(tau, s))), 0, tau)


@dataclass(frozen=True)
class EventWindow:
    """A safe-set window anchored on a contact event E, compiled: [0, T_E) when `before`, else
    [T_E + start, T_E + end); `clock` is the index of tau_E in the state."""

    event: str
    clock: int
    before: bool = False
    start: float = 0.0
    end: float = math.inf

    def active(self, tau, s):
        """1 where the window holds, given the event clock tau and the time s since switch-in."""
        seen = happened(tau, s)
        if self.before:
            return ca.logic_not(seen)
        on = ca.logic_and(seen, tau >= self.start)
        return ca.logic_and(on, tau < self.end) if math.isfinite(self.end) else on

    def over_step(self, tau0, s0, tau1, h):
        """1 where the window holds over a whole step of h from the event clock tau0 at time s0
        since switch-in to tau1 after the step's jump. The step in which the event happens lies
        neither before nor after it (the event is known to one step): a `before` window holds while
        the event has not happened by the step's end, an `after` one is judged at the middle of a
        step that starts after the event."""
        if self.before:
            return self.active(tau1, s0 + h)
        return self.active(tau0 + h / 2, s0 + h / 2)

    @property
    def edges(self) -> tuple[float, ...]:
        """Times after T_E at which the window opens or closes (T_E itself is a step end already)."""
        return tuple(e for e in (self.start, self.end) if 0 < e < math.inf)

    def gap(self, tau, s):
        """Time from now to the window's next edge (inf when E has not happened or none is ahead)."""
        out = ca.inf
        for e in self.edges:
            out = ca.fmin(out, ca.if_else(ca.logic_and(happened(tau, s), tau < e - CARRIED), e - tau, ca.inf))
        return out


def event_window(when, state_names: list[str]) -> EventWindow:
    """The compiled form of a spec window anchored on a contact event (spec.models.EventWindow)."""
    event = ContactEvent(when.before if when.before is not None else when.after)
    start = float(when.delay)
    end = start + float(when.for_) if when.for_ is not None else math.inf
    return EventWindow(event.value, state_names.index(clock_name(event)), before=when.before is not None,
                       start=start, end=end)
