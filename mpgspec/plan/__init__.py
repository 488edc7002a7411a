"""Planning over the motion primitive graph: shortest safe sequences and the lookup table."""
from .planner import Plan, hops, lookup_table, plan_graph, shortest_path, shortest_plan

__all__ = ["Plan", "hops", "lookup_table", "plan_graph", "shortest_path", "shortest_plan"]
