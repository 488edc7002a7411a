"""SafetyOracle: Definition 4 for one primitive B, evaluated through a registered backend."""
from __future__ import annotations

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..settings import OracleSettings
from .backend import CapabilityError, require_capabilities  # noqa: F401 - CapabilityError: callers catch it here
from .evidence import OracleEvidence
from .registry import get_backend


class SafetyOracle:
    """O_B(x0, t_B): 1 when B's closed loop from x0 at clock t_B enters E_B before leaving C_B.

    The horizon is the primitive's own T when it sets one, else the project's; a transient
    primitive is never run past the end of its domain.
    """

    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings):
        self.prim = prim
        self.settings = settings
        self.horizon = prim.horizon or settings.horizon
        backend = get_backend(settings.method)
        require_capabilities(backend, prim)
        self.runner = backend.runner(prim, settings)

    def horizons(self, t0s: np.ndarray) -> np.ndarray:
        return self.prim.horizons(self.settings.horizon, t0s)

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray) -> list[OracleEvidence]:
        """Verdict and evidence for every row of x0s, started at the matching clock in t0s."""
        t0s = np.atleast_1d(np.asarray(t0s, float))
        return self.runner.evaluate(np.atleast_2d(np.asarray(x0s, float)), t0s, self.horizons(t0s))

    def __call__(self, x0, t0: float) -> OracleEvidence:
        return self.evaluate(np.asarray(x0, float)[None, :], np.array([t0]))[0]
