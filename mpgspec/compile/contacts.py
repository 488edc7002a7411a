"""The contact plan of a primitive: which feet its dynamics hold, and when.

One concept in three forms (ContactPlan):
- Fixed: one set of feet throughout (the primitive's `contacts`, all contact frames by default);
- Schedule: the clock sets the contact set, phase by phase (a spec's contact_schedule or the
  timing of a trot), wrapped into the period;
- Events: the flags of the state decide (contact events, compile/events.py), starting from the
  primitive's set.
Every consumer (the compiled loop, the control laws through ControlContext.plan, the safe-set
blocks, the oracle's step end, the robust plant, the simulator replay, the assumption checks) asks
the plan instead of reading lists out of an untyped dict. The clock wrap (wrap_clock, clock_phase,
grid_clock) and the rule for a clock sitting on a switching time (SNAP) are written here once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

SNAP = 1e-9
"""Clock times within SNAP before a switching time count as at it: a step that ends on a switch
(up to rounding) runs the jump into the new mode, and the next step starts in it."""
JUST_BEFORE = 1e-7
"""How far before a step's end the jump reads the mode the step ran in (steps are >= 1e-6 s)."""


def wrap_clock(t, period: float | None):
    """The clock t wrapped into one period [0, T) (CasADi expressions, numbers and numpy arrays);
    t without a period."""
    if period is None:
        return t
    floor = np.floor if isinstance(t, np.ndarray) else ca.floor
    return t - period * floor(t / period)


def clock_phase(t: float, period: float | None) -> float:
    """A clock time taken within one period [0, T) exactly (the float remainder, numbers only; a
    switching time and a window's edges are read this way); t without a period."""
    return t % period if period else t


def grid_clock(t: float, period: float | None) -> float:
    """A clock wrapped into one period to look it up on a switch grid: a clock within 1e-9 periods
    below T counts as 0 (numbers only)."""
    return t - period * np.floor(t / period + 1e-9) if period else t


def scheduled_mode(schedule, feet, t, period: float | None, before: bool = False) -> dict:
    """foot -> 1 while the schedule holds it at clock t (the primitive's raw clock), else 0; after
    the last phase, the last phase. With `before`, the mode just before t."""
    tc = wrap_clock(t - JUST_BEFORE if before else t + SNAP, period)
    mode = {}
    for f in feet:
        val = ca.SX(1.0 if f in schedule[-1][1] else 0.0)
        for until, held in reversed(schedule[:-1]):
            val = ca.if_else(tc < until, 1.0 if f in held else 0.0, val)
        mode[f] = val
    return mode


@dataclass(frozen=True)
class _HeldSet:
    """A contact set not set by the clock: `feet` at switch-in."""

    feet: tuple[str, ...]

    boundaries = ()  # no clock time switches the contact set
    by_clock = False  # the clock does not set the contact set

    def mode(self, frames, t=None) -> dict:
        """foot -> 1 (held) or 0, constant."""
        return {f: ca.SX(1.0 if f in self.feet else 0.0) for f in frames}

    def jump(self, sys, t: ca.SX) -> ca.Function:
        """(x, u, t, s) -> x: the system's own discrete update (back onto the state manifold, events)."""
        return _project(sys, t)

    def record(self) -> dict:
        return {"contacts": list(self.feet)}


@dataclass(frozen=True)
class Fixed(_HeldSet):
    """The dynamics hold `feet` throughout."""

    varies = False  # the contact set never changes during the primitive

    def held(self, t: float) -> tuple[str, ...]:
        return self.feet


@dataclass(frozen=True)
class Events(_HeldSet):
    """Contact events decide: the contact flags in the state, from `feet` at switch-in."""

    varies = True

    def held(self, t: float) -> None:
        """None: the state's flags say which feet are held, not the clock."""
        return None


@dataclass(frozen=True)
class Schedule:
    """The clock sets the contact set: phase k holds phases[k][1] until the clock reaches
    phases[k][0] (wrapped into `period`); after the last phase, the last phase. `feet` names the
    scheduled loop's own set (every contact frame: the mode says which are held)."""

    phases: tuple[tuple[float, tuple[str, ...]], ...]
    period: float | None
    feet: tuple[str, ...] = ()
    _modes: list = field(default_factory=list, init=False, repr=False, compare=False)

    varies = True
    by_clock = True  # the clock sets the contact set

    def __getstate__(self) -> dict:  # the modes built for clock symbols stay in this process
        return {k: v for k, v in self.__dict__.items() if k != "_modes"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, _modes=[])

    @property
    def boundaries(self) -> tuple[float, ...]:
        """Clock times at which the contact set switches."""
        return tuple(float(until) for until, _ in self.phases)

    @property
    def touchdowns(self) -> list[float]:
        """Clock times within the period at which the next phase adds a foot to the held set."""
        return self._changes(adds=True)

    @property
    def liftoffs(self) -> list[float]:
        """Clock times within the period at which the next phase releases a held foot."""
        return self._changes(adds=False)

    def _changes(self, adds: bool) -> list[float]:
        """Clock times within the period at which the next phase adds (or releases) a foot."""
        out = []
        for k, (until, feet) in enumerate(self.phases):
            now, nxt = set(feet), set(self.phases[(k + 1) % len(self.phases)][1])
            if (nxt - now) if adds else (now - nxt):
                out.append(float(until) % float(self.period) if self.period else float(until))
        return sorted(out)

    def held(self, t: float) -> tuple[str, ...]:
        """The feet held at clock t, read as `mode` reads it (a clock within SNAP of a switch is at it)."""
        tc = clock_phase(t + SNAP, float(self.period) if self.period is not None else float("inf"))
        for until, feet in self.phases:
            if tc < until:
                return tuple(feet)
        return tuple(self.phases[-1][1])

    def mode(self, frames, t, before: bool = False) -> dict:
        """foot -> 1 while held at clock t (an expression of t), else 0; `before`: just before t.

        Built once per clock symbol, so the loop, the law and the safe set of a primitive share
        the same expressions (and the compiled functions stay the same whoever asks first)."""
        frames = tuple(frames)
        for tm, fm, bm, mode in self._modes:
            if tm is t and fm == frames and bm == before:
                return mode
        mode = scheduled_mode(self.phases, frames, t, self.period, before)
        self._modes.append((t, frames, before, mode))
        return mode

    def jump(self, sys, t: ca.SX) -> ca.Function:
        """(x, u, t, s) -> x: feet that join the mode at the step's end are put on the ground by their
        legs and touch down with a plastic impact; contact flags in the state follow the schedule."""
        from .rigidbody.hybrid import masked_impact, touchdown_projection

        u = ca.SX.sym("u", sys.nu)
        x = sys.x
        s = ca.SX.sym("s")
        feet = sys.model.contact_frames
        mode = self.mode(feet, t)
        c = ca.vertcat(*[mode[f] for f in feet])
        nq, nv = sys.model.nq, sys.model.nv
        before = self.mode(feet, t, before=True)  # the mode the step ran in
        joins = [ca.logic_and(mode[f] > 0.5, before[f] < 0.5) for f in feet]
        q, v = sys.project(x)[:nq], x[nq:nq + nv]
        q_new = touchdown_projection(sys, q, joins)
        v_new = ca.if_else(sum(joins) > 0, masked_impact(sys, q_new, v, c), v)
        # with contact flags in the state, they follow the schedule; event clocks are left as they are
        tail = ca.vertcat(c, x[nq + nv + len(feet):]) if sys.events else x[nq + nv:]
        return ca.Function("jump", [x, u, t, s], [ca.vertcat(q_new, v_new, tail)])

    def with_flags(self, setpoint: ca.Function, sys) -> ca.Function:
        """x*(t) with its contact flags set to the mode held at t, whatever the table says."""
        feet = sys.model.contact_frames
        ts = ca.SX.sym("t")
        mode = self.mode(feet, ts)
        flags = ca.Function("flags", [ts], [ca.vertcat(*[mode[f] for f in feet])])
        t = ca.MX.sym("t")
        x = setpoint(t)
        i = sys.model.nq + sys.model.nv
        return ca.Function(setpoint.name(), [t], [ca.vertcat(x[:i], flags(t), x[i + len(feet):])])

    def record(self) -> dict:
        return {"contact_schedule": [[float(u), list(f)] for u, f in self.phases], "contacts": list(self.feet)}


ContactPlan = Fixed | Events | Schedule
"""Which feet a primitive's dynamics hold: throughout, as contact events decide, or by the clock."""


def held_feet(plan: ContactPlan | None):
    """clock -> the feet held, where the clock decides them (a contact schedule); else None."""
    return plan.held if isinstance(plan, Schedule) else None


def plan_jump(plan: ContactPlan | None, sys, t: ca.SX) -> ca.Function:
    """(x, u, t, s) -> x after each step, given the step's input and the clock t and time since
    switch-in s after it (s dates contact events); `plan` None for a system without contacts."""
    return _project(sys, t) if plan is None else plan.jump(sys, t)


def _project(sys, t: ca.SX) -> ca.Function:
    u = ca.SX.sym("u", sys.nu)
    x = sys.x
    s = ca.SX.sym("s")
    return ca.Function("jump", [x, u, t, s], [sys.project(x, u, s)])
