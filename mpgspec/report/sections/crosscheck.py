"""The cross-check section: the sequence's runs replayed in an independent simulator (MuJoCo) with
the same compiled control laws; its data is mpgspec.execute.crosscheck's CrossCheckResult."""
from __future__ import annotations

from importlib.resources import files
from typing import Any

from markupsafe import Markup
from pydantic import Field

from .. import svg
from ..findings import SIMULATORS
from ..schema import Num, Violation, _Strict
from . import ReportSection


class CrossCheckSwitch(_Strict):
    t: float
    from_: str | None = Field(default=None, alias="from")
    to: str
    clock: float
    roa_margin: Num = Field(description="margin of E of the primitive left, at the simulator's state (> 0: inside)")


class CrossCheckVerdict(_Strict):
    safe: bool
    first_violation: Violation | None
    violation_samples: int = Field(description="samples at which some active h < -tolerance (mpgspec: recorded ones)")
    failed: str


class CrossCheckCom(_Strict):
    max: float = Field(description="largest distance between the two centres of mass, metres")
    t: float
    mpgspec: list[Num]
    mujoco: list[Num]


class CrossCheckJoint(_Strict):
    max: float = Field(description="largest |q_mujoco - q_mpgspec| over the joints, radians")
    t: float
    joint: str


class CrossCheckDivergence(_Strict):
    samples: int = Field(description="mpgspec's samples compared, each with the nearest control update")
    com: CrossCheckCom | None
    joint: CrossCheckJoint | None
    until: Num = Field(description="the first violation in either simulator; the two may part for good after it")
    com_until: Num = Field(description="largest CoM divergence up to `until`, metres")
    joint_until: Num = Field(description="largest joint divergence up to `until`, radians")


class CrossCheckLeast(_Strict):
    primitive: str
    h: str
    mujoco: Num = Field(description="least value in the simulator")
    t: float


class CrossCheckWorst(_Strict):
    primitive: str
    h: str
    mujoco: Num = Field(description="least value in the simulator")
    t: float
    violated_in_mpgspec: bool = Field(description="whether it is among the violations mpgspec's run recorded "
                                                  "(its first 50 violating samples, the first after each switch and each function's first violation)")


class CrossCheckFoot(_Strict):
    t: float
    foot: str
    primitive: str | None = None


class CrossCheckContact(_Strict):
    max_penetration: Num = Field(description="deepest foot below z = 0, metres")
    max_slip_speed: Num = Field(description="largest horizontal speed of a held foot's contact point, m/s")
    slip_at: CrossCheckFoot | None
    lift_off: CrossCheckFoot | None = Field(description="the first time a foot the primitive holds left the floor")
    trunk_contact: Num = Field(description="the first time the trunk touched the floor")


class CrossCheckPair(_Strict):
    mujoco: list[Num]
    mpgspec: list[Num]


class CrossCheckSeries(_Strict):
    t: list[float]
    com_z: CrossCheckPair
    least_h: CrossCheckPair


class ExecutorGoal(_Strict):
    t: float = Field(description="when the goal was commanded")
    goal: str
    arrived: Num = Field(description="when the executor's run was first in the goal while it was commanded "
                                     "(null: never)")
    arrived_mpgspec: Num = Field(description="the same for mpgspec's graph run")


class ExecutorRun(_Strict):
    """The graph executor run on the simulator's own state: it switches when the simulator's state is
    in E of the active primitive and its clock at a verified t_A, as mpgspec's graph run does on its own."""

    safe: bool
    first_violation: Violation | None
    violation_samples: int
    failed: str
    switches: list[CrossCheckSwitch]
    goals: list[ExecutorGoal]
    reached_every_goal: bool
    largest_lag_s: Num = Field(description="largest |arrival - mpgspec's arrival| over the goals both reached, s")
    waiting: dict[str, Any] | None = Field(default=None, description="where the run ended short of its goal: the "
                                           "primitive it waited in and the largest E margin its state reached there")
    contact: CrossCheckContact
    law_failures: dict[str, int] = Field(default_factory=dict)
    wall_s: float
    worst: list[CrossCheckLeast] = Field(default_factory=list, description="the least margin of each kind of h "
                                         "in the simulator, least first")


class CrossCheckRun(_Strict):
    """One sequence run replayed in the simulator and compared with mpgspec's rollout."""

    mode: str
    agree: bool = Field(description="both say safe, or both unsafe")
    mujoco: CrossCheckVerdict
    mpgspec: CrossCheckVerdict
    switches: list[CrossCheckSwitch]
    divergence: CrossCheckDivergence
    worst: list[CrossCheckWorst] = Field(description="the least margin of each kind of h in the simulator")
    contact: CrossCheckContact
    start_offset: Num = Field(description="distance of the settled start configuration from x*(t0)")
    wall_s: float
    law_failures: dict[str, int] = Field(default_factory=dict, description="per primitive, solves of a sampled "
                                         "law (the ID-QP) that did not converge in the replay (their last iterate "
                                         "was applied)")
    series: CrossCheckSeries
    executor: ExecutorRun | None = Field(default=None, description="the graph run: the executor deciding from "
                                         "the simulator's own state, not from mpgspec's switch times")


class CrossCheckVariant(_Strict):
    """The graph executor run on the simulator's own state with some of the cross-check's settings replaced."""

    name: str
    replaces: dict[str, Any] = Field(description="the settings it replaces, by name (contact ones by theirs)")
    agree: bool = Field(description="the executor's run is safe and reaches every goal, as mpgspec's graph run does")
    mujoco: CrossCheckVerdict
    mpgspec: CrossCheckVerdict
    worst: list[CrossCheckLeast] = Field(description="the five least margins of a kind of h in the simulator")
    goals: list[ExecutorGoal]
    reached_every_goal: bool
    largest_lag_s: Num = Field(description="largest |arrival - mpgspec's arrival| over the goals both reached, s")
    waiting: dict[str, Any] | None = Field(default=None, description="where the run ended short of its goal: the "
                                           "primitive it waited in and the largest E margin its state reached there")


class CrossCheck(_Strict):
    """The sequence's runs replayed in an independent simulator with the same compiled control laws."""

    simulator: str
    settings: dict[str, Any]
    model: dict[str, Any] = Field(description="what the simulator's model was built from and holds")
    agree: bool = Field(description="every replayed run and every variant agrees")
    runs: dict[str, CrossCheckRun]
    variants: list[CrossCheckVariant] = Field(default_factory=list, description="the graph executor "
                                              "on the simulator's state under the project's other contact models, "
                                              "control rates and model errors (crosscheck.variants)")


def data(cp, vg, ch) -> dict | None:
    """The replayed runs, when the project asked for a cross-check."""
    return ch.crosscheck.to_dict() if ch.crosscheck is not None else None


def count(xc: dict) -> tuple:
    """The summary line of the cross-check: how many replayed runs agree with mpgspec's verdict."""
    runs = xc.get("runs") or {}
    agree = sum(bool(r.get("agree")) for r in runs.values())
    sim = SIMULATORS.get(xc.get("simulator"), str(xc.get("simulator")))
    vs = xc.get("variants") or []
    more = f"; {sum(bool(v.get('agree')) for v in vs)} of {len(vs)} variants hold" if vs else ""
    return (f"cross-check in {sim}", f"{agree} / {len(runs)}",
            "runs agree" + "".join(f"; {m} disagrees" for m, r in runs.items() if not r.get("agree")) + more)


def view(xc: dict) -> dict:
    """Each replayed run with its plots: CoM height and least h, simulator vs mpgspec."""
    sim = SIMULATORS.get(xc.get("simulator"), str(xc.get("simulator")))
    runs = []
    for mode, r in (xc.get("runs") or {}).items():
        s = r.get("series") or {}
        pics = []
        for key, title, label in (("com_z", f"{mode}: CoM height", "m"), ("least_h", f"{mode}: least active h", "h")):
            pair = s.get(key) or {}
            pics.append(Markup(svg.series_svg(s.get("t") or [], {sim: pair.get("mujoco") or [],
                                                                 "mpgspec": pair.get("mpgspec") or []},
                                              title=title, ylabel=label, zero_line=key == "least_h",
                                              shade_negative=key == "least_h", width=420, height=200)))
        runs.append({"mode": mode, "run": r, "svgs": pics})
    return {"simulator": sim, "runs": runs}


section = ReportSection(
    name="crosscheck", data=data, model=CrossCheck, top_level=True, after="sequence", label="cross-check",
    template=files(__package__).joinpath("crosscheck.html.j2").read_text(encoding="utf-8"),
    description="the sequence's runs replayed in an independent simulator (mpgspec.execute.crosscheck)",
    view=view, count=count)
