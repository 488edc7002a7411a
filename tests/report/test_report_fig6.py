"""Fig. 6 and Table II of a goal sequence: body series and stick figures from the execute stage, the
plots with their timeline, the gait tiles and the per-goal traversals, on A1-like runs."""
from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mpgspec.report.compact import MAX_RUN, compact_run, run_rows
from mpgspec.report.fig6 import BODY, TILE_W, body_svg, gait_tiles, tile_scale
from mpgspec.report.html import render_html
from mpgspec.report.schema import validate_report
from mpgspec.report.svg import BLUE, VERMILLION
from mpgspec.report.traversal import command_rows

NS = "{http://www.w3.org/2000/svg}"
ROOT = Path(__file__).resolve().parents[2]
SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
PRIMS = ["Lie", "Stand", "Walk(in_place)", "Walk(slow)", "Walk(medium)", "Walk(fast)", "Jump", "Land"]
COMMANDS = [{"t": 0.0, "goal": "Lie"}, {"t": 3.0, "goal": "Walk(fast)"}, {"t": 8.0, "goal": "Jump"},
            {"t": 11.0, "goal": "Walk(fast)"}, {"t": 16.0, "goal": "Lie"}]
GRAPH = [(0.0, "Lie"), (3.0, "Stand"), (3.6, "Walk(in_place)"), (4.2, "Walk(slow)"), (4.9, "Walk(medium)"),
         (5.5, "Walk(fast)"), (8.0, "Walk(medium)"), (8.6, "Walk(slow)"), (9.1, "Walk(in_place)"), (9.6, "Stand"),
         (10.0, "Jump"), (10.4, "Land"), (10.9, "Stand"), (11.0, "Walk(in_place)"), (11.6, "Walk(slow)"),
         (12.2, "Walk(medium)"), (12.8, "Walk(fast)"), (16.0, "Walk(medium)"), (16.6, "Walk(slow)"),
         (17.2, "Walk(in_place)"), (17.8, "Stand"), (18.3, "Lie")]
NAIVE = [(0.0, "Lie"), (3.0, "Walk(fast)"), (8.0, "Jump"), (8.5, "Land"), (11.0, "Walk(fast)"), (16.0, "Lie")]


def _pose(t: float, prim: str, event: str, x: float, height: float = 0.3, pitch: float = 0.0) -> dict:
    c, s = math.cos(pitch), math.sin(pitch)

    def body(px, pz, py=0.0):  # a point of the trunk frame, pitched about y, in the world
        return [x + c * px + s * pz, py, height - s * px + c * pz]

    legs = []
    for hx, y in ((0.18, 0.05), (0.18, -0.05), (-0.18, 0.05), (-0.18, -0.05)):
        hip = body(hx, 0.0, y)
        legs.append([hip, [hip[0], y + 0.03 * np.sign(y), hip[2]], [hip[0] - 0.05, y, hip[2] - 0.15],
                     [hip[0], y, max(hip[2] - 0.3, 0.0)]])
    trunk = [body(-0.18, -0.05), body(0.18, -0.05), body(0.18, 0.05), body(-0.18, 0.05)]
    return {"t": t, "primitive": prim, "event": event, "com": body(0.0, 0.0), "trunk": trunk, "legs": legs}


def _run(mode: str, switches: list[tuple[float, str]], fall_at: float | None = None, n: int = 2001,
         duration: float = 20.0) -> dict:
    """A run as SequenceRun.to_dict() gives it: walking forward, or falling over from fall_at on."""
    t = np.linspace(0.0, duration, n)
    down = np.clip((t - fall_at) / 0.5, 0.0, 1.0) if fall_at is not None else np.zeros(n)
    com_z = 0.3 - 0.22 * down + 0.005 * np.sin(12 * t)
    roll = 1.3 * down
    active = [next(p for ts, p in reversed(switches) if ts <= v + 1e-9) for v in t]
    sw = [{"t": ts, "to": p, "clock": 0.0, "reason": "start"} if k == 0 else
          {"t": ts, "from": switches[k - 1][1], "to": p, "clock": 0.0, "reason": "commanded"}
          for k, (ts, p) in enumerate(switches)]
    min_h = np.where(down > 0.2, -0.05, 0.1)
    viol = [{"t": float(v), "primitive": a, "h": "ground_contact", "value": -0.05}
            for v, a, m in zip(t, active, min_h) if m < 0][:50]
    poses = [_pose(ts, p, "start" if k == 0 else "switch", 0.3 * ts) for k, (ts, p) in enumerate(switches)]
    if viol:
        poses.append(_pose(viol[0]["t"], viol[0]["primitive"], "first_violation", 0.3 * fall_at, 0.1, 1.2))
        poses.sort(key=lambda p: p["t"])
    poses.append(_pose(duration, active[-1], "end", 0.3 * duration, 0.08 if viol else 0.3))
    return {"mode": mode, "safe": not viol, "switches": sw, "violations": viol, "t": t.tolist(),
            "x": [[0.0] * 3 for _ in t], "min_h": min_h.tolist(), "active": active,
            "final_primitive": active[-1], "failed": "",
            "body": {"com_z": com_z.tolist(), "roll": roll.tolist(), "pitch": (0.02 * np.sin(9 * t)).tolist(),
                     "yaw": np.zeros(n).tolist()},
            "poses": poses}


@pytest.fixture(scope="module")
def seq() -> dict:
    """A readable sequence section with the paper's Table II commands, naive falling at 3.3 s."""
    runs = {"naive": _run("naive", NAIVE, fall_at=3.3), "graph": _run("graph", GRAPH)}
    return {"start": "Lie", "duration": 20.0, "commands": COMMANDS, "state_names": ["a", "b", "c"],
            "runs": {m: run_rows(compact_run(r)) for m, r in runs.items()}}


def _parse(text: str) -> ET.Element:
    root = ET.fromstring(text)
    assert root.tag == NS + "svg"
    return root


def test_compact_run_keeps_body_on_the_samples_and_poses_in_full(seq):
    raw = _run("naive", NAIVE, fall_at=3.3)
    c = compact_run(raw)
    assert len(c["t"]) <= MAX_RUN and all(len(v) == len(c["t"]) for v in c["body"].values())
    assert len(c["poses"]) == len(raw["poses"]) and c["poses"][0]["legs"][0][0] == [0.18, 0.05, 0.3]
    assert len(json.dumps(c["body"])) < 30000


def test_body_plot_has_each_series_per_run_on_shared_axes(seq):
    root = _parse(body_svg(seq["runs"], COMMANDS, PRIMS, 20.0))
    groups = {g.get("data-series"): g for g in root.iter(NS + "g") if g.get("data-series")}
    assert list(groups) == [k for k, *_ in BODY] == ["com_z", "roll", "pitch", "yaw"]
    for g in groups.values():
        assert sorted(p.get("stroke") for p in g.iter(NS + "path")) == sorted([BLUE, VERMILLION])
        assert g.get("clip-path", "").startswith("url(#fig6-clip-")
    ys = [float(r.get("y")) for r in root.iter(NS + "clipPath") for r in r.iter(NS + "rect")]
    assert ys == sorted(ys) and len(set(ys)) == 4  # stacked panels


def test_switches_are_marked_and_timeline_has_a_row_per_run(seq):
    root = _parse(body_svg(seq["runs"], COMMANDS, PRIMS, 20.0))
    marks = [e.get("data-switch") for e in root.iter(NS + "line") if e.get("data-switch")]
    assert marks.count("graph") == len(GRAPH) - 1 and marks.count("naive") == len(NAIVE) - 1
    tips = ["".join(r.find(NS + "title").itertext()) for r in root.iter(NS + "rect")
            if r.find(NS + "title") is not None]
    blocks = [x for x in tips if " from " in x and " outside C " not in x]
    assert sum(x.startswith("goals: ") for x in blocks) == len(COMMANDS)
    assert sum(x.startswith("graph: ") for x in blocks) == len(GRAPH)
    assert sum(x.startswith("naive: ") for x in blocks) == len(NAIVE)
    assert "graph: Walk(fast) from 5.5 s to 8 s" in blocks
    unsafe = [r.get("data-unsafe") for r in root.iter(NS + "rect") if r.get("data-unsafe")]
    assert unsafe and set(unsafe) == {"naive"}
    text = "".join(root.itertext())
    assert "naive (unsafe)" in text and "graph (safe)" in text and "Walk(fast)" in text
    assert any(p.get("patternTransform") for p in root.iter(NS + "pattern"))  # the 7th and 8th primitive hatched


def test_body_plot_needs_body_series(seq):
    bare = {m: {**r, "body": {}} for m, r in seq["runs"].items()}
    assert body_svg(bare, COMMANDS, PRIMS, 20.0) is None and gait_tiles({m: {**r, "poses": []}
                                                                        for m, r in bare.items()}) == []


def test_a_run_that_runs_away_is_clipped_not_rescaling(seq):
    runs = json.loads(json.dumps(seq["runs"]))
    runs["naive"]["body"]["com_z"][-5:] = [1e6] * 5
    root = _parse(body_svg(runs, COMMANDS, PRIMS, 20.0))
    box = next(root.iter(NS + "clipPath")).find(NS + "rect")  # the CoM panel
    y0, y1 = float(box.get("y")), float(box.get("y")) + float(box.get("height"))
    ticks = [float(t.text) for t in root.iter(NS + "text") if t.get("text-anchor") == "end" and
             y0 <= float(t.get("y")) <= y1 + 4 and re.fullmatch(r"-?[\d.]+(e[-+]?\d+)?", t.text or "")]
    assert ticks and max(ticks) < 1


def test_gait_tiles_one_per_pose_at_one_scale(seq):
    rows = gait_tiles(seq["runs"])
    assert [r["mode"] for r in rows] == ["naive", "graph"]
    for r in rows:
        assert len(r["tiles"]) == len(seq["runs"][r["mode"]]["poses"])
    roots = [_parse(t) for r in rows for t in r["tiles"]]
    assert {(x.get("width"), x.get("height")) for x in roots} == {(str(TILE_W), roots[0].get("height"))}
    grounds = {ln.get("y1") for x in roots for ln in x.iter(NS + "line") if ln.get("stroke-width") == "1.2"}
    assert len(grounds) == 1  # the ground line at the same height in every tile
    clips = [c.get("id") for x in roots for c in x.iter(NS + "clipPath")]
    assert len(clips) == len(set(clips)) == len(roots)
    naive = [_parse(t) for t in rows[0]["tiles"]]
    framed = [x for x in naive if any(r.get("stroke") == VERMILLION for r in x.iter(NS + "rect"))]
    assert len(framed) == 1 and "leaves C" in "".join(framed[0].itertext())
    graph_text = ["".join(_parse(t).itertext()) for t in rows[1]["tiles"]]
    assert "3.00 s · switch" in graph_text[1] and "→ Stand" in graph_text[1]
    for x in roots:  # trunk and four legs (two near, two far)
        assert len(list(x.iter(NS + "polygon"))) == 1
        legs = [p for p in x.iter(NS + "path") if p.get("stroke-width") in ("2", "2.2")]
        assert len(legs) == 4


def test_tile_scale_ignores_a_pose_that_ran_away(seq):
    runs = json.loads(json.dumps(seq["runs"]))
    base = tile_scale(runs)
    runs["naive"]["poses"][-1]["legs"][0][-1] = [500.0, 0.0, 300.0]
    assert tile_scale(runs) == pytest.approx(base, rel=0.05)


def test_command_rows_list_each_goal_with_the_traversal(seq):
    rows = command_rows(seq)
    assert [(r["t"], r["goal"]) for r in rows] == [(c["t"], c["goal"]) for c in COMMANDS]
    g = [r["runs"]["graph"] for r in rows]
    assert g[0]["reached"] == "active" and g[0]["steps"] == []
    assert [s["to"] for s in g[1]["steps"]] == ["Stand", "Walk(in_place)", "Walk(slow)", "Walk(medium)", "Walk(fast)"]
    assert g[1]["reached"] == 5.5 and g[1]["from"] == "Lie" and g[1]["violation"] is None
    assert [s["to"] for s in g[2]["steps"]][-4:] == ["Stand", "Jump", "Land", "Stand"] and g[2]["reached"] == 10.0
    assert g[3]["from"] == "Stand" and [s["to"] for s in g[3]["steps"]][0] == "Walk(in_place)"
    assert g[4]["reached"] == 18.3 and g[4]["stopped"] is None
    n = [r["runs"]["naive"] for r in rows]
    assert n[1]["reached"] == 3.0 and n[1]["violation"]["h"] == "ground_contact"
    assert 3.3 < n[1]["violation"]["t"] < 3.5 and n[0]["violation"] is None


def test_command_rows_note_a_run_that_stopped_early(seq):
    s = json.loads(json.dumps(seq))
    r = s["runs"]["naive"]
    k = next(i for i, v in enumerate(r["t"]) if v > 9.0)
    for key in ("t", "min_h", "x", "active"):
        r[key] = r[key][:k]
    rows = command_rows(s)
    assert rows[2]["runs"]["naive"]["stopped"] == pytest.approx(r["t"][-1])
    assert rows[3]["runs"]["naive"]["stopped"] is None


@pytest.fixture(scope="module")
def report(seq) -> dict:
    """The sample report with the A1-like sequence in place of the pendulum's (as report.json holds it)."""
    r = json.loads(SAMPLE.read_text(encoding="utf-8"))
    r["primitives"] = [{**r["primitives"][0], "name": n} for n in PRIMS]
    r["sequence"] = {**{k: v for k, v in seq.items() if k != "runs"},
                     "runs": {"naive": compact_run(_run("naive", NAIVE, fall_at=3.3)),
                              "graph": compact_run(_run("graph", GRAPH))}}
    return r


def test_report_with_body_and_poses_validates(report):
    validate_report(report)
    bad = json.loads(json.dumps(report))
    bad["sequence"]["runs"]["naive"]["poses"][0]["event"] = "somewhere"
    with pytest.raises(ValueError):
        validate_report(bad)


def test_html_shows_table_plots_and_tiles(report):
    html = render_html(report)
    for anchor in ('id="goals"', 'id="fig6"', 'id="gait-tiles"', 'id="tiles-naive"', 'id="tiles-graph"'):
        assert anchor in html
    assert html.count('class="tile"') == sum(len(r["poses"]) for r in report["sequence"]["runs"].values())
    table = html[html.index('id="goals"'):html.index('id="fig6"')]
    assert "Lie → Stand" in table and "leaves C at 3.4 s: ground_contact" in table and "already in Lie" in table
    assert "→ <b>Walk(fast)</b>" in table
    assert 'class="scroll fig6"' in html and "src=" not in html


def test_pendulum_report_has_no_fig6():
    html = render_html(json.loads(SAMPLE.read_text(encoding="utf-8")))
    assert 'id="goals"' in html and 'id="fig6"' not in html and 'id="gait-tiles"' not in html


def test_body_and_poses_from_the_compiled_a1():
    """CoM, trunk angles and leg points of the compiled A1 against pinocchio at a random state."""
    pin = pytest.importorskip("pinocchio")
    from mpgspec.compile.rigidbody.model import find_urdf
    from mpgspec.compile.system import compile_system
    from mpgspec.execute.sequence import SequenceRun, _record_body
    from mpgspec.spec.loader import load_project

    system = compile_system(load_project(ROOT / "specs" / "a1" / "project.yaml"))
    model = pin.buildModelFromUrdf(str(find_urdf("example-robot-data/robots/a1_description/urdf/a1.urdf")),
                                   pin.JointModelFreeFlyer())
    data = model.createData()
    x = system.default_state()
    x[:model.nq] = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q = x[:model.nq]
    pin.framesForwardKinematics(model, data, q)
    run = SequenceRun("graph", t=[0.0, 1.0], x=[x.tolist(), x.tolist()], active=["Stand", "Stand"])
    _record_body(run, system, [(1.0, "Stand", "switch", x)])
    R = pin.Quaternion(q[6], q[3], q[4], q[5]).normalized().toRotationMatrix()
    assert [run.body[k][0] for k in ("roll", "pitch", "yaw")] == pytest.approx(pin.rpy.matrixToRpy(R), abs=1e-9)
    assert run.body["com_z"][0] == pytest.approx(pin.centerOfMass(model, data, q)[2], abs=1e-9)
    pose = run.poses[0]
    assert (pose["t"], pose["primitive"], pose["event"]) == (1.0, "Stand", "switch") and len(pose["legs"]) == 4
    for leg, name in zip(pose["legs"], ("FL", "FR", "RL", "RR")):
        want = [data.oMf[model.getFrameId(f"{name}_{part}")].translation for part in ("hip", "thigh", "calf", "foot")]
        assert np.allclose(leg, want, atol=1e-9)
    base = data.oMf[model.getFrameId("base")]
    for corner in pose["trunk"]:
        assert abs((base.inverse().act(np.array(corner)))[1]) < 1e-9  # in the base's x-z plane


def test_runs_record_a_pose_at_the_start_each_switch_the_first_violation_and_the_end(monkeypatch):
    """On the line_graph fixture (an analytic system: no body series, no figures) the snapshots the
    figures are drawn from are taken at the known switches."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.execute import sequence as sq
    from mpgspec.graph import build_graph
    from mpgspec.plan.planner import lookup_table
    from mpgspec.spec.loader import load_project
    from mpgspec.spec.models import GoalCommand, Sequence

    spec = load_project(ROOT / "tests" / "fixtures" / "line_graph" / "project.yaml")
    settings = settings_for(spec).replace(jit=False)
    prims = compile_project(spec)
    g = build_graph(prims, settings)
    seq = Sequence(start="Home", duration=3.0, commands=[GoalCommand(t=0.5, goal="Right")])
    runs = {m: sq.simulate_sequence(prims, g, lookup_table(g), seq, settings, m) for m in ("naive", "graph")}
    assert all(r.body == {} and r.poses == [] for r in runs.values())
    seen = {}
    monkeypatch.setattr(sq, "_record_body", lambda run, system, snaps: seen.__setitem__(run.mode, snaps))
    for m in ("naive", "graph"):
        sq.simulate_sequence(prims, g, lookup_table(g), seq, settings, m)
    naive = [(e, p, round(t, 6)) for t, p, e, _ in seen["naive"]]
    assert naive == [("start", "Home", 0.0), ("switch", "Right", 0.5), ("first_violation", "Right", 0.5),
                     ("end", "Right", 3.0)]
    graph = [(e, p) for t, p, e, _ in seen["graph"]]
    assert graph == [("start", "Home"), ("switch", "Ramp"), ("switch", "Right"), ("end", "Right")]
    assert [t for t, *_ in seen["graph"]][1:3] == [s["t"] for s in runs["graph"].switches[1:]]


def test_a_reference_row_is_carried_beside_the_runs():
    from mpgspec.report.traversal import command_rows

    seq = {"duration": 4.0, "runs": {}, "commands": [
        {"t": 0.0, "goal": "Lie"}, {"t": 2.0, "goal": "Walk(fast)", "reference": ["Lie", "Stand", "Walk(fast)"]}]}
    rows = command_rows(seq)
    assert rows[0]["reference"] is None and rows[1]["reference"] == ["Lie", "Stand", "Walk(fast)"]
