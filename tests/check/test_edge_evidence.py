"""`edge: {..., evidence: certified}`: an edge passes only when every safe cell it rests on is proved.

The unit cases build oracle evidence by hand and run Algorithm 1's classification and the assertion
on it. The end-to-end cases verify a two-primitive project with rk4 (every verdict simulated) and
with a test backend, installed by entry point, that marks the verdicts rk4 decides as proved, the
way the validated backend reports its own: the evidence then travels through the cache, the graph,
the report and the assertion as a real backend's would.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from pydantic import ValidationError

from mpgspec import api
from mpgspec.check.assertions import evaluate_assertions
from mpgspec.graph import MotionPrimitiveGraph, Transition, TransitionClass
from mpgspec.oracle import OracleEvidence, Reason, registry
from mpgspec.oracle.executors import InProcess
from mpgspec.report.compact import expand_cells
from mpgspec.spec.models import RequireEdge
from verifiers.rk4 import backend as rk4

PROJECT = """\
project: ev
system:
  name: line
  kind: analytic
  states: [x]
  inputs: [u]
  dynamics: {f: ["0"], g: [[1]]}
  input_bounds: {u: [-10, 10]}
primitives:
  - name: A
    class: fixed
    setpoint: {expr: [0]}
    controller: {type: expression, u: ["-2*x"]}
    roa: {radius: 0.1}
  - name: B
    class: fixed
    setpoint: {expr: [1]}
    controller: {type: expression, u: ["-2*(x - 1)"]}
    safe_set: [{name: wall, h: "2 - x"}]
    roa: {radius: 0.1}
oracle: {horizon: 3, dt: 0.01, accuracy: low, grid: {t_A: 2, t_B: 2}}
assertions:
  - edge: {from: A, to: B, class: 1, evidence: certified}
"""


def ev(verdict: int, method: str = "simulated") -> OracleEvidence:
    if verdict:
        return OracleEvidence(1, Reason.ENTERED_E, 0.5, t_enter=0.5, method=method)
    return OracleEvidence(0, Reason.LEFT_C, 0.2, violated="wall", method=method)


def graph(rows: list[list[OracleEvidence]]) -> MotionPrimitiveGraph:
    tr = Transition("A", "B", np.arange(len(rows), dtype=float), np.arange(len(rows[0]), dtype=float), rows)
    tr.classify()
    return MotionPrimitiveGraph({"A": {"cls": "fixed"}, "B": {"cls": "fixed"}}, {("A", "B"): tr})


def check(g: MotionPrimitiveGraph, **edge):
    a = RequireEdge.model_validate({"edge": {"from": "A", "to": "B", **edge}})
    (res,) = evaluate_assertions([a], g, {})
    return res


# ----------------------------------------------------------------------------- the assertion on built graphs
def test_an_edge_whose_safe_cells_are_all_proved_is_certified():
    """The unsafe cells beside it may be simulated: the edge does not rest on them."""
    g = graph([[ev(1, "certified"), ev(0)], [ev(0, "validated"), ev(1, "certified")]])
    assert g.edge("A", "B").cls is TransitionClass.CLASS_1 and g.edge("A", "B").method == "certified"
    res = check(g, evidence="certified")
    assert (res.status, res.description, res.message) == ("pass", "edge A -> B, certified", "class 1, certified")


def test_one_simulated_safe_cell_makes_the_edge_simulated():
    g = graph([[ev(1, "certified"), ev(1, "certified")], [ev(1), ev(0, "certified")]])
    assert g.edge("A", "B").method == "simulated"
    res = check(g, evidence="certified", **{"class": 1})
    assert (res.status, res.description) == ("fail", "edge A -> B of class 1, certified")
    assert res.message == "edge A -> B is simulated, not certified: 2 of 3 safe cells certified"
    assert check(g).status == "pass" and check(g, evidence="simulated").status == "pass"  # the default: any evidence


def test_a_method_a_backend_names_otherwise_is_not_certified():
    g = graph([[ev(1, "Certified"), ev(1, "certified")]])
    assert check(g, evidence="certified").message.endswith(": 1 of 2 safe cells certified")


def test_a_missing_edge_fails_before_its_evidence_is_asked():
    g = graph([[ev(0, "certified"), ev(0, "certified")]])
    assert g.transitions[("A", "B")].method == "certified"  # its absence is proved ...
    res = check(g, evidence="certified")
    assert (res.status, res.message) == ("fail", "no transition was verified")  # ... but there is no edge


def test_evidence_takes_only_its_two_levels():
    with pytest.raises(ValidationError, match="'simulated' or 'certified'"):
        RequireEdge.model_validate({"edge": {"from": "A", "to": "B", "evidence": "certifed"}})
    with pytest.raises(ValidationError):
        RequireEdge.model_validate({"edge": {"from": "A", "to": "B", "evidence": "empirical"}})


# ----------------------------------------------------------------------------- end to end
class ProvingRunner:
    """rk4's verdicts, the decided ones marked as proved and the others as validated but unproved."""

    def __init__(self, inner):
        self.inner = inner

    def evaluate(self, x0s, t0s, horizons):
        return [dataclasses.replace(e, method="certified" if e.status in ("safe", "unsafe") else "validated")
                for e in self.inner.evaluate(x0s, t0s, horizons)]


class ProvingBackend:
    name = "proving"
    description = "rk4 with its decided verdicts marked as proved (a test plug-in)"
    capabilities = rk4.capabilities

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim, settings):
        return ProvingRunner(rk4.runner(prim, settings))


backend = ProvingBackend()


@pytest.fixture
def proving(tmp_path, monkeypatch):
    """The proving backend declared under mpgspec.verifiers by a distribution on sys.path."""
    dist = tmp_path / "site" / "mpgspec_proving_backend-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mpgspec-proving-backend\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[mpgspec.verifiers]\nproving = {__name__}:backend\n")
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    registry.backends.cache_clear()
    yield
    registry.backends.cache_clear()


def verify(tmp_path, text: str):
    (tmp_path / "project.yaml").write_text(text)
    res = api.verify([tmp_path / "project.yaml"], out_dir=None, overrides={"jit": False}, executor=InProcess())
    (p,) = res.projects
    return res.exit_code, p


def test_rk4_edges_are_simulated_and_fail_a_certified_requirement(tmp_path):
    rc, p = verify(tmp_path, PROJECT)
    (tr,) = [t for t in p.report["transitions"] if (t["from"], t["to"]) == ("A", "B")]
    safe = tr["counts"]["safe"]
    assert rc == 1 and tr["class"] == 1 and tr["method"] == "simulated" and safe > 0
    assert tr["counts"]["certified_safe"] == 0 and tr["certified"] is None
    (a,) = p.report["assertions"]
    assert a["status"] == "fail"
    assert a["message"] == f"edge A -> B is simulated, not certified: 0 of {safe} safe cells certified"


def test_proved_verdicts_make_a_certified_edge_end_to_end(tmp_path, proving):
    rc, p = verify(tmp_path, PROJECT.replace("accuracy: low,", "accuracy: low, method: proving,"))
    assert rc == 0, p.errors or p.report["assertions"]
    r = p.report
    assert r["settings"]["method"] == "proving" and r["verdicts"]["certified"] == r["verdicts"]["total"] > 0
    by_pair = {(t["from"], t["to"]): t for t in r["transitions"]}
    tr = by_pair[("A", "B")]
    assert tr["method"] == "certified" and tr["counts"]["certified_safe"] == tr["counts"]["safe"] > 0
    assert {c["method"] for row in expand_cells(tr) for c in row} == {"certified"}
    assert r["assertions"][0]["message"] == "class 1, certified"


def test_a_robust_edge_cannot_demand_certified_evidence(tmp_path):
    """The robust graph rests on sampled scenarios: the requirement is refused where it is written."""
    text = PROJECT + ("uncertainty:\n  parameters: {}\n  disturbance: {inputs: [u], bound: 0.5}\n  samples: 0\n"
                      "  runs: 0\n  assertions:\n    - edge: {from: A, to: B, evidence: certified}\n")
    rc, p = verify(tmp_path, text)
    assert rc == 2
    (err,) = [e for e in p.errors if e["code"] == "MPG104"]
    assert err["line"] == len(text.splitlines()) and "uncertainty.assertions.0.edge.evidence" in err["text"]
    assert "sampled scenarios" in err["text"]
