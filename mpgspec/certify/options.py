"""Typed `roa.options` of the built-in level-set verifiers (verifiers/lyapunov.py, sos.py, polyv.py).

The spec's options are validated against these models before any verifier runs, so a wrong value
is a located spec error instead of a failed or silently different region of attraction.
"""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, StrictStr, field_validator

from ..spec.system import Number

Positive = Annotated[Number, Field(gt=0)]
Matrix = list[list[Number]]


class LevelSetOptions(BaseModel):
    """Options of the `sos` verifier (the certified route of `lyapunov`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    degree: StrictInt = Field(default=2, ge=2, description="degree of V (even); above 2 the V-rho alternation")
    iterations: StrictInt = Field(default=10, ge=0, le=1000, description="V-rho alternation rounds")
    improve_tol: Annotated[Number, Field(ge=0)] = Field(default=1e-3, description="stop below this relative gain")
    P: Matrix | None = Field(default=None, description="V = y'Py given")
    Q: Matrix | None = Field(default=None, description="P from A'P + PA = -Q")
    rho: Positive | None = Field(default=None, description="check this level only")
    rho_max: Positive | None = Field(default=None, description="cap of the level search")
    rtol: Annotated[Number, Field(gt=0, lt=1)] = 1e-3
    eps: Positive = 1e-4
    equilibrium_tol: Positive = 1e-8
    polynomial: StrictBool | None = None
    samples: StrictInt = Field(default=20000, ge=1)
    radial: StrictInt = Field(default=40, ge=1)
    local_starts: StrictInt = Field(default=8, ge=0)
    boundary_tol: Annotated[Number, Field(ge=0)] = 1e-9
    empirical_margin: Annotated[Number, Field(gt=0, le=1)] = 0.99
    seed: StrictInt = 0
    mult_half_degree: Annotated[StrictInt, Field(ge=0)] | None = None
    solver: StrictStr = "CLARABEL"
    solver_opts: dict = Field(default_factory=dict)
    tol_eig: Positive = 1e-8
    tol_res: Positive = 1e-6
    region: Literal["ball", "level_set"] = Field(
        default="ball", description="E: the largest W-ball inside {V <= rho} (ball) or the level set itself")

    @field_validator("degree")
    @classmethod
    def _even(cls, v: int) -> int:
        if v % 2:
            raise ValueError(f"degree must be even (a Lyapunov function of odd degree is unbounded below), got {v}")
        return v


class LyapunovOptions(LevelSetOptions):
    """Options of the `lyapunov` verifier."""

    require_certified: StrictBool = False


OPTION_MODELS: dict[str, type[BaseModel]] = {"sos": LevelSetOptions, "lyapunov": LyapunovOptions}
"""Typed options of the built-in verifiers that declare them."""
