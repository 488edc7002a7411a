"""Typed `roa.options` of the built-in verifiers (verifiers/lyapunov.py, sos.py, polyv.py,
sampling.py, floquet.py).

The spec's options are validated against these models before any verifier runs, so a wrong value
is a located spec error instead of a failed or silently different region of attraction. Sizes are
bounded too (MAX_DEGREE, MAX_SAMPLES, MAX_STEPS): past them a solver allocates tens of gigabytes
or a run never ends, so they are refused before any work starts.
"""
from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, StrictStr, field_validator

from ..spec.system import Number

Positive = Annotated[Number, Field(gt=0)]
Matrix = list[list[Number]]

MAX_DEGREE = 12
"""Highest degree of V: the SOS Gram matrices grow as C(n + d/2, d/2) squared (degree 12 in 6
states: 924 monomials, a 924 x 924 Gram matrix)."""
MAX_SAMPLES = 1_000_000
"""Most sampled states of any check (a million rollouts or level-set points)."""
MAX_STEPS = 1_000_000
"""Most integration steps per period or horizon."""


class LevelSetOptions(BaseModel):
    """Options of the `sos` verifier (the certified route of `lyapunov`)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    degree: StrictInt = Field(default=2, ge=2, le=MAX_DEGREE, description="degree of V (even); above 2 the V-rho alternation")
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
    samples: StrictInt = Field(default=20000, ge=1, le=MAX_SAMPLES)
    radial: StrictInt = Field(default=40, ge=1, le=10_000)
    local_starts: StrictInt = Field(default=8, ge=0, le=10_000)
    boundary_tol: Annotated[Number, Field(ge=0)] = 1e-9
    empirical_margin: Annotated[Number, Field(gt=0, le=1)] = 0.99
    seed: StrictInt = 0
    mult_half_degree: Annotated[StrictInt, Field(ge=0, le=MAX_DEGREE // 2)] | None = None
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

    require_certified: StrictBool = Field(
        default=False, description="fail unless every part is certified (set by the spec's `require: certified`)")
    branch_and_bound: StrictBool = Field(
        default=True, description="with require_certified, prove non-polynomial parts by interval branch-and-bound")
    boxes: StrictInt = Field(default=50_000, ge=1, le=MAX_SAMPLES,
                             description="most boxes of the branch-and-bound at each level tried")


class SearchOptions(BaseModel):
    """Options of the `sampling` verifier: a bisection on r, each level checked by sampled rollouts."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    r0: Positive | None = Field(default=None, description="first radius tried")
    r_max: Positive | None = Field(default=None, description="largest radius tried")
    rtol: Annotated[Number, Field(gt=0, lt=1)] | None = Field(default=None, description="relative width where the bisection stops")
    confirm_rounds: StrictInt = Field(default=5, ge=0, le=100, description="rounds of fresh samples at the final radius")
    confirm_shrink: Annotated[Number, Field(ge=0.5, lt=1)] = Field(
        default=0.9, description="factor the radius shrinks by after a round of fresh samples fails (finer: a closer "
        "estimate of the radius fresh samples pass, more rounds)")
    samples: StrictInt = Field(default=256, ge=1, le=MAX_SAMPLES, description="rollouts per level")
    seed: StrictInt = Field(default=0, ge=0)
    conv: Positive | None = Field(default=None, description="contraction that counts as converged")
    dt: Positive | None = Field(default=None, description="integration step (s)")
    horizon: Annotated[Number, Field(gt=0, le=1e5)] | None = Field(default=None, description="rollout length (s)")


class FloquetOptions(SearchOptions):
    """Options of the `floquet` verifier: the monodromy of one period, then sampled rollouts."""

    t0: Number = Field(default=0.0, description="clock where the period starts")
    steps: StrictInt = Field(default=2000, ge=1, le=MAX_STEPS, description="integration steps of the monodromy")
    tol: Positive = 1e-6
    orbit_tol: Positive = 1e-3
    periods: StrictInt | None = Field(default=None, ge=1, le=1000, description="periods each sampled rollout runs")
    steps_per_period: StrictInt = Field(default=200, ge=1, le=MAX_STEPS)
    neutral: list[StrictStr] = Field(default_factory=list, description="neutral directions of a floating base")
    window: Annotated[Number, Field(gt=0, le=10)] = Field(
        default=0.02, description="seconds before each contact change where a gait's tube puts window_samples starts")
    window_samples: StrictInt = Field(default=512, ge=0, le=MAX_SAMPLES,
                                      description="starts of a gait's tube before contact changes, run 2 window")


OPTION_MODELS: dict[str, type[BaseModel]] = {"sos": LevelSetOptions, "lyapunov": LyapunovOptions,
                                             "sampling": SearchOptions, "floquet": FloquetOptions}
"""Typed options of the built-in verifiers that declare them."""
