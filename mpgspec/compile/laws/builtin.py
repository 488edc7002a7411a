"""The built-in controller kinds, as their entry points name them (pyproject.toml,
`mpgspec.controllers`): spec models from the spec layer, laws imported on first use."""
from __future__ import annotations

from ...spec.controllers import ExpressionController, IDQPController, LQRController, PDController
from .kind import ControllerKind

EXPRESSION = ControllerKind(ExpressionController, law="mpgspec.compile.laws.expression:expression_law", position=0)
PD = ControllerKind(PDController, law="mpgspec.compile.laws.pd:pd_law", position=1)
LQR = ControllerKind(LQRController, law="mpgspec.compile.laws.lqr:lqr_law", position=2)
ID_QP = ControllerKind(IDQPController, law="mpgspec.compile.rigidbody.idqp:idqp_law", position=3)
