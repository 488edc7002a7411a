"""Compile a system spec to CasADi: state/input symbols and the open-loop dynamics xdot(x, u)."""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..errors import SpecError
from ..spec.loader import ProjectSpec
from .exprs import ExprCompiler


@dataclass
class OpenLoop:
    """xdot(x, u) of one dynamics mode, with the extra symbols it defines (e.g. contact forces)."""

    xdot: ca.SX
    env: dict
    contacts: tuple[str, ...] = ()


@dataclass
class CompiledSystem:
    """Open-loop dynamics (eq. 1) with named states, inputs and parameters.

    Later system kinds (rigid bodies with contact domains) provide the same attributes, so the
    primitive compiler and the oracle work on any of them.
    """

    name: str
    state_names: list[str]
    input_names: list[str]
    parameters: dict[str, float]
    x: ca.SX
    u: ca.SX
    xdot: ca.SX
    u_lo: np.ndarray
    u_hi: np.ndarray
    wrap: np.ndarray  # period per state, 0 = none
    extra_env: dict[str, ca.SX] = field(default_factory=dict)

    kind = "analytic"  # the registry key this system was compiled by (SYSTEM_KINDS)
    events = False  # the state jumps at contact events (rigid bodies with contact_events)

    @property
    def is_rigid_body(self) -> bool:
        return self.kind == "rigid_body"

    @property
    def nx(self) -> int:
        return len(self.state_names)

    @property
    def nu(self) -> int:
        return len(self.input_names)

    def env(self) -> dict[str, object]:
        """Symbols and constants an expression may name."""
        env: dict[str, object] = dict(self.parameters)
        env.update({n: self.x[i] for i, n in enumerate(self.state_names)})
        env.update(self.extra_env)
        return env

    def default_state(self, contacts: tuple[str, ...] | None = None) -> np.ndarray:
        """Value of states a setpoint leaves unnamed."""
        return np.zeros(self.nx)

    def open_loop(self, contacts: list[str] | None) -> OpenLoop:
        """The open-loop dynamics a primitive runs on; analytic systems have one mode."""
        return OpenLoop(self.xdot, dict(self.extra_env))

    def project(self, x: ca.SX, u: ca.SX | None = None) -> ca.SX:
        """The discrete part of a step: back onto the state manifold, events (identity here)."""
        return x

    def builtin_safe_set(self, name: str, contacts: tuple[str, ...]) -> list[tuple[str, ca.SX]]:
        raise KeyError(name)

    def wrapped_error(self, dx: ca.SX) -> ca.SX:
        """x - x* with wrapped states (angles) mapped into [-P/2, P/2)."""
        parts = []
        for i in range(self.nx):
            p = float(self.wrap[i])
            d = dx[i]
            parts.append(d - p * ca.floor((d + p / 2) / p) if p > 0 else d)
        return ca.vertcat(*parts)


def _rigid_body(spec: ProjectSpec) -> CompiledSystem:
    from .rigidbody.system import compile_rigid_body  # pinocchio is loaded only for robots

    return compile_rigid_body(spec)


def compile_system(spec: ProjectSpec) -> CompiledSystem:
    """Build the CasADi symbols and dynamics of the project's system, by its kind (SYSTEM_KINDS)."""
    return SYSTEM_KINDS[spec.system.kind](spec)


def compile_analytic(spec: ProjectSpec) -> CompiledSystem:
    """Build the CasADi symbols and dynamics of an analytic system."""
    s = spec.system
    ec = ExprCompiler(spec.system_locate, f"system '{s.name}'")
    names = list(s.states) + list(s.inputs) + list(s.parameters)
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise SpecError("names of states, inputs and parameters must be distinct", location=spec.system_locate(("states",)),
                        key="states", expected="unique names", found=", ".join(sorted(dup)), code="MPG105")
    x = ca.SX.sym("x", len(s.states))
    u = ca.SX.sym("u", len(s.inputs))
    env = dict(s.parameters)
    env.update({n: x[i] for i, n in enumerate(s.states)})
    if s.dynamics is not None:
        if len(s.dynamics.f) != len(s.states):
            raise SpecError("f needs one entry per state", location=spec.system_locate(("dynamics", "f")),
                            key="dynamics.f", expected=f"{len(s.states)} entries", found=f"{len(s.dynamics.f)}",
                            code="MPG106")
        if len(s.dynamics.g) != len(s.states) or any(len(r) != len(s.inputs) for r in s.dynamics.g):
            raise SpecError("g must be a states x inputs matrix", location=spec.system_locate(("dynamics", "g")),
                            key="dynamics.g", expected=f"{len(s.states)} rows of {len(s.inputs)}",
                            found=f"{[len(r) for r in s.dynamics.g]}", code="MPG106")
        f = ec.vector(s.dynamics.f, ("dynamics", "f"), env)
        g = ca.vertcat(*[ca.horzcat(*[ec.sx(v, ("dynamics", "g", i, j), env) for j, v in enumerate(row)])
                         for i, row in enumerate(s.dynamics.g)]) if s.inputs else ca.SX(len(s.states), 0)
        xdot = f + (ca.mtimes(g, u) if s.inputs else 0)
    else:
        if len(s.xdot) != len(s.states):
            raise SpecError("xdot needs one entry per state", location=spec.system_locate(("xdot",)), key="xdot",
                            expected=f"{len(s.states)} entries", found=f"{len(s.xdot)}", code="MPG106")
        env.update({n: u[i] for i, n in enumerate(s.inputs)})
        xdot = ec.vector(s.xdot, ("xdot",), env)
    lo = np.full(len(s.inputs), -np.inf)
    hi = np.full(len(s.inputs), np.inf)
    for k, (a, b) in s.input_bounds.items():
        if k not in s.inputs:
            raise SpecError("bound for an unknown input", location=spec.system_locate(("input_bounds", k)),
                            key=f"input_bounds.{k}", expected="one of " + ", ".join(s.inputs), found=repr(k),
                            code="MPG107")
        if b <= a:
            raise SpecError("input bounds must be [low, high] with low < high",
                            location=spec.system_locate(("input_bounds", k)), key=f"input_bounds.{k}",
                            expected="low < high", found=f"[{a}, {b}]", code="MPG107")
        i = s.inputs.index(k)
        lo[i], hi[i] = a, b
    wrap = np.zeros(len(s.states))
    for k, p in s.wrap.items():
        if k not in s.states:
            raise SpecError("wrap for an unknown state", location=spec.system_locate(("wrap", k)), key=f"wrap.{k}",
                            expected="one of " + ", ".join(s.states), found=repr(k), code="MPG107")
        wrap[s.states.index(k)] = p
    return CompiledSystem(s.name, list(s.states), list(s.inputs), dict(s.parameters), x, u, xdot, lo, hi, wrap)


SYSTEM_KINDS = {"analytic": compile_analytic, "rigid_body": _rigid_body}
"""System kinds by the `kind` key of a system spec: each builds a CompiledSystem."""
