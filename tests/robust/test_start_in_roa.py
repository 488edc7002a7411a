"""Robust edges from samples of the source's region of attraction (uncertainty.start_in_roa): boundary
starts break an edge that x_A* alone keeps (checked against the target's oracle), they are seeded,
lie on E_A's weighted sphere (projected and kept inside E_A on a contact manifold), and a bad option
is a located spec error."""
from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.oracle import SafetyOracle
from mpgspec.robust import starts as starts_mod
from mpgspec.robust.graph import robust_stage
from mpgspec.robust.starts import boundary_starts, sphere_offsets, weighted_distance
from mpgspec.spec.loader import load_project

ROOT = Path(__file__).resolve().parents[2]
PEND = ROOT / "specs" / "pendulum"
FALLING = ROOT / "tests" / "fixtures" / "falling_body"
W_HANG = np.diag([4.0, 0.04])  # Hang's E: theta within 0.5 rad, omega within 5 rad/s of hanging at rest
PROJECT = """project: pendulum_roa
system: system.yaml
primitives: [primitives/hang.yaml, primitives/swing.yaml]
safe_sets:
  speed_limit:
    - {name: speed_limit, h: "9 - abs(omega)"}
oracle: {horizon: 6.0, dt: 0.005, accuracy: medium, grid: {t_A: 16, t_B: 16}}
"""
NOMINAL_PLANT = """uncertainty:
  parameters: {m: {range: [1.0, 1.0]}}   # the nominal plant: only the start varies
  samples: 0
  runs: 0
"""


def _project(root: Path, block: str) -> Path:
    """Hang and Swing(1) of the pendulum, Hang's E given as the ball of radius 1 in W_HANG, and the
    uncertainty `block`."""
    dst = root / "pendulum"
    shutil.copytree(PEND, dst)
    for name, old, new in [("hang.yaml", "roa: {radius: 0.15, method: lyapunov}",
                             "roa: {radius: 1.0, weights: [4, 0.04]}"),
                           ("swing.yaml", "amp: [1.0, 2.0, 2.6]", "amp: [1.0]")]:
        f = dst / "primitives" / name
        text = f.read_text()
        assert old in text
        f.write_text(text.replace(old, new))
    (dst / "project.yaml").write_text(PROJECT + block)
    return dst / "project.yaml"


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    path = _project(tmp_path_factory.mktemp("roa"), NOMINAL_PLANT + "  start_in_roa: {samples: 16, seed: 0}\n")
    spec = load_project(path)
    return api.build(spec, api.settings_for(spec))


def _with(cp, **update):
    """cp with its uncertainty block updated."""
    unc = cp.spec.project.uncertainty.model_copy(update=update)
    return dataclasses.replace(cp, spec=dataclasses.replace(cp.spec, project=cp.spec.project.model_copy(
        update={"uncertainty": unc})))


def _edges(rob) -> dict:
    return {(e["from"], e["to"]): e for e in rob.to_dict()["edges"]}


def test_boundary_of_E_A_breaks_an_edge_that_x_star_keeps_and_the_oracle_agrees(built):
    cp, vg = built
    hang, swing = cp.prims["Hang"], cp.prims["Swing(1)"]
    alone = _edges(robust_stage(_with(cp, start_in_roa=None), vg))
    assert alone[("Hang", "Swing(1)")]["survives"] and alone[("Hang", "Swing(1)")]["worst_margin"] > 0
    assert "start" not in alone[("Hang", "Swing(1)")]["worst_case"]

    rob = robust_stage(cp, vg)
    d = rob.to_dict()
    assert d["scenarios"]["start_in_roa"] == {"level": "empirical (sampled)", "samples": 16, "seed": 0,
                                              "drawn": 16 * 25, "kept": 16 * 25, "projected": False}
    edges = _edges(rob)
    e = edges[("Hang", "Swing(1)")]
    assert not e["survives"] and e["worst_margin"] < 0 and e["cells"]["robust_safe"] == [0]
    assert rob.graph.edge("Hang", "Swing(1)") is None and vg.graph.edge("Hang", "Swing(1)") is not None
    assert e["start_in_roa"] == {"radius": 1.0, "drawn": 16, "kept": 16} and e["cells"]["starts_kept"] == [16]
    back = edges[("Swing(1)", "Hang")]  # Swing(1)'s E (r = 0.15) lies well within what Hang catches
    assert back["survives"] and back["start_in_roa"]["kept"] == 16 * back["cells_checked"] == 16 * 24

    wc = e["worst_case"]
    st, t_A, t_B = wc["start"], wc["t_A"], wc["t_B"]
    x0 = hang.x_star(t_A) + np.array([st["offset"].get(n, 0.0) for n in hang.system.state_names])
    dx = x0 - hang.x_star(t_A)
    assert st["sample"] is not None and st["radius"] == 1.0
    assert np.sqrt(dx @ W_HANG @ dx) == pytest.approx(1.0) == pytest.approx(st["weighted_distance"])
    again = {s.sample: s.x for s in boundary_starts(hang, t_A, 16, 0)}
    assert np.allclose(again[st["sample"]], x0, atol=1e-12)  # drawn again from its index

    # independently: the target's own oracle, nominal model, from that start at the t_B the plan uses
    # (the cell stops at its first unsafe scenario: this start may already lie outside C_B, as part of
    # E_A's boundary does, or leave it later)
    ev = SafetyOracle(swing, cp.settings)(x0, t_B)
    assert ev.verdict != 1 and ev.status in ("unsafe", "inconclusive")
    assert SafetyOracle(swing, cp.settings)(hang.x_star(t_A), t_B).verdict == 1


def test_start_samples_are_seeded(built):
    cp, vg = built
    hang = cp.prims["Hang"]
    a, b = robust_stage(cp, vg).to_dict(), robust_stage(cp, vg).to_dict()
    assert a["edges"] == b["edges"] and a["scenarios"] == b["scenarios"]
    s16, s8 = boundary_starts(hang, 0.0, 16, 0), boundary_starts(hang, 0.0, 8, 0)
    assert [s.sample for s in s16] == list(range(16))
    assert all(np.array_equal(p.x, q.x) for p, q in zip(s8, s16))  # sample k does not depend on how many
    other = boundary_starts(hang, 0.0, 16, 1)
    assert not any(np.allclose(p.x, q.x) for p, q in zip(s16, other))
    c = robust_stage(_with(cp, start_in_roa=cp.spec.project.uncertainty.start_in_roa.model_copy(
        update={"seed": 1})), vg).to_dict()
    assert c["scenarios"]["start_in_roa"]["seed"] == 1
    assert [e["worst_case"]["start"] for e in c["edges"]] != [e["worst_case"]["start"] for e in a["edges"]]


def test_samples_lie_on_the_weighted_sphere_and_move_weighted_directions_only():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(3, 3))
    W = A @ A.T + 0.1 * np.eye(3)
    dx = sphere_offsets(W, 0.7, 50, np.random.default_rng(2))
    assert np.allclose(np.einsum("ni,ij,nj->n", dx, W, dx), 0.49)
    free = sphere_offsets(np.diag([4.0, 0.0, 1.0]), 0.5, 50, np.random.default_rng(3))
    assert np.all(free[:, 1] == 0.0)  # a direction of zero weight is not moved
    assert np.allclose(4 * free[:, 0] ** 2 + free[:, 2] ** 2, 0.25)


def test_a_projected_sample_is_kept_only_inside_E(built, monkeypatch):
    hang = built[0].prims["Hang"]
    xs = hang.x_star(0.0)

    def projection(prim, W):  # odd samples pushed 10 % outside E, even ones 10 % inside
        calls = iter(range(100))
        return lambda x, xs_, t=0.0: (xs_ + (1.1 if next(calls) % 2 else 0.9) * (x - xs_), ())

    monkeypatch.setattr(starts_mod, "_contact_projection", projection)
    kept = boundary_starts(hang, 0.0, 8, 0)
    assert [s.sample for s in kept] == [0, 2, 4, 6]
    assert all(s.distance == pytest.approx(0.9) == pytest.approx(weighted_distance(hang, s.x, xs)) for s in kept)


def test_rigid_body_samples_are_projected_onto_the_contact_manifold():
    spec = load_project(FALLING / "project.yaml")
    land = api.compile_project(spec)["Land"]
    sys, W = land.system, np.asarray(land.info["roa_W"])
    xs = land.x_star(0.0)
    kept = boundary_starts(land, 0.0, 16, 0)
    assert 0 < len(kept) <= 16 and len({s.sample for s in kept}) == len(kept)
    for s in kept:
        assert s.distance <= land.radius * (1 + 1e-9)
        assert np.allclose(sys.project_to_contacts(s.x, ("foot",), W), s.x, atol=1e-9)  # on the manifold
        assert np.allclose(s.x[15:], xs[15:])  # contact flag and event clocks: weight 0, not moved


def _cli(capsys, *argv):
    from mpgspec.cli import main

    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_verify_reports_the_worst_start_as_empirical_sampled(capsys, tmp_path):
    path = _project(tmp_path, NOMINAL_PLANT + "  start_in_roa: {samples: 4, seed: 0}\n")
    out = tmp_path / "reports"
    rc, _, err = _cli(capsys, "verify", path, "--out", out, "-q")
    assert rc == 0, err
    rob = json.loads((out / "pendulum_roa" / "report.json").read_text())["robust"]
    assert rob["scenarios"]["start_in_roa"]["level"] == "empirical (sampled)"
    assert rob["summary"]["nominal_only"] == ["Hang -> Swing(1)"]
    start = next(e for e in rob["edges"] if e["from"] == "Hang")["worst_case"]["start"]
    html = (out / "pendulum_roa" / "report.html").read_text()
    section = html.split('<section id="robust">')[1].split("</section>")[0]
    assert "empirical (sampled)</span>" in section and "certified" not in section
    assert f"from boundary sample {start['sample']} of E_A" in html


@pytest.mark.parametrize("option, what", [
    ("{samples: 0}", "greater than or equal to 1"),
    ("{samples: 4, seed: -1}", "greater than or equal to 0"),
    ("{samples: 4, sede: 1}", "sede"),
    ("8", "start_in_roa"),
])
def test_bad_start_in_roa_is_a_located_spec_error(capsys, tmp_path, option, what):
    path = _project(tmp_path, NOMINAL_PLANT + f"  start_in_roa: {option}\n")
    line = path.read_text().splitlines().index(f"  start_in_roa: {option}") + 1
    rc, _, err = _cli(capsys, "verify", path, "--no-write", "-q")
    assert rc == 2 and "Traceback" not in err
    assert f"project.yaml:{line}:" in err and "start_in_roa" in err and what in err
