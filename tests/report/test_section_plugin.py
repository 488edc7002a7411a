"""A report section defined here, outside mpgspec/, registered in-process through the entry-point
group `mpgspec.report_sections` (the way an installed package adds one): its data lands in
report.json under `sections`, checked against its own model, and its template part, its summary line
and its navigation link appear in report.html; without it the report has no `sections` key."""
from __future__ import annotations

import json
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest
from pydantic import BaseModel, ConfigDict, ValidationError

from mpgspec import api
from mpgspec.report.schema import validate_report
from mpgspec.report.sections import ReportSection
from mpgspec.report.sections.registry import GROUP, register, unregister

TINY = Path(__file__).parents[1] / "fixtures" / "cli_tiny" / "project.yaml"


class Tally(BaseModel):
    """The section's schema: how many primitives, edges and oracle calls the graph has."""

    model_config = ConfigDict(extra="forbid")
    primitives: int
    edges: int
    oracle_calls: int


def tally(cp, vg, ch) -> dict:
    """The section's data, from the pipeline's results."""
    return {"primitives": len(cp.prims), "edges": vg.graph.G.number_of_edges(),
            "oracle_calls": int(vg.timing["oracle_calls"])}


section = ReportSection(
    name="tally", data=tally, model=Tally, label="tally", after="sequence",
    template='<section id="tally">\n<h2>Tally</h2>\n<p>{{ s.primitives }} primitives, {{ s.edges }} edges, '
             '{{ s.oracle_calls }} oracle calls ({{ r.project.name }}).</p>\n</section>\n\n',
    count=lambda s: ("tallied edges", s["edges"], "from a plug-in section"))


@pytest.fixture()
def plugin():
    register(EntryPoint("tally", f"{__name__}:section", GROUP))
    yield
    unregister("tally")


def test_a_plugin_section_reaches_report_json_and_html(plugin, tmp_path):
    res = api.verify(TINY, out_dir=tmp_path)["tiny"]
    assert res.status == "pass", res.errors
    report = json.loads(Path(res.files["json"]).read_text(encoding="utf-8"))
    validate_report(report)
    assert report["sections"] == {"tally": {"primitives": 3, "edges": len(report["edges"]),
                                            "oracle_calls": report["timing"]["oracle_calls"]}}
    html = Path(res.files["html"]).read_text(encoding="utf-8")
    assert '<section id="tally">' in html and f"{len(report['edges'])} edges" in html and "(tiny)." in html
    assert '<a href="#tally">tally</a>' in html and "tallied edges" in html
    assert html.index('id="tally"') < html.index('id="evidence"')
    bad = {**report, "sections": {"tally": {"primitives": "three"}}}
    with pytest.raises(ValidationError):
        validate_report(bad)


def test_without_plugins_the_report_has_no_sections_key(tmp_path):
    report = api.verify(TINY)["tiny"].report
    assert "sections" not in report and "robust" in report and "crosscheck" in report
    validate_report(report)
