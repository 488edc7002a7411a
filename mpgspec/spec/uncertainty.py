"""Spec model of model uncertainty and disturbances, for the robust graph (mpgspec.robust)."""
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


class Disturbance(Strict):
    """Additive disturbance on inputs, |d_i(t)| <= bound, added after saturation."""

    inputs: list[Text] = Field(min_length=1)
    bound: Positive | list[Positive] = Field(description="one bound for all inputs or one per input")
    segments: int = Field(default=8, ge=1, le=200,
                          description="piecewise-constant pieces over the horizon for the adversarial search")

    @model_validator(mode="after")
    def _one_bound_per_input(self):
        if isinstance(self.bound, list) and len(self.bound) != len(self.inputs):
            raise ValueError(f"bound needs one value per input ({len(self.inputs)}), got {len(self.bound)}")
        return self


class Uncertainty(Strict):
    """What the robust graph must withstand and how hard it searches (a falsification, not a proof)."""

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
