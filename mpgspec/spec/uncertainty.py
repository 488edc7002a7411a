"""Spec model of model uncertainty and disturbances, for the robust graph (mpgspec.robust).

Rigid-body systems take the parameters `mass_scale` (every link's mass and inertia times k),
`friction` (the feet's Coulomb coefficient), `torque_scale` (every actuator delivers k_tau times
the torque its law commands) and `velocity_error_x/y/z` (the laws read a floating base's linear
velocity with this error added, m/s), a push `force` at a frame of the base and a `latency` between
the state a law reads and the plant receiving its input."""
from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from .base import Strict
from .system import Number, Text

Positive = Annotated[Number, Field(gt=0)]
NonNegative = Annotated[Number, Field(ge=0)]


class ParameterRange(Strict):
    """A parameter of the plant somewhere in [low, high]; the controllers keep the system's value."""

    nominal: Number | None = Field(default=None, description="the system's value; checked when given")
    range: tuple[Number, Number]

    @model_validator(mode="after")
    def _ordered(self):
        lo, hi = self.range
        if hi < lo:
            raise ValueError(f"range must be [low, high] with low <= high, got [{lo:g}, {hi:g}]")
        if self.nominal is not None and not lo <= self.nominal <= hi:
            raise ValueError(f"nominal {self.nominal:g} lies outside the range [{lo:g}, {hi:g}]")
        return self


class Force(Strict):
    """A push: a world-frame force at a frame of a rigid body's base, |F_i| <= bound_i per axis."""

    frame: Text = Field(description="a frame attached to the floating base, e.g. the trunk")
    bound: tuple[NonNegative, NonNegative, NonNegative] = Field(description="N per world axis x, y, z")
    duration: Positive | None = Field(default=None, description="seconds after switch-in the push lasts "
                                                                "(default: the whole horizon)")

    @model_validator(mode="after")
    def _some_force(self):
        if not any(self.bound):
            raise ValueError("bound must be > 0 on at least one axis, got [0, 0, 0]")
        return self


class Disturbance(Strict):
    """Additive disturbance on inputs, |d_i(t)| <= bound, added after saturation; or a force on a
    rigid body's base."""

    inputs: list[Text] | None = Field(default=None, min_length=1)
    bound: Positive | list[Positive] | None = Field(default=None,
                                                    description="one bound for all inputs or one per input")
    force: Force | None = None
    segments: int = Field(default=8, ge=1, le=200,
                          description="piecewise-constant pieces over the horizon (or the push) for the "
                                      "adversarial search")

    @model_validator(mode="after")
    def _one_bound_per_input(self):
        if (self.inputs is None) == (self.force is None):
            raise ValueError("give either inputs (with bound) or force")
        if self.inputs is not None and self.bound is None:
            raise ValueError("inputs need a bound")
        if self.force is not None and self.bound is not None:
            raise ValueError("a force takes its bound inside force: {frame, bound: [x, y, z]}")
        if isinstance(self.bound, list) and len(self.bound) != len(self.inputs):
            raise ValueError(f"bound needs one value per input ({len(self.inputs)}), got {len(self.bound)}")
        return self


class StartInRoA(Strict):
    """Start states sampled on the boundary of the source's region of attraction E_A, besides x_A*(t_A)."""

    samples: int = Field(ge=1, le=1000, description="seeded samples of the weighted sphere ||x - x_A*(t_A)||_W = r_A "
                                                    "per cell, each run with every scenario")
    seed: int = Field(default=0, ge=0, description="seed of the samples (sample k of a source has the same direction for "
                                                   "every target and t_A row)")


class Uncertainty(Strict):
    """What the robust graph must withstand and how hard it searches (a falsification, not a proof)."""

    def rollouts(self, n_nodes: int) -> int:
        """An upper bound on the robust stage's rollouts over n_nodes primitives (the budget's measure)."""
        dim = len(self.parameters) + len(self.initial_state)
        corners = min(2 ** dim, self.corners) if dim else 0
        per_cell = (1 + corners + (self.samples if dim else 0)) * (3 if self.disturbance is not None else 1)
        starts = 1 + (self.start_in_roa.samples if self.start_in_roa is not None else 0)
        return n_nodes * (n_nodes - 1) * self.cells * per_cell * starts * (1 + self.search)

    parameters: dict[str, ParameterRange] = Field(default_factory=dict)
    disturbance: Disturbance | None = None
    initial_state: dict[str, NonNegative] = Field(
        default_factory=dict, description="|x_i - x_A*(t_A)| <= bound per named state at the switch")
    samples: int = Field(default=4, ge=0, le=1000, description="seeded random scenarios per cell, besides corners")
    corners: int = Field(default=32, ge=0, le=1024, description="at most this many corners of the box per cell")
    search: int = Field(default=2, ge=0, le=50, description="adversarial disturbance iterations per cell")
    cells: int = Field(default=64, ge=1, le=1000,
                       description="at most this many t_A rows checked per nominal edge (evenly spread); rows not "
                                   "checked are not in the robust graph")
    runs: int = Field(default=8, ge=0, le=1000,
                      description="seeded runs of the goal sequence under sampled uncertainty, per mode")
    seed: int = 0
    budget: int = Field(default=1_000_000, ge=1, le=100_000_000,
                        description="most robust rollouts the stage may run, checked before it starts: edges among the "
                                    "nodes x cells x scenarios per cell x start states x (1 + search)")
    latency: NonNegative = Field(default=0.0, description="seconds between the state a rigid body's laws read and "
                                                          "the plant receiving their input: a whole number of oracle "
                                                          "steps; each law's input is then held over a step")
    start_in_roa: StartInRoA | None = Field(
        default=None, description="also start each cell from seeded samples of the boundary of the source's region "
                                  "of attraction E_A (projected onto its contact manifold for rigid bodies)")
    nodes: list[Text] | None = Field(default=None, min_length=1,
                                     description="primitives whose edges among each other are re-checked "
                                                 "(default: all); the robust graph has only these")
