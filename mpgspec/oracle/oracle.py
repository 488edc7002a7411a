"""SafetyOracle: Definition 4 for one primitive B, evaluated through a registered backend."""
from __future__ import annotations

import numpy as np

from ..compile.primitive import CompiledPrimitive
from ..spec.models import PrimitiveClass
from ..settings import OracleSettings
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
        self.runner = get_backend(settings.method).runner(prim, settings)

    def horizons(self, t0s: np.ndarray) -> np.ndarray:
        h = np.full(len(t0s), self.horizon)
        if self.prim.cls is PrimitiveClass.TRANSIENT:  # whole steps that end at or before t_f
            dt = self.settings.dt
            h = np.minimum(h, np.floor((self.prim.domain[1] - np.asarray(t0s)) / dt + 1e-9) * dt)
        return np.maximum(h, 0.0)

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray) -> list[OracleEvidence]:
        """Verdict and evidence for every row of x0s, started at the matching clock in t0s."""
        t0s = np.atleast_1d(np.asarray(t0s, float))
        return self.runner.evaluate(np.atleast_2d(np.asarray(x0s, float)), t0s, self.horizons(t0s))

    def __call__(self, x0, t0: float) -> OracleEvidence:
        return self.evaluate(np.asarray(x0, float)[None, :], np.array([t0]))[0]
