"""Pydantic models of the JSON report (schema version 2), its JSON Schema, and a validator.

The committed file schema/report-v2.json is generated from these models; regenerate it with
`python -m mpgspec.report.schema` whenever the report changes. Version 2 stores oracle cells and
sequence runs by column and rounds floats (see compact.py); 2.1 adds how each cell's verdict was
obtained (cells.method), the certified counts and the t_A intervals proved for every t_A (certified),
all optional so that 2.0 reports still validate; 2.2 keeps a trace's binding safety functions and
their least instead of every function, the inputs and the states.
"""
from __future__ import annotations

import json
from functools import lru_cache
from importlib.resources import files
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model, model_validator

from .sections.registry import plugin_sections, report_sections

SCHEMA_FILE = "schema/report-v2.json"
SCHEMA_ID = "https://mpgspec.invalid/schema/report-v2.json"
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
    digest: str | None = Field(default=None, description="sha256 of the project's spec files when verified; "
                                                         "plan and simulate reuse the report only while it matches")


class Codes(_Strict):
    """Meaning of the digit codes in oracle cells."""

    status: list[str]
    reason: list[str]
    method: list[str] | None = Field(None, description="how a cell's verdict was obtained (schema 2.1)")


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


class Crossings(_Strict):
    """Where the oracle ended steps at a guard, counted along the report's traced rollouts."""

    located: int = Field(ge=0, description="steps ended at a located crossing, summed over the rollouts")
    rollouts: int = Field(ge=0, description="traced rollouts of this closed loop")


class Guards(_Strict):
    """The closed loop's switching points (compile/guards.py): the oracle ends a step where one crosses."""

    exposed: bool = Field(True, description="false when the loop's switching points could not be searched")
    guards: list[str] = Field(default_factory=list, description="each guard: the operation and its expression")
    why: str = Field("", description="why the loop's switching points are not exposed, or why it has none to locate (a sampled law)")
    crossings: Crossings | None = Field(None, description="guard crossings located along the traced rollouts "
                                                          "of this closed loop (edge and failure traces into it)")


class Primitive(_Strict):
    name: str
    cls: Literal["fixed", "periodic", "transient"] = Field(alias="class")
    period: Num
    domain: tuple[float, float] | None
    next: str | None
    controller: str
    safety_functions: list[str]
    roa_radius: float | None = Field(description="radius of the region of attraction E (null when not finite)")
    roa_before_touchdown: dict[str, float] | None = Field(default=None, description="where E(t) is narrower: "
                                                          "{window: seconds before each scheduled touchdown, radius: "
                                                          "E's radius there}; absent when E's radius is the same at "
                                                          "every phase")
    roa_method: str = Field(description="how E was obtained: 'given' in the spec, or a verifier's name")
    roa_level: Literal["certified", "empirical", "given", "failed"] = "given"
    roa_message: str = ""
    roa_evidence: dict[str, Any] = Field(default_factory=dict, description="P, rho, Gram eigenvalues, solver...")
    horizon: Num
    setpoint_t0: list[float]
    description: str
    info: dict[str, Any] = Field(description="free-form data from the controller (e.g. LQR gains)")
    guards: Guards = Field(default_factory=lambda: Guards(), description="where the closed loop switches or kinks; "
                                                                         "the oracle steps piece by piece between them")


Grid = list[list[Num]]
Digits = list[str]


class Cells(_Strict):
    """The oracle calls O_B(x_A*(t_A), t_B) of one pair, one grid per field ([i_A][i_B]); the verdict of
    a cell is the transition's verdicts[i_A][i_B]."""

    status: Digits = Field(description="one string per t_A row, a digit per t_B: index into codes.status "
                                       "(safe only when every margin exceeds its numerical error bound)")
    reason: Digits = Field(description="one string per t_A row, a digit per t_B: index into codes.reason")
    violated: list[list[int | None]] = Field(description="index into the target's safety functions (h_names, or the "
                                                             "target primitive's safety_functions) of the "
                                                             "violated one, or null")
    t_stop: Grid
    t_enter: Grid
    margin: Grid = Field(description="least sampled value of any active safety function")
    error_bound: Grid = Field(description="what the numerics may hide below margin (3 significant digits)")
    best_roa_margin: Grid
    peak_input: list[Grid] = Field(description="per input: largest |u| applied, after saturation")
    peak_demand: list[Grid] = Field(description="per input: largest |u| asked for, before saturation")
    min_margins: list[Grid] = Field(description="per safety function family (order of h_families, else of "
                                                "the target's safety functions): the least value of its "
                                                "functions")
    checked: Digits = Field(description="one string per t_A row: 1 where every active h was evaluated")
    refined: Digits = Field(description="one string per t_A row: 1 where the verdict was refined with a finer step")
    saturated: Digits = Field(description="one string per t_A row: 1 where an input saturated")
    messages: list[tuple[int, int, str]] = Field(description="[i_A, i_B, text] of the cells with a message")
    method: Digits | None = Field(None, description="one string per t_A row, a digit per t_B: index into "
                                  "codes.method (certified: the verdict is proved; absent: every cell simulated)")


class Counts(_Strict):
    safe: int
    total: int
    inconclusive: int = 0
    refined: int
    errors: int
    certified: int = Field(0, description="cells whose verdict (safe or unsafe) is proved")
    certified_safe: int = Field(0, description="safe cells whose verdict is proved")


class VerdictCounts(_Strict):
    """Oracle calls by status; inconclusive calls had a margin within its numerical error bound."""

    total: int
    safe: int
    unsafe: int
    inconclusive: int
    refined: int
    errors: int
    certified: int = Field(0, description="oracle calls whose verdict is proved")


class Certified(_Strict):
    """What a validated stage proved of an edge beyond its grid points."""

    windows: list[tuple[float, float]] = Field(description="t_A intervals [a, b]: the switch is proved safe for "
                                                           "every t_A in them, not only at grid points")
    boxes: int = Field(ge=0, description="start boxes the proof used")
    order: int = Field(ge=0, description="Taylor order of the validated integration")
    width: float = Field(ge=0, description="the largest start box's width")
    time_s: float = Field(ge=0, description="wall-clock time the proof took, s")



class FromRoA(_Strict):
    rows: list[tuple[float, int, int] | None] = Field(description="per t_A: [share of r_A, samples safe, samples "
                                                     "drawn on E_A's boundary] at the row's best t_B; null where not "
                                                     "checked. The executor switches through the row only within "
                                                     "that share of r_A from x_A*(t_A); 0: never ([0, 0, 0]: not "
                                                     "checked, the sequence's rule, reserve or keep never takes the row)")
    worst: dict | None = Field(None, description="the worst sample not safe: t_A, t_B, sample, status, violated, "
                                                 "margin, reason (null: every sample safe)")


class Transition(_Strict):
    """Oracle grid of one ordered pair: cells[i_A][i_B]; class 0 means no edge."""

    from_: str = Field(alias="from")
    to: str
    cls: Literal[0, 1, 2] = Field(alias="class")
    method: Method = Field(description="certified: every cell the verdict rests on (the safe cells of an edge, "
                                       "every cell of a pair without one) is proved; else simulated")
    h_names: list[str] | None = Field(None, description="safety functions of the target, which cells.violated "
                                                       "indexes (reports before 2.2; since, the target "
                                                       "primitive's safety_functions)")
    h_families: list[str] | None = Field(None, description="the safety functions grouped by the name before "
                                                           "an index (friction_cone[4]), the order of each "
                                                           "cell's min_margins; absent when each has its own")
    t_A: list[float]
    t_B: list[float]
    verdicts: list[list[Literal[0, 1]]]
    cells: Cells
    windows: list[tuple[float, float]]
    best_t_B: list[Num]
    weights: dict[str, float]
    row_margins: list[Num] | None = Field(None, description="per t_A: the least normalised safety margin of the "
                                          "cell at its best t_B (null where none is verified); what "
                                          "`sequence: {switch: margin}` chooses switch times by")
    from_roa: FromRoA | None = Field(None, description="the rows the executor may switch through, also checked from "
                                     "seeded samples of E_A's boundary (absent: not checked)")
    counts: Counts
    certified: Certified | None = Field(None, description="t_A intervals proved for every t_A in them (null: none)")

    @model_validator(mode="after")
    def _grid_shape(self):
        shape = (len(self.t_A), len(self.t_B))
        c = self.cells
        grids = [("verdicts", self.verdicts)] + [(k, getattr(c, k)) for k in (
            "status", "reason", "violated", "t_stop", "t_enter", "margin", "error_bound", "best_roa_margin",
            "checked", "refined", "saturated", "method") if getattr(c, k) is not None] + [
            (f"{k}[{m}]", g) for k in ("peak_input", "peak_demand", "min_margins") for m, g in enumerate(getattr(c, k))]
        for name, grid in grids:
            if len(grid) != shape[0] or any(len(row) != shape[1] for row in grid):
                raise ValueError(f"{name} of {self.from_} -> {self.to} is not len(t_A) x len(t_B) = {shape}")
        for name in ("status", "reason", "checked", "refined", "saturated", "method"):
            if any(not row.isdigit() for row in getattr(c, name) or () if row):
                raise ValueError(f"{name} of {self.from_} -> {self.to} must be strings of digits")
        rows = self.from_roa.rows if self.from_roa is not None else None
        for name, v in (("best_t_B", self.best_t_B), ("row_margins", self.row_margins), ("from_roa.rows", rows)):
            if v is not None and len(v) != shape[0]:
                raise ValueError(f"{name} of {self.from_} -> {self.to} has {len(v)} entries, not {shape[0]}")
        return self


class Edge(_Strict):
    from_: str = Field(alias="from")
    to: str
    cls: Literal[1, 2] = Field(alias="class")
    duration: Num = None
    peak_input: Num = None
    hops: Num = None
    margin: Num = Field(None, description="the least normalised safety margin over the cells the edge switches "
                                          "through: each h's lower bound over the rollout / its value at B's setpoint")
    usable: bool = Field(default=True, description="whether the planner may take the edge (a transient hands over "
                                                   "only to its next primitive, at the end of its domain)")
    unusable_reason: str | None = None


class TraceCrossings(_Strict):
    """The located guard crossings of one rollout: their count and the first times (s after switch-in)."""

    count: int = Field(ge=0)
    t: list[float]


class Series(_Strict):
    """Dense rollout from one start point over time: the binding safety functions, their least, the
    RoA margin (schema 2.2; earlier reports: every h, the inputs and the states)."""

    t: list[float]
    h: dict[str, list[Num]] = Field(description="the binding safety functions (2.2: the violated one, then "
                                                "the least ones), each over t")
    h_least: list[Num] | None = Field(None, description="the least of all h_count safety functions at each t")
    h_count: int | None = Field(None, ge=0, description="how many safety functions h_least is taken over")
    roa_margin: list[Num]
    u: list[list[Num]] | None = Field(None, description="inputs over t (reports before 2.2)")
    x: list[list[Num]] | None = Field(None, description="states over t (reports before 2.2)")
    crossings: TraceCrossings | None = Field(None, description="steps of a loop with guards that ended at a "
                                                               "located crossing")


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
    switch: Literal["first", "margin"] = Field("first", description="the sequence's switching rule: the first "
                                              "verified t_A, or the well-kept ones (sequence.switch)")
    reserve: Num = Field(None, description="sequence.reserve: switches are taken only through cells whose peak |u| "
                                           "is at most this share of each input's bound")
    keep: dict[str, float] | None = Field(None, description="sequence.keep: switches are taken only through cells "
                                          "whose least value of each named safety function family is at least this")
    next: dict[str, dict[str, str | None]] = Field(description="next[current][goal] = primitive to switch to")


class Where(_Strict):
    """A position in a spec file (1-based line and column)."""

    file: str
    line: int
    column: int = 0


class Assertion(_Strict):
    index: int
    kind: str
    description: str
    status: Status
    message: str
    location: Where | None = Field(default=None, description="where the assertion is written")


class AssumptionCheck(_Strict):
    """A Definition-1 check of one primitive; level says how it was established."""

    primitive: str
    name: str
    status: Literal["pass", "info", "warn", "fail"]
    level: Literal["certified", "computed", "empirical", "none"]
    message: str
    numbers: dict[str, Any]
    location: Where | None = Field(default=None, description="the primitive (or its roa) in the spec")


class Command(_Strict):
    t: float
    goal: str
    reference: list[str] | None = Field(default=None, description="what a reference run (e.g. the paper's "
                                        "Table II) goes through for this goal")


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


class ViolationTotal(_Strict):
    """Every violating sample of one safety function in one primitive, counted."""

    primitive: str
    h: str
    first: float = Field(description="time of the first violating sample (s)")
    last: float = Field(description="time of the last violating sample (s)")
    samples: int = Field(description="violating samples (at the run's step)")
    least: Num = Field(description="the least value (null: not finite)")


Point = tuple[Num, Num, Num]


class Pose(_Strict):
    """The robot's stick figure at one instant of a run, world coordinates in metres."""

    t: float
    primitive: str = Field(description="the primitive active from this instant on")
    event: Literal["start", "switch", "first_violation", "end"]
    com: Point
    trunk: list[Point] = Field(description="corners of the trunk's rectangle in the base's x-z plane")
    legs: list[list[Point]] = Field(description="per contact frame: the joints from the base down, then the frame")


class Run(_Strict):
    """One execution of the sequence; samples decimated for pictures, switches and violations in full."""

    mode: str
    safe: bool
    switches: list[Switch]
    violations: list[Violation]
    t: list[float]
    x: list[list[Num]] = Field(description="x[k][i]: state k (order of state_names) at t[i]")
    min_h: list[Num]
    active: list[tuple[str, int]] = Field(description="the active primitive as runs [name, samples]")
    final_primitive: str
    failed: str
    body: dict[str, list[Num]] = Field(default_factory=dict, description=(
        "rigid bodies with a floating base: com_z (m) and roll, pitch, yaw (rad, Z-Y-X Euler angles of the "
        "base, yaw unwrapped) at the samples of t"))
    poses: list[Pose] = Field(default_factory=list, description="stick figures at the start, each switch, the "
                                                                "first violation and the end")
    violation_totals: list[ViolationTotal] = Field(default_factory=list, description=(
        "every violating sample counted per primitive and safety function (violations keeps the first 50 "
        "samples' most violated function, each function's first and the first after each switch)"))


class Sequence(_Strict):
    start: str
    duration: float
    commands: list[Command]
    state_names: list[str]
    runs: dict[str, Run]
    playback: str | None = Field(default=None, description="the 3D playback page of the runs beside the report "
                                                          "(playback.html), when the system has a floating base")


class Integrity(_Strict):
    """What plan and simulate check before they use the report (mpgspec.report.trust)."""

    sha256: str = Field(pattern=r"^[0-9a-f]{64}$", description="sha256 of the report's canonical JSON (sorted keys, "
                                                               "no whitespace) without integrity, generated_at "
                                                               "and timing")
    mac: str = Field(pattern=r"^[0-9a-f]{64}$", description="HMAC-SHA256 of that hash under the key of the machine "
                                                            "that wrote it (MPGSPEC_CACHE_KEY, else its key file)")


class ReportCore(_Strict):
    """One project's verification report; the HTML, DOT and GraphML files are rendered from it."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True, title="mpgspec report v2")
    schema_version: str = Field(pattern=r"^2\.\d+$")
    mpgspec_version: str
    generated_at: str
    project: Project
    codes: Codes
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
    integrity: Integrity | None = Field(default=None, description="written with report.json; absent from the "
                                                                  "report of a run that wrote no files")


@lru_cache(maxsize=1)
def _report_model(names: tuple[str, ...]) -> type[BaseModel]:
    sections = report_sections()
    fields = {n: (sections[n].model | None, Field(default=None, description=sections[n].description))
              for n in names if sections[n].top_level}
    fields["sections"] = (dict[str, dict[str, Any]] | None, Field(
        default=None, description="the data of report sections added as plug-ins (entry-point group "
                                  "mpgspec.report_sections), by name; absent when none is installed"))
    return create_model("Report", __base__=ReportCore, __doc__=ReportCore.__doc__, **fields)


def report_model() -> type[BaseModel]:
    """The report's model: the core fields, then each built-in section's, then `sections`, where the
    plug-in sections' data goes (each checked against its own model by validate_report)."""
    return _report_model(tuple(report_sections()))


def validate_report(d: dict) -> None:
    """Raise pydantic.ValidationError when d does not match the report schema (a plug-in section's
    data, too, against its own model)."""
    report_model().model_validate(d)
    for name, section in plugin_sections().items():
        data = (d.get("sections") or {}).get(name)
        if data is not None:
            section.validate(data)


def report_schema() -> dict:
    """JSON Schema of the report (by alias: 'from', 'class')."""
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
            **report_model().model_json_schema(by_alias=True)}


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
