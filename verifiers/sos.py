"""The `sos` RoA verifier: the certified route of the Lyapunov verifier only.

It fails unless every part of the quadratic (or, with `degree`, polynomial) Lyapunov level set
has a checked SOS certificate (sos_certificates.py); see lyapunov.py.
"""
from __future__ import annotations

import cvxpy as cp

from .lyapunov import verifier as lyapunov
from .sos_certificates import padd, pmul, prove_sos  # noqa: F401 - the SOS toolkit, as tests call it

class SOSVerifier:
    """The certified route of the Lyapunov verifier only: fails unless every part has an SOS certificate."""

    name = "sos"
    description = "quadratic Lyapunov level set certified by checked SOS certificates (polynomial loops only)"

    @staticmethod
    def is_installed() -> bool:
        return bool({"CLARABEL", "SCS"} & set(cp.installed_solvers()))

    def estimate(self, problem, options: dict | None = None):
        return lyapunov.estimate(problem, {**(options or {}), "require_certified": True, "branch_and_bound": False,
                                           "method_name": self.name})


verifier = SOSVerifier()
