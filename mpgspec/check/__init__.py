"""CI assertions over the graph, plans and simulated sequences."""
from .assertions import AssertionResult, evaluate_assertions

__all__ = ["AssertionResult", "evaluate_assertions"]
