"""Execution of a timed sequence of goal primitives, naive or through the graph (Table II)."""
from .sequence import SequenceRun, simulate_sequence

__all__ = ["SequenceRun", "simulate_sequence"]
