"""Validated oracle backend: certified verdicts by validated integration in arb ball arithmetic.

What it guarantees, and what not:
- a `safe` verdict is a proof (mpgspec.validated.flow): from every state of a start box around
  x0 (its rounding, `Options.box`) the closed loop enters E_B and no safety function of B is
  negative before, computed with outward-rounded arithmetic on the compiled closed loop's own
  expression graph (its operations and constants), with Taylor remainders and a-priori enclosures
  in place of error estimates; `unsafe` is equally proved (a safety function certainly negative
  while the flow cannot have entered E yet, or the horizon passed with E never possibly reached);
  anything else is `inconclusive` with the reason, never safe;
- laws that switch or saturate are covered: a step over which a branch is not fixed is a
  first-order hull step, valid for any bounded right-hand side;
- it reads expression graphs only: closed loops that jump (contact events, contact schedules),
  call compiled code (rigid-body libraries) or solve an optimizer at a control rate are refused
  by capability;
- pure Python over python-flint: tens to hundreds of milliseconds per start point, for small
  analytic systems.
Verdicts carry method 'certified' (decided) or 'validated' (inconclusive).
"""
from __future__ import annotations

import importlib.util

import numpy as np
from flint import arb

from mpgspec.compile.primitive import CompiledPrimitive
from mpgspec.oracle.evidence import OracleEvidence, Reason
from mpgspec.settings import OracleSettings
from mpgspec.validated.flow import Options, loop_of, run
from mpgspec.validated.lohner import LohnerSet

_REASONS = {"entered_E": Reason.ENTERED_E, "left_C": Reason.LEFT_C, "horizon_reached": Reason.HORIZON,
            "inconclusive": Reason.INCONCLUSIVE}


class ValidatedRunner:
    """Evaluates O_B(x0, t_B) of one primitive by validated integration, one start point at a time."""

    def __init__(self, prim: CompiledPrimitive, settings: OracleSettings, options: Options = Options()):
        """Reads the primitive's closed loop, safe set and E as tapes (refusing what is no expression graph)."""
        self.prim, self.s, self.o = prim, settings, options
        self.loop = loop_of(prim)

    def evaluate(self, x0s: np.ndarray, t0s: np.ndarray, horizons) -> list[OracleEvidence]:
        x0s, t0s = np.atleast_2d(x0s), np.atleast_1d(t0s)
        T = np.broadcast_to(horizons, (len(t0s),))
        return [self.one(x, float(t), float(h)) for x, t, h in zip(x0s, t0s, T)]

    def one(self, x0, t0: float, horizon: float) -> OracleEvidence:
        x0 = np.asarray(x0, float)
        radius = self.o.box * np.maximum(1.0, np.abs(x0))
        start = LohnerSet.box(x0, radius)
        x_sw = [arb(float(v), float(q)) for v, q in zip(x0, radius)]
        try:
            enc = run(self.loop, start, t0, horizon, x_sw, self.o)
        except (ArithmeticError, ValueError) as err:
            return OracleEvidence(0, Reason.ERROR, 0.0, status="inconclusive", method="validated",
                                  message=f"validated integration failed: {type(err).__name__}: {err}"[:500])
        decided = enc.status != "inconclusive"
        margin = min(enc.lower.values(), default=None)
        how = (f"{enc.steps} steps of order {self.o.order} ({enc.hull_steps} first-order hull steps), "
               f"end width {enc.width:.2g}")
        return OracleEvidence(
            verdict=int(enc.status == "safe"), reason=_REASONS[enc.reason], t_stop=enc.s_stop,
            t_enter=enc.s_enter, violated=enc.violated, min_margins=dict(enc.lower), lower_bounds=dict(enc.lower),
            best_roa_margin=enc.best_roa if np.isfinite(enc.best_roa) else None, status=enc.status,
            margin=margin, error_bound=0.0 if decided else None, steps=enc.steps,
            message=(f"{enc.message}; " if enc.message else "") + how,
            method="certified" if decided else "validated")


class ValidatedBackend:
    """The `validated` entry point (an OracleBackend): expression graphs without jumps only."""

    name = "validated"
    description = "validated integration (Taylor order 10, Lohner QR, arb balls): certified verdicts; slow"
    capabilities = frozenset()

    @staticmethod
    def is_installed() -> bool:
        return importlib.util.find_spec("flint") is not None

    @staticmethod
    def runner(prim: CompiledPrimitive, settings: OracleSettings) -> ValidatedRunner:
        return ValidatedRunner(prim, settings)


backend = ValidatedBackend()
