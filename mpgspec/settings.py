"""One frozen settings object for the safety oracle, with accuracy presets."""
from __future__ import annotations

from dataclasses import dataclass, replace


@dataclass(frozen=True)
class OracleSettings:
    """How the safety oracle integrates and decides.

    dt: fixed step of the integrator; horizon: T of Definition 4; h_tolerance: h >= -tol is safe;
    check: re-run 'safe' verdicts ('safe') or all verdicts ('all') with step dt / refine and keep the
    finer answer, or skip ('none'); chunk: steps per compiled call between early-termination
    checks; batch: start points integrated side by side in one call; jit: compile with gcc.
    """

    horizon: float = 5.0
    dt: float = 0.01
    method: str = "rk4"
    h_tolerance: float = 0.0
    check: str = "safe"
    refine: int = 2
    chunk: int = 64
    batch: int = 64
    jit: bool = True
    jit_flags: tuple[str, ...] = ("-O1",)

    @classmethod
    def with_accuracy(cls, level: str, **kw) -> "OracleSettings":
        """Presets: low (no check), medium (check safe verdicts), high (dt/2, check all), very_high (dt/4)."""
        base = cls(**kw)
        if level == "low":
            return replace(base, check="none")
        if level == "medium":
            return replace(base, check="safe")
        if level == "high":
            return replace(base, dt=base.dt / 2, check="all")
        if level == "very_high":
            return replace(base, dt=base.dt / 4, check="all")
        raise ValueError(f"unknown accuracy level {level!r}; expected low, medium, high or very_high")

    def replace(self, **kw) -> "OracleSettings":
        return replace(self, **kw)
