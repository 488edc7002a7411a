"""The oracle-backend contract: what an `mpgspec.verifiers` entry point provides.

A backend evaluates the safety oracle O_B(x0, t_B) of Definition 4 for batches of start points of
one compiled primitive, through a runner it builds per primitive. It declares its capabilities:
the kinds of closed loop it can run beyond a smooth flow whose safe set switches at clock times.
The registry (registry.py) refuses a loaded backend that does not implement OracleBackend, and
SafetyOracle (oracle.py) refuses one that lacks a capability a primitive needs
(CompiledPrimitive.needs); the build reports that refusal at the spec's `oracle.method`.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..errors import UsageError
from ..settings import OracleSettings
from .evidence import OracleEvidence

HYBRID = "hybrid"
COMPILED = "compiled"
CAPABILITIES = {HYBRID: "the state jumps at contact events or a contact schedule",
                COMPILED: "the closed loop calls compiled code (a loop library or an optimizer solved at a "
                          "control rate), not an expression graph"}
"""Capabilities a backend may declare, with what a primitive that needs one does."""


@runtime_checkable
class Runner(Protocol):
    """Evaluates O_B for one primitive B."""

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray, horizons: np.ndarray) -> list[OracleEvidence]:
        """Verdict and evidence of each row of x0s started at clock t0s, run for at most its horizon."""


@runtime_checkable
class OracleBackend(Protocol):
    """A named oracle backend with its declared capabilities and a factory of runners. It may also
    offer prebuild(prims, settings): compile what its runners need for all primitives at once
    (the executors call it before the oracle's tasks run; not part of the required contract)."""

    name: str
    description: str
    capabilities: frozenset[str]

    def is_installed(self) -> bool:
        """Whether the libraries it needs are present."""

    def runner(self, prim: CompiledPrimitive, settings: OracleSettings) -> Runner:
        """A runner of O_B for the compiled primitive B under the oracle settings."""


class BackendError(UsageError):
    """A loaded oracle backend does not implement OracleBackend."""


class CapabilityError(UsageError):
    """The chosen backend cannot run a primitive of the project."""


def contract_defects(backend) -> list[str]:
    """What `backend` lacks of OracleBackend: missing or wrongly typed members (empty when it conforms)."""
    out = [f"attribute {a!r} (a string)" for a in ("name", "description")
           if not isinstance(getattr(backend, a, None), str)]
    caps = getattr(backend, "capabilities", None)
    if not isinstance(caps, (set, frozenset)) or not all(isinstance(c, str) for c in caps):
        out.append("attribute 'capabilities' (a set of capability names, such as frozenset({'hybrid'}) or frozenset())")
    out += [f"method {m}()" for m in ("is_installed", "runner") if not callable(getattr(backend, m, None))]
    return out


def check_backend(name: str, target: str, backend) -> None:
    """Raise BackendError, naming the entry point, when a loaded backend does not implement the contract."""
    defects = contract_defects(backend)
    if defects:
        raise BackendError(f"oracle backend {name!r} (entry point {name} = {target!r} of the group "
                           f"'mpgspec.verifiers') does not implement mpgspec.oracle.backend.OracleBackend: "
                           f"it lacks {'; '.join(defects)}")


def require_capabilities(backend: OracleBackend, prim: CompiledPrimitive) -> None:
    """Refuse, with a message naming what is missing, a backend that cannot run the primitive."""
    missing = prim.needs - set(backend.capabilities)
    if missing:
        why = "; ".join(CAPABILITIES.get(c, c) for c in sorted(missing))
        raise CapabilityError(
            f"oracle method {backend.name!r} cannot run primitive {prim.name!r}: it lacks the capability "
            f"{', '.join(sorted(missing))} ({why}); use a backend that has it, e.g. method: rk4")
