"""Planning over the motion primitive graph: shortest safe sequences and the lookup table."""
from .planner import Plan, lookup_table, plan_graph, shortest_plan

__all__ = ["Plan", "lookup_table", "plan_graph", "shortest_plan"]
