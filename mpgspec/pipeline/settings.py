"""The oracle settings of a project: its accuracy preset, overrides, and the checks that they can run
(a known backend, a bounded number of steps and oracle calls), located in the spec."""
from __future__ import annotations

import difflib

import numpy as np

from ..errors import SpecError, UsageError
from ..oracle.registry import GROUP, backends, get_backend
from ..plugins import unloaded
from ..settings import OracleSettings
from ..spec.loader import ProjectSpec


def settings_for(spec: ProjectSpec, overrides: dict | None = None) -> OracleSettings:
    """Oracle settings of a project: its accuracy preset, then explicit overrides."""
    o = spec.project.oracle
    s = OracleSettings.with_accuracy(o.accuracy, horizon=o.horizon, dt=o.dt, method=o.method,
                                     h_tolerance=o.h_tolerance, error=o.error)
    s = s.replace(**(overrides or {}))
    try:
        get_backend(s.method)  # an unknown method is a spec error, not evidence
    except UsageError:
        if "method" in (overrides or {}):  # named on the command line, not in the spec
            raise
        names = sorted(backends())
        near = difflib.get_close_matches(s.method, names, n=1)
        broken = unloaded(GROUP).get(s.method)
        hint = (f"the backend {s.method!r} is installed but could not be imported ({broken}); reinstall mpgspec"
                if broken else f"did you mean {near[0]!r}?" if near else "")
        raise SpecError("unknown oracle method", location=spec.locate(("oracle", "method")), key="oracle.method",
                        expected="one of " + ", ".join(names) if names else "an installed oracle backend",
                        found=repr(s.method), hint=hint, code="MPG104") from None
    _check_budget(spec, s)
    return s


MAX_STEPS = 1_000_000
"""Most RK4 steps one oracle rollout may take (horizon / dt at the finest preset)."""
MAX_GRID = 10_000
"""Most clock samples of one grid axis."""
MAX_CALLS = 1_000_000
"""Most oracle calls Algorithm 1 may make for one project (sum over ordered pairs of t_A x t_B)."""


def _check_budget(spec: ProjectSpec, s: OracleSettings) -> None:
    """Refuse, located, oracle settings that could not finish: too many steps or too many calls."""
    o = spec.project.oracle
    if not (np.isfinite(s.horizon) and np.isfinite(s.dt) and s.dt > 0):
        raise SpecError("the oracle's horizon and step must be finite", location=spec.locate(("oracle",)),
                        key="oracle.horizon / oracle.dt", expected="finite numbers, dt > 0",
                        found=f"horizon {s.horizon:g}, dt {s.dt:g}", code="MPG104")
    steps = s.horizon / s.dt
    if steps > MAX_STEPS:
        raise SpecError("horizon / dt needs too many steps", location=spec.locate(("oracle", "dt")), key="oracle.dt",
                        expected=f"at most {MAX_STEPS:,} steps per rollout (accuracy presets divide dt further)",
                        found=f"{steps:,.0f} steps ({s.horizon:g} s / {s.dt:g} s)", code="MPG104")
    for key in ("t_A", "t_B"):
        n = getattr(o.grid, key)
        if n > MAX_GRID:
            raise SpecError("grid too fine", location=spec.locate(("oracle", "grid", key)), key=f"oracle.grid.{key}",
                            expected=f"at most {MAX_GRID:,} clock samples", found=f"{n:,}", code="MPG104")
    sizes = []
    for inst in spec.primitives:
        g = inst.spec.grid
        n_a = (g.t_A if g else o.grid.t_A) if inst.spec.class_.value != "fixed" else 1
        n_b = (g.t_B if g else o.grid.t_B) if inst.spec.class_.value != "fixed" else 1
        sizes.append((n_a, n_b))
    calls = sum(a * b for i, (a, _) in enumerate(sizes) for j, (_, b) in enumerate(sizes) if i != j)
    if calls > MAX_CALLS:
        raise SpecError("the oracle grids need too many oracle calls", location=spec.locate(("oracle", "grid")),
                        key="oracle.grid", expected=f"at most {MAX_CALLS:,} calls (sum over pairs of t_A x t_B)",
                        found=f"{calls:,} calls", code="MPG104")
