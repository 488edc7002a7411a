"""Safety oracle (Definition 4): closed-loop rollouts that decide whether a flow enters E before leaving C."""
from .evidence import OracleEvidence, Reason
from .oracle import SafetyOracle

__all__ = ["OracleEvidence", "Reason", "SafetyOracle"]
