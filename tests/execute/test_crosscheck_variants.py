"""`crosscheck.variants`: the graph run replayed again under other contact models and control rates.
On the A1's Lie/Stand project, a variant that replaces a setting by its own value replays exactly
as the cross-check's graph run does; at 200 Hz control the PD laws lose the A1 in MuJoCo (a front
foot lifts in Lie), which is a disagreement: a warning, a JUnit case, and with `require_agreement`
a failed assertion. A variant MuJoCo cannot run is a located spec error."""
from __future__ import annotations

import json
import sys
from pathlib import Path

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
def test_variants_replay_the_graph_run_under_other_settings(tmp_path):
    path = _variants(tmp_path, [{"name": "same", "integrator": "implicitfast"}, {"control_rate": 200}],
                     require_agreement=True)
    res = api.verify(path, out_dir=tmp_path / "reports")["a1"]
    report = json.loads(Path(res.files["json"]).read_text())
    validate_report(report)
    xc = report["crosscheck"]
    graph, (same, slow) = xc["runs"]["graph"], xc["variants"]
    assert same["name"] == "same" and same["replaces"] == {"integrator": "implicitfast"}
    assert same["mujoco"] == graph["mujoco"] and same["agree"] == graph["agree"] is True
    assert slow["name"] == "control_rate 200" and slow["replaces"] == {"control_rate": 200.0}
    assert not slow["agree"] and not slow["mujoco"]["safe"] and slow["mujoco"]["violation_samples"] > 0
    assert not xc["agree"]
    # the disagreement is a finding everywhere findings are counted, and fails the run when required
    found = [d for d in disagreements(report) if d.get("variant") == "control_rate 200"]
    assert len(found) == 1 and "finds the graph run unsafe" in found[0]["text"]
    assert res.status == "fail"
    failed = [a for a in report["assertions"] if a["status"] == "fail"]
    assert [a["description"] for a in failed] == ["graph run agrees in mujoco with control_rate 200"]
    xml = junit([res])
    assert 'name="graph run with control_rate 200"' in xml and 'name="graph run with same"' in xml
    html = Path(res.files["html"]).read_text()
    assert 'id="crosscheck-variants"' in html and "control_rate 200" in html


@pytest.mark.parametrize("variant, code, word", [
    ({"name": "nothing"}, "MPG103", "replaces none"),
    ({"control_rate": 3000}, "MPG104", "whole number"),
    ({"contact": {"timeconst": 0.00015}}, "MPG104", "softer"),
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
