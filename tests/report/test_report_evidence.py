"""How a transition's evidence reaches report.json, the HTML page and the graph exports: certified only
when every cell the verdict rests on was proved, each cell's method stored, the t_A intervals proved
for every t_A kept unrounded and never shown wider than proved."""
from __future__ import annotations

import json
import re
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from pydantic import ValidationError

from mpgspec.graph import Transition
from mpgspec.oracle import OracleEvidence, Reason
from mpgspec.report.build import transition_entry
from mpgspec.report.compact import expand_cells
from mpgspec.report.export import to_dot, to_networkx
from mpgspec.report.html import render_html
from mpgspec.report.proved import interval_text
from mpgspec.report.schema import validate_report

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
PROVED = {"windows": [[0.1, 1.2345678]], "boxes": 12, "order": 6, "width": 0.01, "time_s": 3.25}


def ev(verdict: int, method: str) -> OracleEvidence:
    if verdict:
        return OracleEvidence(1, Reason.ENTERED_E, 0.5, t_enter=0.5, min_margins={"wall": 0.3}, method=method)
    return OracleEvidence(0, Reason.LEFT_C, 0.2, violated="wall", min_margins={"wall": -0.1}, method=method)


def entry(rows, certified: dict | None = None) -> dict:
    tr = Transition("A", "B", np.array([0.0, 1.0]), np.array([0.0, 0.5]), rows, certified=dict(certified or {}))
    tr.classify()
    return transition_entry(tr, ["wall"])


@pytest.fixture
def sample() -> dict:
    return json.loads(SAMPLE.read_text(encoding="utf-8"))


# ----------------------------------------------------------------------------- report.json
def test_an_edge_is_certified_only_when_every_safe_cell_is_proved():
    proved = entry([[ev(1, "certified"), ev(0, "simulated")], [ev(0, "validated"), ev(1, "certified")]], PROVED)
    mixed = entry([[ev(1, "certified"), ev(0, "certified")], [ev(1, "simulated"), ev(0, "certified")]])
    assert (proved["class"], proved["method"], mixed["class"], mixed["method"]) == (1, "certified", 1, "simulated")
    assert proved["cells"]["method"] == ["10", "21"] and mixed["cells"]["method"] == ["11", "01"]
    assert {k: proved["counts"][k] for k in ("safe", "certified", "certified_safe")} == \
        {"safe": 2, "certified": 2, "certified_safe": 2}
    assert {k: mixed["counts"][k] for k in ("safe", "certified", "certified_safe")} == \
        {"safe": 2, "certified": 3, "certified_safe": 1}
    assert [[c["method"] for c in row] for row in expand_cells(mixed)] == [["certified", "certified"],
                                                                          ["simulated", "certified"]]


def test_a_pair_without_an_edge_is_certified_only_when_every_cell_is_proved():
    assert entry([[ev(0, "certified")] * 2] * 2)["method"] == "certified"
    assert entry([[ev(0, "certified"), ev(0, "validated")]] * 2)["method"] == "simulated"


def test_the_proved_intervals_are_kept_unrounded_and_null_without_a_proof():
    assert entry([[ev(1, "certified")] * 2] * 2, PROVED)["certified"] == PROVED
    assert entry([[ev(1, "certified")] * 2] * 2)["certified"] is None


def test_the_schema_takes_the_new_fields_and_still_takes_a_2_0_report(sample):
    validate_report(sample)  # written by 2.0: no cells.method, counts.certified or certified
    sample["transitions"][0] = entry([[ev(1, "certified"), ev(0, "simulated")], [ev(1, "certified")] * 2], PROVED)
    validate_report(sample)
    for broken in ({**PROVED, "windows": [[0.1]]}, {k: v for k, v in PROVED.items() if k != "order"},
                   {**PROVED, "boxes": -1}):
        bad = json.loads(json.dumps(sample))
        bad["transitions"][0]["certified"] = broken
        with pytest.raises(ValidationError):
            validate_report(bad)
    bad = json.loads(json.dumps(sample))
    bad["transitions"][0]["cells"]["method"] = ["10"]  # one row short
    with pytest.raises(ValidationError, match="method of A -> B"):
        validate_report(bad)


def test_cells_of_a_2_0_report_read_as_simulated(sample):
    assert {c["method"] for t in sample["transitions"] for row in expand_cells(t) for c in row} == {"simulated"}


@pytest.mark.parametrize("a, b", [(0.1, 1.2345678), (-0.123456, 0.98765), (3.00004e-4, 7.99996), (2.5, 2.5)])
def test_a_proved_interval_is_written_rounded_inwards(a, b):
    lo, hi = (float(v) for v in re.fullmatch(r"\[(\S+), (\S+)\]", interval_text(a, b)).groups())
    assert a <= lo <= hi <= b


# ----------------------------------------------------------------------------- page and exports
def _certify_first_edge(sample: dict) -> tuple[str, str]:
    """The sample with its first edge's transition certified over [0.1, 1.2345678]; its (from, to)."""
    e = sample["edges"][0]
    tr = next(t for t in sample["transitions"] if (t["from"], t["to"]) == (e["from"], e["to"]))
    tr["method"], tr["certified"] = "certified", PROVED
    return e["from"], e["to"]


def _edge_row(html: str, a: str, b: str) -> str:
    table = html[html.index('<section id="edges">'):]
    return next(r for r in table.split("<tr") if r.startswith(f' class=""><td>{a}</td><td>{b}</td>')
                or r.startswith(f' class="unusable"><td>{a}</td><td>{b}</td>'))


def test_the_page_shows_each_edges_evidence_and_what_was_proved(sample):
    a, b = _certify_first_edge(sample)
    html = render_html(sample)
    row = _edge_row(html, a, b)
    assert '<span class="ev certified">certified</span>' in row
    assert "certified for every t_A in [0.1, 1.234] s" in row  # 1.2345678 rounded down, never up
    other = sample["edges"][1]
    row = _edge_row(html, other["from"], other["to"])
    assert '<span class="ev simulated">simulated</span>' in row and "certified" not in row
    assert "Every edge here is" not in html and "A <span class=\"ev certified\">certified</span> edge" in html


def test_a_simulated_edge_says_how_many_of_its_safe_cells_are_proved(sample):
    e = sample["edges"][0]
    tr = next(t for t in sample["transitions"] if (t["from"], t["to"]) == (e["from"], e["to"]))
    j, nb = tr["verdicts"][0].index(1), len(tr["t_B"])  # the first safe cell proved, the others not
    tr["cells"]["method"] = ["0" * j + "1" + "0" * (nb - j - 1)] + ["0" * nb] * (len(tr["t_A"]) - 1)
    assert tr["counts"]["safe"] > 1
    row = _edge_row(render_html(sample), e["from"], e["to"])
    assert '<span class="ev simulated">simulated</span>' in row and "ev certified" not in row
    assert f"1 of {tr['counts']['safe']} safe cells certified" in row


def test_the_exports_carry_the_evidence(sample):
    a, b = _certify_first_edge(sample)
    line = next(ln for ln in to_dot(sample).splitlines() if ln.strip().startswith(f'"{a}" -> "{b}"'))
    assert "certified, " in line and "certified for every t_A in [0.1, 1.234]" in line
    G = to_networkx(sample)
    assert G.edges[a, b]["method"] == "certified" and G.edges[a, b]["certified_windows"] == "[0.1, 1.2345678]"
    others = [d for u, v, d in G.edges(data=True) if (u, v) != (a, b)]
    assert others and all(d["method"] == "simulated" and "certified_windows" not in d for d in others)
    assert "\n".join(nx.generate_graphml(G))  # scalar attributes only
