"""The quadruped controller kinds as their entry points name them (pyproject.toml,
`mpgspec.controllers`); laws and the trot's setup are imported on first use."""
from __future__ import annotations

from ...compile.laws.kind import ControllerKind
from .models import JumpController, LandController, TrotController

TROT = ControllerKind(TrotController, law="mpgspec.robots.quadruped.trot:trot_law",
                      setup="mpgspec.robots.quadruped.setup:trot_setup", position=4)
JUMP = ControllerKind(JumpController, law="mpgspec.robots.quadruped.jump:jump_law", position=5)
LAND = ControllerKind(LandController, law="mpgspec.robots.quadruped.land:land_law", position=6)
