"""What one safety-oracle call found, beyond the 0/1 verdict."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import Enum


class Reason(str, Enum):
    """Why the oracle stopped."""

    ENTERED_E = "entered_E"
    LEFT_C = "left_C"
    HORIZON = "horizon_reached"
    INTEGRATION_FAILED = "integration_failed"
    ERROR = "error"


@dataclass
class OracleEvidence:
    """Verdict of O_B(x0, t_B) with its evidence; times are measured from the switch-in.

    method is how the verdict was obtained: 'simulated' for a rollout of the oracle.
    """

    verdict: int
    reason: Reason
    t_stop: float
    t_enter: float | None = None
    violated: str | None = None
    min_margins: dict[str, float] = field(default_factory=dict)
    best_roa_margin: float | None = None  # max of r - ||x - x*||: how close the flow came to E
    peak_input: list[float] = field(default_factory=list)  # largest |u| the law asked for, before saturation
    saturated: bool = False
    steps: int = 0
    checked: bool = False
    refined: bool = False
    message: str = ""
    method: str = "simulated"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["reason"] = self.reason.value
        return d
