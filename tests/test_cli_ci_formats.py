"""`verify --format junit` and `--format sarif`: the documents validate against the JUnit XSD and the
SARIF 2.1.0 schema (tests/data/schemas), carry each finding at its spec line, and are stdout's only
content."""
from __future__ import annotations

import json
import shutil
from pathlib import Path
from xml.etree import ElementTree as ET

import jsonschema
import pytest
import xmlschema

from mpgspec.cli import main

HERE = Path(__file__).parent
SCHEMAS = HERE / "data" / "schemas"
TINY = HERE / "fixtures" / "cli_tiny"

DRIFT = """  - name: Drift
    class: fixed
    setpoint: {expr: [0.5]}
    controller: {type: pd, outputs: [x], kp: [0], kd: [0]}
    roa: {radius: 0.05}
"""


@pytest.fixture(scope="module")
def project(tmp_path_factory) -> Path:
    """The tiny project with two assertions that fail (Left -> Right is not an edge; Drift, which
    no primitive reaches, makes `reachable_from` fail) and a primitive whose Definition 1 check warns
    (Drift has no stability)."""
    proj = tmp_path_factory.mktemp("ci") / "tiny"
    shutil.copytree(TINY, proj)
    spec = proj / "project.yaml"
    text = spec.read_text().replace("  - no_edge: {from: Left, to: Right}", "  - edge: {from: Left, to: Right}")
    spec.write_text(text.replace("primitives:\n", "primitives:\n" + DRIFT, 1))
    return proj


def _run(capsys, *args) -> tuple[int, str, str]:
    rc = main(["verify", *map(str, args), "-q", "-j", "1", "--no-write"])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_junit_validates_and_counts_the_failed_assertion(capsys, project):
    rc, out, _ = _run(capsys, project, "--format", "junit")
    assert rc == 1
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(out)
    root = ET.fromstring(out)
    suite = root.find("testsuite")
    assert suite.get("name") == "tiny" and suite.get("failures") == "2" and suite.get("errors") == "0"
    failed = [c for c in suite.iter("testcase") if c.find("failure") is not None]
    assert [c.get("name") for c in failed] == ["edge Left -> Right", "every primitive reachable from Left"]
    line = _line_of(project / "project.yaml", "edge: {from: Left, to: Right}")
    assert f"project.yaml:{line})" in failed[0].find("failure").text
    drift = next(c for c in suite.iter("testcase") if c.get("classname") == "tiny.assumptions.Drift"
                 and c.get("name") == "local_stability")
    assert drift.find("failure") is None and drift.find("system-out").text.startswith("WARN")
    assert int(suite.get("tests")) == len(list(suite.iter("testcase"))) > 5


def test_junit_under_strict_fails_the_warning_too(capsys, project):
    rc, out, _ = _run(capsys, project, "--format", "junit", "--strict")
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(out)
    suite = ET.fromstring(out).find("testsuite")
    assert rc == 1 and suite.get("failures") == "3"


def test_sarif_validates_and_places_each_finding_at_its_spec_line(capsys, project, tmp_path):
    rc, out, err = _run(capsys, project, "--format", "sarif", "--baseline", tmp_path / "none")
    assert rc == 1
    doc = json.loads(out)  # stdout is the document alone: the baseline's note went to stderr
    assert "baseline" in err
    schema = json.loads((SCHEMAS / "sarif-2.1.0.json").read_text())
    jsonschema.Draft4Validator(schema).validate(doc)
    results = doc["runs"][0]["results"]
    assert sorted(r["ruleId"] for r in results) == ["assertion", "assertion", "assumption"]
    a = results[0]
    assert a["level"] == "error" and "edge Left -> Right" in a["message"]["text"]
    where = a["locations"][0]["physicalLocation"]
    assert where["artifactLocation"]["uri"].endswith("project.yaml")
    assert where["region"]["startLine"] == _line_of(project / "project.yaml", "edge: {from: Left, to: Right}")
    assert results[2]["ruleId"] == "assumption" and results[2]["level"] == "warning"
    assert doc["runs"][0]["invocations"][0]["exitCode"] == 1


@pytest.mark.parametrize("fmt", ["junit", "sarif"])
def test_a_usage_error_is_a_valid_document_too(capsys, tmp_path, fmt):
    rc, out, _ = _run(capsys, tmp_path / "missing", "--format", fmt)
    assert rc == 2
    if fmt == "junit":
        xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(out)
        error = ET.fromstring(out).find("testsuite/testcase/error")
        assert error is not None and error.get("message").startswith("MPG001")
    else:
        doc = json.loads(out)
        jsonschema.Draft4Validator(json.loads((SCHEMAS / "sarif-2.1.0.json").read_text())).validate(doc)
        assert [r["ruleId"] for r in doc["runs"][0]["results"]] == ["MPG001"]
        assert doc["runs"][0]["tool"]["driver"]["rules"][-1]["id"] == "MPG001"


def test_characters_xml_cannot_hold_are_replaced_and_paths_are_uris():
    from types import SimpleNamespace

    from mpgspec.report.ci import junit, sarif

    loc = {"file": "my specs/project.yaml", "line": 3}
    report = {"assertions": [{"description": "edge A -> B\x07", "status": "fail", "message": "bell\x07 \x00 end",
                              "location": loc}], "assumptions": [], "timing": {}}
    p = SimpleNamespace(path="my specs/project.yaml", name="p\x01", status="fail", report=report, errors=[])
    text = junit([p])
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(text)
    assert "\x07" not in text and "bell\ufffd" in ET.fromstring(text).find("testsuite/testcase/failure").get("message")
    doc = sarif([p])
    jsonschema.Draft4Validator(json.loads((SCHEMAS / "sarif-2.1.0.json").read_text())).validate(doc)
    assert doc["runs"][0]["results"][0]["locations"][0]["physicalLocation"]["artifactLocation"]["uri"] == \
        "my%20specs/project.yaml"


def test_a_projects_time_counts_its_check_stage_once():
    from mpgspec.report.ci import project_seconds

    # the check stage's parts run side by side, each timed from the stage's start: checks_s is the whole
    side_by_side = {"compile_s": 1.0, "roa_s": 2.0, "graph_s": 3.0, "traces_s": 0.5, "oracle_calls_per_s": 99.0,
                    "plan_execute_s": 1.0, "crosscheck_s": 8.0, "robust_s": 9.0, "assumptions_s": 4.0,
                    "checks_s": 9.5, "oracle_calls": 7}
    assert project_seconds(side_by_side) == pytest.approx(1.0 + 2.0 + 3.0 + 0.5 + 9.5)
    # a report from before (no checks_s): its parts ran one after the other
    one_by_one = {k: v for k, v in side_by_side.items() if k != "checks_s"}
    assert project_seconds(one_by_one) == pytest.approx(1.0 + 2.0 + 3.0 + 0.5 + 1.0 + 8.0 + 9.0 + 4.0)
