"""Compile a system spec to CasADi: state/input symbols and the open-loop dynamics xdot(x, u)."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import Protocol

import casadi as ca
import numpy as np

from ..errors import SpecError, SpecErrors
from ..spec.expr import CONSTANTS, FUNCTIONS, KEYWORDS
from ..spec.loader import ProjectSpec
from ..spec.models import PrimitiveClass
from .exprs import ExprCompiler

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass
class OpenLoop:
    """xdot(x, u) of one dynamics mode, with the extra symbols it defines (e.g. contact forces); which
    feet it holds is the primitive's contact plan (compile/contacts.py)."""

    xdot: ca.SX
    env: dict


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

    kind = "analytic"  # the system kind this system was compiled by (entry points `mpgspec.systems`)
    events = False  # the state jumps at contact events (rigid bodies with contact_events)

    @property
    def is_rigid_body(self) -> bool:
        return self.kind == "rigid_body"

    @property
    def nx(self) -> int:
        return len(self.state_names)

    @property
    def event_clocks(self) -> list[int]:
        """State indices of the event clocks of contact events (compile/events.py); none here."""
        return []

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

    def project(self, x: ca.SX, u: ca.SX | None = None, s=ca.inf) -> ca.SX:
        """The discrete part of a step ending s after switch-in: back onto the state manifold, events
        (identity here)."""
        return x

    def builtin_safe_set(self, name: str, loop: OpenLoop, plan=None,
                         t: ca.SX | None = None) -> list[tuple[str, ca.SX]]:
        """The safety functions of a block the system provides (none here)."""
        raise KeyError(name)

    def ground_setpoint(self, x_star: ca.SX, t: ca.SX) -> ca.SX | None:
        """x*(t) with the lowest foot put on the ground (`setpoint.feet_on_ground`); None: no feet."""
        return None

    def wrapped_error(self, dx: ca.SX) -> ca.SX:
        """x - x* with wrapped states (angles) mapped into [-P/2, P/2)."""
        parts = []
        for i in range(self.nx):
            p = float(self.wrap[i])
            d = dx[i]
            parts.append(d - p * ca.floor((d + p / 2) / p) if p > 0 else d)
        return ca.vertcat(*parts)


class SystemKind(Protocol):
    """A system kind: builds the CompiledSystem of a project whose `system.kind` is its name."""

    def __call__(self, spec: ProjectSpec) -> CompiledSystem: ...


SYSTEM_GROUP = "mpgspec.systems"
"""Entry-point group of the system kinds (analytic here, rigid_body in compile/rigidbody/system.py:
pinocchio is loaded only for robots)."""


def system_kind(name: str) -> SystemKind:
    """The system kind registered under `name`."""
    found = {ep.name: ep for ep in entry_points(group=SYSTEM_GROUP)}
    if name not in found:
        raise KeyError(f"no system kind {name!r} is registered under the entry points {SYSTEM_GROUP!r} (installed: "
                       f"{', '.join(sorted(found)) or 'none'}); install mpgspec (pip install -e .)")
    return found[name].load()


def compile_system(spec: ProjectSpec) -> CompiledSystem:
    """Build the CasADi symbols and dynamics of the project's system, by its kind (system_kind).

    Checks first what concerns the whole project (transient hand-over chains), then, with the
    system's names known, that parameters shadow nothing an expression can name.
    """
    check_transients(spec)
    sys = system_kind(spec.system.kind)(spec)
    taken = taken_names(sys, parameters=False)
    errors = [e for n in sys.parameters
              if (e := shadowing_error(n, sys, spec.system_locate(("parameters", n)), f"parameters.{n}",
                                       what="parameter", taken=taken)) is not None]
    if errors:
        raise SpecErrors(errors)
    return sys


def builtin_names() -> dict[str, str]:
    """Names the expression language defines itself, with what they are."""
    names = {n: "a built-in constant" for n in CONSTANTS}
    names.update({n: "a function of the expression language" for n in FUNCTIONS})
    names.update({n: "a keyword of the expression language" for n in KEYWORDS})
    names.update({"t": "the primitive's clock", "s": "the time since switch-in"})  # RESERVED
    return names


def taken_names(sys: "CompiledSystem", *, env: dict | None = None, parameters: bool = True) -> dict[str, str]:
    """Every name an expression of a primitive can already mean, with what it means."""
    names = builtin_names()
    for n in sys.parameters if parameters else ():
        names[n] = "a parameter of the system"
    for k in (env or sys.extra_env):
        names.setdefault(k, "a quantity the system defines")
    for n in sys.input_names:
        names[n] = "an input of the system"
    for n in sys.state_names:
        names[n] = "a state of the system"
        names[f"{n}_star"] = f"the setpoint of state {n}"
        names[f"{n}_star_dot"] = f"the setpoint rate of state {n}"
    return names


def shadowing_error(name: str, sys: "CompiledSystem | None", location, key: str, *, what: str,
                    taken: dict[str, str] | None = None) -> SpecError | None:
    """The error for a declared name (parameter, argument, let) that cannot be named in an
    expression or that would hide a state, input, parameter, constant, function or t/s."""
    if not _IDENT.fullmatch(name):
        return SpecError(f"a {what} name must be an identifier", location=location, key=key,
                         expected="a letter or '_', then letters, digits or '_'", found=repr(name[:60]),
                         code="MPG105")
    taken = taken if taken is not None else taken_names(sys)
    if name in taken:
        return SpecError(f"{what} '{name}' shadows {taken[name]}", location=location, key=key,
                         expected="a name that is not a state, input, parameter, setpoint symbol, built-in "
                                  "constant (pi, e, inf), function, keyword or t/s",
                         found=f"{name!r} ({taken[name]})", code="MPG105", hint="rename it")
    return None


def check_transients(spec: ProjectSpec) -> None:
    """Every transient hands over, at the end of its domain, to an existing primitive, and
    following `next` from a transient reaches a primitive that is not transient (no cycles)."""
    nodes = {p.name: p for p in spec.primitives}
    errors: list[SpecError] = []
    reported: set[str] = set()
    cycles: set[frozenset] = set()
    for inst in spec.primitives:
        nxt = inst.spec.next
        if inst.cls is not PrimitiveClass.TRANSIENT or inst.base in reported:
            continue
        if nxt not in nodes:
            reported.add(inst.base)
            errors.append(SpecError("unknown next primitive", location=inst.locate(("next",)),
                                    key=f"primitive '{inst.base}': next", expected="one of " + ", ".join(sorted(nodes)),
                                    found=repr(nxt), code="MPG304"))
            continue
        chain, cur = [inst.name], nodes[nxt]
        while cur.cls is PrimitiveClass.TRANSIENT and cur.name not in chain and cur.spec.next in nodes:
            chain.append(cur.name)
            cur = nodes[cur.spec.next]
        if cur.name in chain:
            cycle = chain[chain.index(cur.name):]
            if inst.name not in cycle or frozenset(cycle) in cycles:
                continue  # reported at a member of the cycle
            cycles.add(frozenset(cycle))
            reported.add(inst.base)
            loop = " -> ".join(cycle + [cur.name])
            errors.append(SpecError("transient primitives hand over in a cycle", location=inst.locate(("next",)),
                                    key=f"primitive '{inst.base}': next",
                                    expected="a chain of transients that ends in a fixed or periodic primitive",
                                    found=loop, code="MPG306",
                                    hint="a transient runs once over its domain; its next must lead out of it"))
    if errors:
        raise SpecErrors(errors)


def compile_analytic(spec: ProjectSpec) -> CompiledSystem:
    """Build the CasADi symbols and dynamics of an analytic system."""
    s = spec.system
    ec = ExprCompiler(spec.system_locate, f"system '{s.name}'")
    names = list(s.states) + list(s.inputs) + list(s.parameters)
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise SpecError("names of states, inputs and parameters must be distinct", location=spec.system_locate(("states",)),
                        key="states", expected="unique names", found=", ".join(sorted(dup)), code="MPG105")
    builtins = builtin_names()
    errors = [e for field_, what in (("states", "state"), ("inputs", "input")) for i, n in enumerate(getattr(s, field_))
              if (e := shadowing_error(n, None, spec.system_locate((field_, i)), f"{field_}.{i}", what=what,
                                       taken=builtins)) is not None]
    stars = {f"{n}{suffix}": n for n in s.states for suffix in ("_star", "_star_dot")}
    errors += [SpecError(f"{what} '{n}' shadows the setpoint symbol of state {stars[n]}",
                         location=spec.system_locate((field_, i)), key=f"{field_}.{i}",
                         expected="a name that is not <state>_star or <state>_star_dot", found=repr(n), code="MPG105")
               for field_, what in (("states", "state"), ("inputs", "input")) for i, n in enumerate(getattr(s, field_))
               if n in stars]
    if errors:
        raise SpecErrors(errors)
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
        if math.isnan(a) or math.isnan(b) or a == math.inf or b == -math.inf:
            raise SpecError("input bounds must be numbers, low < +inf and high > -inf",
                            location=spec.system_locate(("input_bounds", k)), key=f"input_bounds.{k}",
                            expected="[low, high] with low < high (either side may be infinite outward)",
                            found=f"[{a}, {b}]", code="MPG107")
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
