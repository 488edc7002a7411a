"""`crosscheck.variants`: the graph executor run again on MuJoCo's state under other contact models,
control rates, model errors (the floor's friction, the motors' torque) and sensing errors.
On the A1's Lie/Stand project, a variant that replaces a setting by its own value runs exactly
as the cross-check's graph executor does; at 200 Hz control the PD laws lose the A1 in MuJoCo (a front
foot lifts in Lie), which is a disagreement: a warning, a JUnit case, and with `require_agreement`
a failed assertion. A variant MuJoCo cannot run is a located spec error."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from mpgspec import api  # noqa: E402
from mpgspec.errors import SpecError, SpecErrors  # noqa: E402
from mpgspec.execute.crosscheck.settings import settings_of, variants_of  # noqa: E402
from mpgspec.report.ci import junit  # noqa: E402
from mpgspec.report.findings import disagreements  # noqa: E402
from mpgspec.report.schema import validate_report  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from test_crosscheck import _project  # noqa: E402

SEQUENCE = {"start": "Stand", "duration": 6.5, "commands": [{"t": 1, "goal": "Lie"}, {"t": 4, "goal": "Stand"}]}


def _variants(tmp_path, variants, **more):
    return _project(tmp_path, sequence=SEQUENCE, crosscheck={"simulator": "mujoco", "control_rate": 1000,
                                                              "runs": ["graph"], "variants": variants, **more})


@pytest.mark.slow
def test_variants_run_the_graph_executor_under_other_settings(tmp_path):
    path = _variants(tmp_path, [{"name": "same", "integrator": "implicitfast"}, {"control_rate": 200},
                                {"name": "40 % torque", "torque_scale": 0.4}, {"name": "late", "latency": 0.004},
                                {"name": "noisy", "velocity_noise": 0.05}],
                     require_agreement=True)
    res = api.verify(path, out_dir=tmp_path / "reports")["a1"]
    report = json.loads(Path(res.files["json"]).read_text())
    validate_report(report)
    xc = report["crosscheck"]
    graph, (same, slow, weak, late, noisy) = xc["runs"]["graph"], xc["variants"]
    assert same["name"] == "same" and same["replaces"] == {"integrator": "implicitfast"}
    ex = graph["executor"]
    assert same["mujoco"] == {k: ex[k] for k in ("safe", "first_violation", "violation_samples", "failed")}
    assert same["agree"] is True and same["reached_every_goal"] and same["goals"] == ex["goals"]
    assert same["largest_lag_s"] == ex["largest_lag_s"] and same["worst"] == ex["worst"][:5]
    assert same["mpgspec"] == graph["mpgspec"]
    assert slow["name"] == "control_rate 200" and slow["replaces"] == {"control_rate": 200.0}
    assert not slow["agree"] and not slow["mujoco"]["safe"] and slow["mujoco"]["violation_samples"] > 0
    assert not xc["agree"]
    # a model error mpgspec does not hold: with motors giving 40 % of the torque asked, Stand sags and its
    # state never enters E, so the executor never switches to Lie: safe, but a goal is missed
    assert weak["replaces"] == {"torque_scale": 0.4} and not weak["agree"] and weak["mujoco"]["safe"]
    assert [g["arrived"] is None for g in weak["goals"]] == [True, False] and not weak["reached_every_goal"]
    # sensing: the PD laws read the state 4 ms late and lose the robot in Lie (a foot's friction cone);
    # the base's velocity seen off by up to 0.05 m/s is withstood, though the run differs from the graph run's
    assert late["replaces"] == {"latency": 0.004} and not late["agree"]
    assert late["mujoco"]["first_violation"]["primitive"] == "Lie"
    assert noisy["agree"] and noisy["mujoco"]["safe"] and noisy["worst"] != same["worst"]
    # the disagreement is a finding everywhere findings are counted, and fails the run when required
    found = [d for d in disagreements(report) if d.get("variant") == "control_rate 200"]
    assert len(found) == 1 and "deciding from MuJoCo's state is unsafe" in found[0]["text"]
    assert res.status == "fail"
    failed = [a for a in report["assertions"] if a["status"] == "fail"]
    assert [a["description"] for a in failed] == [f"graph executor holds in mujoco with {n}"
                                                  for n in ("control_rate 200", "40 % torque", "late")]
    assert "not reached: Lie" in failed[1]["message"]
    weak_text = [d["text"] for d in disagreements(report) if d.get("variant") == "40 % torque"]
    assert weak_text == ["with 40 % torque, the graph executor deciding from MuJoCo's state does not reach every "
                         "goal: it misses Lie (commanded at 1 s)"]
    xml = junit([res])
    assert 'name="graph run with control_rate 200"' in xml and 'name="graph run with same"' in xml
    html = Path(res.files["html"]).read_text()
    assert 'id="crosscheck-variants"' in html and "control_rate 200" in html


@pytest.mark.parametrize("variant, code, word", [
    ({"name": "nothing"}, "MPG103", "replaces none"),
    ({"control_rate": 3000}, "MPG104", "whole number"),
    ({"contact": {"timeconst": 0.00015}}, "MPG104", "softer"),
    ({"latency": 0.0015}, "MPG104", "latency"),
])
def test_a_variant_mujoco_cannot_run_is_a_located_spec_error(tmp_path, variant, code, word):
    spec = load_project(_variants(tmp_path, [{"control_rate": 500}, variant]))
    with pytest.raises(SpecError) as err:
        variants_of(spec, settings_of(spec))
    e = err.value
    assert e.code == code and word in str(e) and e.key == "crosscheck.variants[1]" and e.location.line > 0


def test_variants_need_distinct_names(tmp_path):
    with pytest.raises(SpecErrors) as err:
        load_project(_variants(tmp_path, [{"name": "soft", "contact": {"timeconst": 0.001}},
                                          {"name": "soft", "contact": {"timeconst": 0.002}}]))
    (e,) = err.value.errors
    assert "variant names must differ; soft" in str(e) and e.key == "crosscheck.variants" and e.location.line > 0


def test_a_variant_replaces_the_cone_the_floors_friction_and_the_armature(tmp_path):
    """Models beyond the contact's stiffness: the friction cone, the floor's friction (the uncertainty
    range's ends), a rotor armature mpgspec does not model and motors that deliver 90 % of the torque
    asked each change the MuJoCo model they name, and only it."""
    import mujoco

    from mpgspec.api import compile_project
    from mpgspec.execute.crosscheck.mjcf import build_robot

    spec = load_project(_variants(tmp_path, [{"name": "pyramidal", "contact": {"cone": "pyramidal"}},
                                             {"contact": {"friction": 0.4}}, {"armature": 0.01},
                                             {"name": "weak motors", "torque_scale": 0.9}]))
    base = settings_of(spec)
    assert (base.cone, base.friction, base.armature) == ("elliptic", None, None)
    (n1, pyr, c1), (n2, low, c2), (n3, bare, c3), (n4, weak, c4) = variants_of(spec, base)
    assert (n1, c1, pyr.cone) == ("pyramidal", {"cone": "pyramidal"}, "pyramidal")
    assert (n2, c2, low.friction) == ("friction 0.4", {"friction": 0.4}, 0.4)
    assert (n3, c3, bare.armature) == ("armature 0.01", {"armature": 0.01}, 0.01)
    assert (n4, c4, weak.torque_scale, base.torque_scale) == ("weak motors", {"torque_scale": 0.9}, 0.9, 1.0)
    system = compile_project(spec)["Lie"].system
    models = {k: build_robot(system, st) for k, st in (("base", base), ("pyr", pyr), ("low", low), ("bare", bare),
                                                       ("weak", weak))}
    m = {k: r.model for k, r in models.items()}
    assert m["base"].opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and m["pyr"].opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    feet = models["low"].foot_geoms
    assert np.allclose(m["base"].geom_friction[feet, 0], 0.6) and np.allclose(m["low"].geom_friction[feet, 0], 0.4)
    assert m["low"].geom_friction[models["low"].floor, 0] == 0.4
    legs = slice(6, None)  # the free joint's six dofs carry none; the A1's URDF gives its joints none
    assert not m["base"].dof_armature.any() and np.allclose(m["bare"].dof_armature[legs], 0.01)
    assert not m["bare"].dof_armature[:6].any()
    assert np.allclose(m["base"].actuator_gainprm[:, 0], 1.0) and np.allclose(m["weak"].actuator_gainprm[:, 0], 0.9)
    assert np.array_equal(m["weak"].actuator_forcerange, m["base"].actuator_forcerange)  # the limit still binds
    for k in ("pyr", "low", "bare", "weak"):  # nothing else moved
        assert m[k].nbody == m["base"].nbody and np.array_equal(m[k].body_mass, m["base"].body_mass)


def test_the_law_sees_the_state_late_and_the_base_velocity_noisy():
    """_Sensing: the state `delay` control updates old (the oldest there is before that), the floating
    base's linear velocity (v[0:3], after the nq configuration entries) off by at most the noise and
    nothing else moved; the same draws in every replay; the simulator's own state when neither is set."""
    from mpgspec.execute.crosscheck.replay import _Sensing
    from mpgspec.execute.crosscheck.settings import CrossCheckSettings

    class SM:  # the part of a StateMap _Sensing reads: the A1's 19 configuration entries, a floating base
        nq, floating = 19, True

    xs = [np.full(37, float(k)) for k in range(6)]
    late = _Sensing(CrossCheckSettings(latency=0.002), SM)
    assert [late(x)[0] for x in xs] == [0, 0, 0, 1, 2, 3]
    noisy = [_Sensing(CrossCheckSettings(velocity_noise=0.05), SM) for _ in range(2)]
    a, b = [np.array([s(x) for x in xs]) for s in noisy]
    assert np.array_equal(a, b)
    d = a - np.array(xs)
    assert np.abs(d[:, 19:22]).max() <= 0.05 and np.abs(d[:, 19:22]).min() > 0
    assert not np.delete(d, np.s_[19:22], axis=1).any()
    plain = _Sensing(CrossCheckSettings(), SM)
    assert not plain.on and plain(xs[2]) is xs[2]


@pytest.mark.parametrize("where", ["crosscheck", "variant"])
def test_velocity_noise_on_a_fixed_base_is_a_located_spec_error(tmp_path, where):
    """The noise acts on the floating base's velocity: on a fixed base it would silently do nothing."""
    import yaml

    noisy = {"velocity_noise": 0.05}
    path = _variants(tmp_path, [noisy] if where == "variant" else [{"control_rate": 500}],
                     **({} if where == "variant" else noisy))
    doc = yaml.safe_load(path.read_text())
    doc["system"]["floating_base"] = False
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    spec = load_project(path)
    with pytest.raises(SpecError) as err:
        variants_of(spec, settings_of(spec))
    e = err.value
    assert e.code == "MPG108" and "fixed" in str(e) and e.location.line > 0
    assert e.key == ("crosscheck.variants[0]" if where == "variant" else "crosscheck.velocity_noise")
