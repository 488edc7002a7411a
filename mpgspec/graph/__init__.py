"""Motion primitive graph (Definition 3) built by Algorithm 1."""
from .build import build_graph
from .transition import MotionPrimitiveGraph, Transition, TransitionClass

__all__ = ["MotionPrimitiveGraph", "Transition", "TransitionClass", "build_graph"]
