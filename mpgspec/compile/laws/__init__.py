"""Control laws k(x, t) of a primitive: the ControllerKind contract, its registry (entry points
`mpgspec.controllers`) and the built-in kinds expression, pd and lqr."""
