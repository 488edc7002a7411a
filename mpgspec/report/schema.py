"""Pydantic models of the JSON report (schema version 1), its JSON Schema, and a validator.

The committed file schema/report-v1.json is generated from these models; regenerate it with
`python -m mpgspec.report.schema` whenever the report changes.
"""
from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

SCHEMA_FILE = "schema/report-v1.json"
Num = float | None  # non-finite numbers are written as null
Reason = Literal["entered_E", "left_C", "horizon_reached", "integration_failed", "inconclusive", "error"]
Method = Literal["certified", "simulated", "empirical"]
Status = Literal["pass", "fail", "error"]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", populate_by_name=True)


class Project(_Strict):
    name: str
    path: str
    description: str


class Settings(BaseModel):
    """Oracle settings; free-form beyond the fields every report has."""

    model_config = ConfigDict(extra="allow")
    horizon: float
    dt: float
    method: str


class System(_Strict):
    name: str
    kind: str
    states: list[str]
    inputs: list[str]
    input_bounds: dict[str, tuple[float, float]]


class Primitive(_Strict):
    name: str
    cls: Literal["fixed", "periodic", "transient"] = Field(alias="class")
    period: Num
    domain: tuple[float, float] | None
    next: str | None
    controller: str
    safety_functions: list[str]
    roa_radius: float | None = Field(description="radius of the region of attraction E (null when not finite)")
    roa_method: str = Field(description="how E was obtained: 'given' in the spec, or a verifier's name")
    roa_level: Literal["certified", "empirical", "given", "failed"] = "given"
    roa_message: str = ""
    roa_evidence: dict[str, Any] = Field(default_factory=dict, description="P, rho, Gram eigenvalues, solver...")
    horizon: Num
    setpoint_t0: list[float]
    description: str
    info: dict[str, Any] = Field(description="free-form data from the controller (e.g. LQR gains)")


class Cell(_Strict):
    """One oracle call O_B(x_A*(t_A), t_B) with its evidence."""

    verdict: Literal[0, 1]
    status: Literal["safe", "unsafe", "inconclusive"] = Field(
        default=None, description="safe only when every margin exceeds its numerical error bound")
    reason: Reason
    t_stop: Num
    t_enter: Num
    violated: str | None
    checked: bool
    refined: bool
    margin: Num = Field(default=None, description="least sampled value of any active safety function")
    error_bound: Num = Field(default=None, description="what the numerics may hide below margin")
    peak_input: list[Num] = Field(description="largest |u| applied, after saturation")
    peak_demand: list[Num] = Field(default_factory=list, description="largest |u| asked for, before saturation")
    saturated: bool
    min_margins: list[Num] = Field(description="least value of each safety function, in the order of h_names")
    best_roa_margin: Num
    message: str


class Counts(_Strict):
    safe: int
    total: int
    inconclusive: int = 0
    refined: int
    errors: int


class VerdictCounts(_Strict):
    """Oracle calls by status; inconclusive calls had a margin within its numerical error bound."""

    total: int
    safe: int
    unsafe: int
    inconclusive: int
    refined: int
    errors: int


class Transition(_Strict):
    """Oracle grid of one ordered pair: cells[i_A][i_B]; class 0 means no edge."""

    from_: str = Field(alias="from")
    to: str
    cls: Literal[0, 1, 2] = Field(alias="class")
    method: Method
    h_names: list[str] = Field(description="safety functions of the target, the order of each cell's min_margins")
    t_A: list[float]
    t_B: list[float]
    verdicts: list[list[Literal[0, 1]]]
    cells: list[list[Cell]]
    windows: list[tuple[float, float]]
    best_t_B: list[Num]
    weights: dict[str, float]
    counts: Counts

    @model_validator(mode="after")
    def _grid_shape(self):
        shape = (len(self.t_A), len(self.t_B))
        for name, grid in (("verdicts", self.verdicts), ("cells", self.cells)):
            if len(grid) != shape[0] or any(len(row) != shape[1] for row in grid):
                raise ValueError(f"{name} of {self.from_} -> {self.to} is not len(t_A) x len(t_B) = {shape}")
        if len(self.best_t_B) != shape[0]:
            raise ValueError(f"best_t_B of {self.from_} -> {self.to} has {len(self.best_t_B)} entries, not {shape[0]}")
        return self


class Edge(_Strict):
    from_: str = Field(alias="from")
    to: str
    cls: Literal[1, 2] = Field(alias="class")
    duration: Num = None
    peak_input: Num = None
    hops: Num = None


class Series(_Strict):
    """Dense rollout from one start point: h, RoA margin, inputs and states over time."""

    t: list[float]
    h: dict[str, list[Num]]
    roa_margin: list[Num]
    u: list[list[Num]]
    x: list[list[Num]]


class SeriesError(_Strict):
    error: str


class Failure(_Strict):
    from_: str = Field(alias="from")
    to: str
    t_A: float
    t_B: float
    reason: Reason
    violated: str | None
    t_stop: Num
    series: Series | SeriesError


class Plan(_Strict):
    from_: str = Field(alias="from")
    to: str
    weight: str
    path: list[str] | None
    cost: Num


class LookupTable(_Strict):
    weight: str
    next: dict[str, dict[str, str | None]] = Field(description="next[current][goal] = primitive to switch to")


class Assertion(_Strict):
    index: int
    kind: str
    description: str
    status: Status
    message: str


class AssumptionCheck(_Strict):
    """A Definition-1 check of one primitive; level says how it was established."""

    primitive: str
    name: str
    status: Literal["pass", "warn", "fail"]
    level: Literal["certified", "computed", "empirical", "none"]
    message: str
    numbers: dict[str, Any]


class Command(_Strict):
    t: float
    goal: str


class Switch(_Strict):
    t: float
    from_: str | None = Field(default=None, alias="from")
    to: str
    clock: float
    reason: str


class Violation(_Strict):
    t: float
    primitive: str
    h: str
    value: Num


class Run(_Strict):
    mode: str
    safe: bool
    switches: list[Switch]
    violations: list[Violation]
    t: list[float]
    x: list[list[Num]]
    min_h: list[Num]
    active: list[str]
    final_primitive: str
    failed: str


class Sequence(_Strict):
    start: str
    duration: float
    commands: list[Command]
    state_names: list[str]
    runs: dict[str, Run]


class Report(_Strict):
    """One project's verification report; the HTML, DOT and GraphML files are rendered from it."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True, title="mpgspec report v1")
    schema_version: str = Field(pattern=r"^1\.\d+$")
    mpgspec_version: str
    generated_at: str
    project: Project
    status: Status
    settings: Settings
    system: System
    primitives: list[Primitive]
    transitions: list[Transition]
    verdicts: VerdictCounts | None = Field(default=None, description="oracle calls of the graph by status")
    edges: list[Edge]
    failures: list[Failure]
    edge_traces: list[Failure] = Field(default_factory=list, description="the verified switch of every edge over time")
    plans: list[Plan]
    lookup_table: LookupTable
    assertions: list[Assertion]
    assumptions: list[AssumptionCheck] = Field(default_factory=list)
    sequence: Sequence | None
    timing: dict[str, float]


def validate_report(d: dict) -> None:
    """Raise pydantic.ValidationError when d does not match the report schema."""
    Report.model_validate(d)


def report_schema() -> dict:
    """JSON Schema of the report (by alias: 'from', 'class')."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **Report.model_json_schema(by_alias=True)}


def schema_path() -> Path:
    return Path(str(files("mpgspec.report").joinpath(SCHEMA_FILE)))


def main() -> None:
    """Regenerate the committed schema file."""
    path = schema_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report_schema(), indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(path)


if __name__ == "__main__":
    main()
