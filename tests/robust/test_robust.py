"""Robust graph on the pendulum: spec errors, rollouts against the oracle, gradients, worst cases."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.errors import SpecErrors
from mpgspec.robust.graph import robust_stage
from mpgspec.robust.rollout import RobustRollout, judge, plant
from mpgspec.robust.scenarios import Scenarios
from mpgspec.spec.loader import load_project

PEND = Path(__file__).resolve().parents[2] / "specs" / "pendulum"


def _copy(tmp_path: Path, block: str | None) -> Path:
    """The pendulum project with its uncertainty block replaced by `block` (None: removed)."""
    dst = tmp_path / "pendulum"
    shutil.copytree(PEND, dst)
    text = (dst / "project.yaml").read_text()
    text = text[: text.index("uncertainty:")]
    (dst / "project.yaml").write_text(text + (block or ""))
    return dst / "project.yaml"


@pytest.fixture(scope="module")
def built():
    spec = load_project(PEND / "project.yaml")
    cp, vg = api.build(spec, api.settings_for(spec))
    return cp, vg


@pytest.fixture(scope="module")
def rob(built):
    return robust_stage(*built)


@pytest.mark.parametrize("block, key, hint", [
    ("uncertainty:\n  parameters: {mm: {range: [0.9, 1.2]}}\n", "uncertainty.parameters.mm", "did you mean 'm'"),
    ("uncertainty:\n  disturbance: {inputs: [tua], bound: 0.1}\n", "uncertainty.disturbance.inputs.0",
     "did you mean 'tau'"),
    ("uncertainty:\n  initial_state: {omgea: 0.1}\n", "uncertainty.initial_state.omgea", "did you mean 'omega'"),
    ("uncertainty:\n  parameters: {m: {nominal: 2.0, range: [0.9, 2.2]}}\n", "uncertainty.parameters.m.nominal", ""),
    ("uncertainty:\n  parameters: {m: {range: [1.1, 1.2]}}\n", "uncertainty.parameters.m.range", ""),
    ("uncertainty:\n  assertions:\n    - edge: {from: Hangg, to: Balance}\n", "uncertainty.assertions.0.edge.from",
     "did you mean 'Hang'"),
    ("uncertainty:\n  assertions:\n    - simulation_safe: graph\n", "uncertainty.assertions.0", ""),
])
def test_uncertainty_names_are_checked_with_located_errors(tmp_path, block, key, hint):
    path = _copy(tmp_path, block)
    spec = load_project(path)
    with pytest.raises(SpecErrors) as ei:
        api.compile_stage(spec, api.settings_for(spec))
    err = ei.value.errors[0]
    assert err.key == key and err.location.line > 0 and str(err.location.file).endswith("project.yaml")
    assert hint in err.hint


@pytest.mark.parametrize("block, what", [
    ("uncertainty:\n  parameters: {m: {range: [1.2, 0.9]}}\n", "low <= high"),
    ("uncertainty:\n  disturbance: {inputs: [tau], bound: -1}\n", "greater than 0"),
    ("uncertainty:\n  samples: many\n", "integer"),
    ("uncertainty:\n  disturbanse: {inputs: [tau], bound: 1}\n", "disturbanse"),
])
def test_uncertainty_structure_errors(tmp_path, block, what):
    with pytest.raises(SpecErrors) as ei:
        load_project(_copy(tmp_path, block))
    text = ei.value.errors[0].format()
    assert "uncertainty" in text and what in text and "project.yaml:" in text


def test_rollout_agrees_with_oracle_and_gradient_with_finite_differences(built):
    cp, vg = built
    spec, prims = cp.spec, cp.prims
    tr = vg.graph.edge("Hang", "Swing(1)")
    rr = RobustRollout(prims["Swing(1)"], plant(spec, ["m"]), [0], 4, cp.settings, 6.0)
    x0 = prims["Hang"].x_star(0.0)
    Y, last = rr.run(x0[None], np.array([tr.best_t_B[0]]), np.array([[1.0]]), np.zeros((1, 1, 4)))
    ok, margin, k = judge(Y[0, :-1], Y[0, -1], int(last[0]), 0.0)
    ev = tr.evidence[0][int(np.argmin(np.abs(tr.t_B - tr.best_t_B[0])))]
    assert ok and ev.verdict == 1
    assert k * cp.settings.dt == pytest.approx(ev.t_enter, abs=2 * cp.settings.dt)
    D = np.array([[[0.2, -0.1, 0.3, 0.0]]])
    th = np.array([[1.1]])
    g = rr.gradients(x0[None], np.array([0.3]), th, D, [0], [300])[0]
    eps = 1e-6
    for j in range(4):
        Dp, Dm = D.copy(), D.copy()
        Dp[0, 0, j] += eps
        Dm[0, 0, j] -= eps
        run = lambda D_: rr.run(x0[None], np.array([0.3]), th, D_, tol=np.inf)[0][0, 0, 300]  # noqa: E731
        fd = run(Dp) - run(Dm)
        assert g[0, j] == pytest.approx(fd / (2 * eps), rel=1e-4, abs=1e-8)


def test_gradient_at_chunk_edges_matches_finite_differences(built):
    """The reverse sweep runs chunk by chunk back from each sample: samples at switch-in, at the first
    step, at a chunk's last and next step, and several at once in one call, each against central differences."""
    cp, _ = built
    prims = cp.prims
    rr = RobustRollout(prims["Swing(1)"], plant(cp.spec, ["m"]), [0], 4, cp.settings, 3.0)
    L = rr.CHUNK
    ks = [0, 1, L, L + 1, 2 * L + 37]
    n = len(ks)
    x0 = np.tile(prims["Hang"].x_star(0.0), (n, 1)) + 0.01 * np.arange(n)[:, None]
    T0, th = np.full(n, 0.3), np.full((n, 1), 0.95)
    D = np.tile(np.array([[[0.2, -0.1, 0.3, 0.1]]]), (n, 1, 1))
    rows = [0, 0, 1, 0, 1][:n] if rr.nh else [0] * n
    g = rr.gradients(x0, T0, th, D, rows, ks)
    eps = 1e-6
    for q, (r, k) in enumerate(zip(rows, ks)):
        for j in range(4):
            Dp, Dm = D[q:q + 1].copy(), D[q:q + 1].copy()
            Dp[0, 0, j] += eps
            Dm[0, 0, j] -= eps
            run = lambda D_: rr.run(x0[q:q + 1], T0[q:q + 1], th[q:q + 1], D_, tol=np.inf)[0][0, r, k]  # noqa: E731
            assert g[q, 0, j] == pytest.approx((run(Dp) - run(Dm)) / (2 * eps), rel=1e-4, abs=1e-8), (k, j)
    assert np.any(g[2:] != 0)
    with pytest.raises(ValueError, match="samples must lie"):  # past the horizon: no sample there
        rr.gradients(x0[:1], T0[:1], th[:1], D[:1], [0], [rr.N + 1])


def test_pendulum_robust_graph_and_worst_cases(built, rob):
    cp, vg = built
    d = rob.to_dict()
    assert d["level"] == "empirical" and "not proof" in d["note"]
    edges = {(e["from"], e["to"]): e for e in d["edges"]}
    assert len(edges) == len([t for t in vg.graph.transitions.values() if int(t.cls)])
    lost = edges[("Balance", "SwingUp")]
    assert not lost["survives"] and lost["worst_margin"] < 0
    wc = lost["worst_case"]
    assert lost["cells"]["row"] == [0] and lost["cells"]["robust_safe"] == [0] and wc["t_A"] == 0.0
    assert set(wc["parameters"]) == {"m"} and 0.9 <= wc["parameters"]["m"] <= 1.2
    assert max(abs(v) for v in wc["disturbance"]["tau"]) <= 0.3 + 1e-12
    assert abs(wc["initial_error"]["theta"]) <= 0.02 + 1e-12
    kept = edges[("Hang", "Swing(1)")]
    assert kept["survives"] and kept["robust_class"] == 1 and kept["worst_margin"] >= 0
    assert all(a.status == "pass" for a in rob.assertions), [a.message for a in rob.assertions]
    assert rob.graph.edge("Balance", "SwingUp") is None and vg.graph.edge("Balance", "SwingUp") is not None


def test_no_uncertainty_reproduces_the_nominal_graph(tmp_path):
    path = _copy(tmp_path, "uncertainty:\n  parameters: {m: {range: [1.0, 1.0]}}\n  samples: 0\n  runs: 0\n")
    spec = load_project(path)
    cp, vg = api.build(spec, api.settings_for(spec))
    rob = robust_stage(cp, vg)
    nominal = {k: int(t.cls) for k, t in vg.graph.transitions.items() if int(t.cls)}
    robust = {k: int(t.cls) for k, t in rob.graph.transitions.items() if int(t.cls)}
    assert robust == nominal


def test_planner_on_robust_edges_from_the_report(built, rob):
    from mpgspec.plan.planner import shortest_path
    from mpgspec.report.read import ReportGraph
    from mpgspec.robust.plan import robust_report_graph

    cp, vg = built
    report = {"primitives": [{"name": n, "class": "fixed"} for n in cp.prims],
              "edges": [{"from": a, "to": b, "class": int(t.cls), **t.weights}
                        for (a, b), t in vg.graph.transitions.items() if int(t.cls)],
              "transitions": [{"from": a, "to": b, "t_A": list(t.t_A), "best_t_B": t.best_t_B, "windows": t.windows}
                              for (a, b), t in vg.graph.transitions.items()],
              "robust": rob.to_dict()}
    nominal, robust = ReportGraph(report), robust_report_graph(report)
    assert nominal.edge("Balance", "SwingUp") is not None and robust.edge("Balance", "SwingUp") is None
    path, _ = shortest_path(robust.planner_graph(), "Balance", "SwingUp")
    assert path == ["Balance", "Swing(2.6)", "SwingUp"]
    for (a, b), t in rob.graph.transitions.items():
        if robust.edge(a, b) is not None:
            assert robust.edge(a, b).best_t_B == t.best_t_B and robust.edge(a, b).cls == int(t.cls)


def test_sequence_under_uncertainty_naive_vs_graphs(rob):
    modes = rob.sequence["modes"]
    assert rob.sequence["runs"] == 8 and set(modes) == {"naive", "graph", "robust_graph"}
    assert modes["naive"]["safe_fraction"] == 0.0 and modes["naive"]["first_violation"][0]["primitive"] == "Balance"
    assert modes["graph"]["safe_fraction"] == 1.0 and modes["robust_graph"]["safe_fraction"] == 1.0


def _balance_to_swingup(spec):
    """The pendulum spec with a goal sequence that asks for SwingUp from Balance: the nominal graph's
    shortest way is the nominal-only edge Balance -> SwingUp."""
    import dataclasses

    from mpgspec.spec.project import Sequence

    seq = Sequence(start="Balance", duration=6, commands=[{"t": 0, "goal": "SwingUp"}])
    return dataclasses.replace(spec, project=spec.project.model_copy(update={"sequence": seq}))


def test_sequence_statistics_are_seeded_on_shared_draws_and_robust_mode_avoids_lost_edges(built, rob):
    from mpgspec.plan.planner import lookup_table
    from mpgspec.robust.sequence import sequence_under_uncertainty

    cp, vg = built
    spec = _balance_to_swingup(cp.spec)
    graphs = {"graph": (vg.graph, lookup_table(vg.graph)), "robust_graph": (rob.graph, lookup_table(rob.graph))}
    a = sequence_under_uncertainty(spec, cp.prims, cp.settings, graphs, 6, 11)
    assert a == sequence_under_uncertainty(spec, cp.prims, cp.settings, graphs, 6, 11)
    assert a["runs"] == 6 and a["seed"] == 11 and set(a["modes"]) == {"naive", "graph", "robust_graph"}
    for m in a["modes"].values():
        assert m["runs"] == 6 and m["safe_fraction"] == pytest.approx(m["safe_runs"] / 6)
    used = {m: {(s["from"], s["to"]) for s in x["switches"]} for m, x in a["modes"].items()}
    assert ("Balance", "SwingUp") in used["graph"]  # the nominal plan takes the edge lost under uncertainty
    lost = {tuple(x.split(" -> ")) for x in rob.to_dict()["summary"]["nominal_only"]}
    assert used["robust_graph"] and not used["robust_graph"] & lost
    assert all(rob.graph.edge(*e) is not None for e in used["robust_graph"])
    assert ("Balance", "Swing(2.6)") in used["robust_graph"]  # the robust way round, through the largest swing


def test_a_modes_runs_split_in_blocks_give_the_statistics_of_all_runs_at_once(built, rob):
    """With fewer modes than workers each mode's runs go out in consecutive blocks (uneven here: 7 runs
    on 3 workers); merged, every statistic (fractions, goals, first violations, final primitives,
    switches per edge) is what one job running all of them gives."""
    from mpgspec.oracle.executors import InProcess
    from mpgspec.oracle.joint import run
    from mpgspec.plan.planner import lookup_table
    from mpgspec.robust.sequence import uncertain_stage

    cp, vg = built
    spec = _balance_to_swingup(cp.spec)
    graphs = {"graph": (vg.graph, lookup_table(vg.graph)), "robust_graph": (rob.graph, lookup_table(rob.graph))}
    whole = run(uncertain_stage(spec, cp.prims, cp.settings, graphs, 7, 11, workers=1), InProcess())
    for name, g in graphs.items():
        split = run(uncertain_stage(spec, cp.prims, cp.settings, {name: g}, 7, 11, workers=3, naive=False),
                    InProcess())
        assert split["modes"] == {name: whole["modes"][name]} and split["runs"] == 7
    naive = run(uncertain_stage(spec, cp.prims, cp.settings, {}, 7, 11, workers=2), InProcess())
    assert naive["modes"] == {"naive": whole["modes"]["naive"]}
    assert any(m["first_violation"] for m in whole["modes"].values())  # the merge had violations to order


def _cli(capsys, *argv):
    from mpgspec.cli import main

    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_simulate_uncertain_from_the_report_and_rebuilt_agree(capsys, tmp_path):
    import json

    out = tmp_path / "reports"
    rc, _, err = _cli(capsys, "verify", PEND, "--out", out, "-q")
    assert rc == 0, err
    rc, text, err = _cli(capsys, "simulate", PEND, "--out", out, "--uncertain", "--runs", "5", "--seed", "4",
                         "--format", "json")
    assert rc == 0 and "rebuild" not in err
    doc = json.loads(text)
    assert doc["runs"] == 5 and doc["seed"] == 4 and doc["uncertainty"]["parameters"] == {"m": [0.9, 1.2]}
    modes = doc["modes"]
    assert modes["naive"]["safe_runs"] == 0 and modes["naive"]["first_violation"][0]["primitive"] == "Balance"
    assert modes["graph"]["safe_runs"] == 5 and modes["robust_graph"]["safe_fraction"] == 1.0
    for m in modes.values():  # a run is in every goal only if it reached each while it was commanded
        assert len(m["goals_reached"]) == len(m["goals"]) >= 1
        assert m["reached_goal"] <= min(m["goals_reached"]) <= m["safe_runs"]
    rc, text2, _ = _cli(capsys, "simulate", PEND, "--out", out, "--uncertain", "--runs", "5", "--seed", "4",
                        "--format", "json", "--rebuild")
    assert rc == 0 and json.loads(text2)["modes"] == modes  # the report's graphs run as the rebuilt ones
    rc, text, _ = _cli(capsys, "simulate", PEND, "--out", out, "--uncertain", "--runs", "3")
    assert rc == 0 and "3 seeded runs (seed 0)" in text
    assert [ln.split()[0] for ln in text.splitlines()[1:]] == ["naive", "graph", "robust"]
    assert "0 / 3 safe (0.0 %), 0 safe and in every goal; first unsafe at t = 2.010 s in Balance (" in text
    rc, _, err = _cli(capsys, "simulate", PEND, "--out", out, "--runs", "3")
    assert rc == 2 and "--uncertain" in err
    rc, _, err = _cli(capsys, "simulate", PEND, "--out", out, "--uncertain", "--runs", "0")
    assert rc == 2 and "--runs" in err


def test_simulate_uncertain_needs_an_uncertainty_block(capsys, tmp_path):
    path = _copy(tmp_path, None)
    rc, _, err = _cli(capsys, "simulate", path, "--out", tmp_path / "r", "--uncertain")
    assert rc == 2 and "declares no `uncertainty`" in err


def test_a_run_that_never_leaves_its_start_reaches_none_of_the_later_goals():
    """Goals Lie, Walk, Lie: a run that stays in Lie is in the first goal and, at the end, in Lie
    again, but it never reached Walk while Walk was commanded, so it is not in every goal."""
    import numpy as np

    from mpgspec.robust.sequence import _Runs

    runs = object.__new__(_Runs)
    runs.goals, runs.cmd = ["Lie", "Walk", "Lie"], 0
    runs.arrived = np.zeros((3, 2), bool)
    runs.safe = np.array([True, True])
    runs.cur_a = np.array(["Lie", "Lie"], dtype=object)
    for cmd, where in ((1, ["Lie", "Lie"]), (2, ["Lie", "Walk"]), (3, ["Lie", "Lie"])):
        runs.cmd, runs.cur_a = cmd, np.array(where, dtype=object)
        runs.arrive()
    assert runs.arrived[:, 0].tolist() == [True, False, True]  # stayed in Lie
    assert runs.arrived[:, 1].tolist() == [True, True, True]  # went to Walk and back
    assert (runs.safe & runs.arrived.all(axis=0)).tolist() == [False, True]


def test_a_groups_rollouts_stop_once_one_of_them_is_unsafe(built):
    """run_groups: the rollouts of a group that one member lost stop at the end of that chunk,
    every sample computed equals the ungrouped run's, and a group no member lost runs as alone."""
    cp, vg = built
    prims, tol = cp.prims, cp.settings.h_tolerance
    tr = vg.graph.edge("SwingUp", "Balance")
    rr = type("Short", (RobustRollout,), {"CHUNK": 25})(prims["Balance"], plant(cp.spec, ["m"]), [0], 4, cp.settings,
                                                          cp.settings.horizon)
    x = prims["SwingUp"].x_star(float(tr.t_A[0]))
    X0, T0 = np.tile(x, (4, 1)), np.full(4, float(tr.best_t_B[0]))
    TH = np.array([[0.9], [1.2], [1.0], [0.9]])  # a heavy pendulum pushed hard leaves C; the rest enter E
    D = np.array([[[-2.0] * 4], [[-2.0] * 4], [[0.0] * 4], [[0.0] * 4]])
    Y0, last0 = rr.run(X0, T0, TH, D, tol=tol)
    res = [judge(Y0[r, :-1], Y0[r, -1], int(last0[r]), tol) for r in range(4)]
    assert [ok for ok, _, _ in res] == [True, False, True, True] and res[1][1] < -tol
    assert last0[0] > last0[1]  # its partner runs on past the chunk that decided it
    Y, last, cut = rr.run_groups(X0, T0, TH, D, tol=tol, groups=np.array([0, 0, 1, 1]))
    assert cut.tolist() == [True, False, False, False]
    assert last[0] == last[1] == last0[1] and last[2:].tolist() == last0[2:].tolist()
    assert np.isnan(Y[0, :, last[0] + 1:]).all()
    np.testing.assert_array_equal(Y[0, :, : last[0] + 1], Y0[0, :, : last[0] + 1])
    np.testing.assert_array_equal(Y[1:], Y0[1:])


def test_a_cells_scenarios_stop_once_one_is_unsafe_and_no_verdict_moves(built, rob, monkeypatch):
    """With the stop and the waves, every cell's and own flow's verdict is the one every scenario run
    to its end gives; a stopped cell's worst case is the worst of those decided, never worse than the
    full one."""
    d = rob.to_dict()
    full_run = RobustRollout.run_groups
    monkeypatch.setattr(RobustRollout, "run_groups", lambda self, *a, groups=None, **k: full_run(self, *a, **k))
    monkeypatch.setattr(Scenarios, "waves", lambda self: [np.arange(self.S)])
    full = robust_stage(*built).to_dict()
    assert sum(sum(e["cells"]["stopped"]) for e in d["edges"]) > 0
    assert sum(sum(e["cells"]["stopped"]) for e in full["edges"]) == 0
    for e, f in zip(d["edges"], full["edges"]):
        assert (e["from"], e["to"], e["survives"]) == (f["from"], f["to"], f["survives"])
        assert e["cells"]["robust_safe"] == f["cells"]["robust_safe"]
        for m, mf, k in zip(e["cells"]["worst_margin"], f["cells"]["worst_margin"], e["cells"]["stopped"]):
            assert mf <= m if k else mf == m
    assert [n["robust_safe"] for n in d["nodes"]] == [n["robust_safe"] for n in full["nodes"]]


def test_an_own_flow_no_edge_depends_on_runs_its_first_wave_only(built):
    """A target none of whose cells withstood its scenarios: no edge into it depends on its own flow,
    so the flow runs the first wave (the box's undisturbed corners) only and is undecided when that
    was safe; run in full it is safe, with a least h no larger than the first wave's."""
    from mpgspec.robust.cells import _node_check
    from mpgspec.robust.graph import target_jobs

    cp, vg = built
    sc, jobs = target_jobs(cp.spec, cp.prims, cp.settings, vg.graph)
    job = next(j for j in jobs if j.target == "Balance")
    B, tol = cp.prims["Balance"], cp.settings.h_tolerance
    rr = job.rollout(B, cp.settings.horizon)
    tbs = [0.0, 0.5]
    first = sc.waves()[0]
    assert 0 < len(first) < sc.S
    part = _node_check(B, rr, tbs, sc, cp.settings, tol, decisive=False)
    whole = _node_check(B, rr, tbs, sc, cp.settings, tol, decisive=True)
    assert whole["robust_safe"] is True and whole["not_run"] == 0 and whole["scenarios"] == sc.S * len(tbs)
    assert part["robust_safe"] is None and part["scenarios"] == len(first) * len(tbs)
    assert part["not_run"] == (sc.S - len(first)) * len(tbs)
    assert whole["worst_margin"] <= part["worst_margin"]
    assert part["worst_case"]["kind"].startswith("corner") and "disturbance" not in part["worst_case"]["kind"]


def test_scenario_waves_run_the_undisturbed_corners_first():
    """Scenarios.waves: the corners without disturbance, then every other scenario, each once; a box
    without corners (or only corners) is one wave."""
    kinds = ["nominal", "corner", "corner", "sample"]
    kinds = kinds + [k + ", constant disturbance +bound" for k in kinds] + [k + ", constant disturbance -bound" for k in kinds]
    sg = np.repeat([0.0, 1.0, -1.0], 4)
    sc = Scenarios(["m"], np.zeros((12, 1)), np.zeros((12, 2)), sg, kinds, np.ones(1), 1, ["F"], ["x", "v"])
    first, rest = sc.waves()
    assert first.tolist() == [1, 2]
    assert sorted(first.tolist() + rest.tolist()) == list(range(12))
    alone = Scenarios([], np.zeros((3, 0)), np.zeros((3, 2)), np.array([0.0, 1, -1]),
                      ["nominal", "nominal, constant disturbance +bound", "nominal, constant disturbance -bound"],
                      np.ones(1), 1, ["F"], ["x", "v"])
    assert [w.tolist() for w in alone.waves()] == [[0, 1, 2]]


def test_cells_are_batched_whole_and_a_large_one_alone():
    """_cell_batches: every (cell, start) pair once, at most `per` to a batch, a cell never shares a
    batch once it is split, and how a cell is cut does not depend on the cells around it."""
    from mpgspec.robust.cells import _cell_batches

    starts = [list("ab"), list("cde"), list("fghijkl"), list("m")]
    batches = _cell_batches(starts, 4)
    assert [[c for c, _ in b] for b in batches] == [[0, 0], [1, 1, 1], [2] * 4, [2] * 3, [3]]
    assert sorted(p for b in batches for p in b) == sorted((c, s) for c, ss in enumerate(starts) for s in ss)
    alone = _cell_batches([list("fghijkl")], 4)
    assert [b for b in batches if b[0][0] == 2] == [[(0 + 2, s) for _, s in b] for b in alone]
    assert _cell_batches([list("ab"), list("cd"), list("e")], 4) == [[(0, "a"), (0, "b"), (1, "c"), (1, "d")],
                                                                     [(2, "e")]]
