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
    INCONCLUSIVE = "inconclusive"
    ERROR = "error"


@dataclass
class OracleEvidence:
    """Verdict of O_B(x0, t_B) with its evidence; times are measured from the switch-in.

    status is three-valued: 'safe' (verdict 1) only when every margin exceeds its numerical error
    bound; 'unsafe' when the flow certainly left C, failed, or did not reach E in time;
    'inconclusive' when a margin is within its error bound (no edge is built on it).
    margin is the least sampled value of any active safety function (of the function in doubt, named
    by `violated`, when inconclusive), error_bound what the numerics may hide below it (integration
    error and the dip between samples): margin - error_bound is the least error-aware lower bound.
    method is how the verdict was obtained: 'simulated' for a rollout.
    """

    verdict: int
    reason: Reason
    t_stop: float
    t_enter: float | None = None
    violated: str | None = None
    min_margins: dict[str, float] = field(default_factory=dict)  # least sampled value of each h
    best_roa_margin: float | None = None  # max of r - ||x - x*||: how close the flow came to E
    peak_input: list[float] = field(default_factory=list)  # largest |u| applied, after saturation
    saturated: bool = False
    status: str = ""
    lower_bounds: dict[str, float] = field(default_factory=dict)  # error-aware lower bound of each h
    margin: float | None = None
    error_bound: float | None = None
    entry_margin: float | None = None  # RoA margin at the sample where E was entered
    entry_error: float | None = None  # its numerical error bound
    peak_demand: list[float] = field(default_factory=list)  # largest |u| the law asked for, before saturation
    steps: int = 0
    checked: bool = False
    refined: bool = False
    message: str = ""
    method: str = "simulated"

    def __post_init__(self):
        if not self.status:
            self.status = "safe" if self.verdict == 1 else "unsafe"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["reason"] = self.reason.value
        return d
