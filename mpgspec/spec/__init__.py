"""The spec layer: YAML with positions, pydantic models, the expression grammar (parsed, never
evaluated) and every check a spec gets before it is compiled. It imports neither CasADi nor cvxpy;
controller kinds contribute their spec models through the `mpgspec.controllers` entry points."""
