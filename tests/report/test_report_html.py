"""The HTML report renders from the JSON alone, shows every section and escapes all text."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpgspec.report.html import render_html

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"
EVIL = "<script>alert(1)</script>"


@pytest.fixture
def sample_text() -> str:
    return SAMPLE.read_text(encoding="utf-8")


def test_renders_sections(sample_text):
    report = json.loads(sample_text)
    html = render_html(report)
    assert html.startswith("<!DOCTYPE html>")
    assert "<svg" in html
    for p in report["primitives"]:
        assert p["name"] in html
    for label in ("certified", "simulated", "empirical"):
        assert label in html
    assert "Every edge here is" in html
    for s in ("□", "○", "◇", "Lookup table", "naive execution", "graph execution", "oracle_calls"):
        assert s in html
    assert html.count("<details") >= len(report["transitions"])


def test_self_contained(sample_text):
    html = render_html(json.loads(sample_text))
    assert "<script" not in html and "<link" not in html and "src=" not in html


def test_escapes_primitive_names(sample_text):
    report = json.loads(sample_text.replace('"Hang"', json.dumps(EVIL)).replace("Hang ->", f"{EVIL} ->"))
    html = render_html(report)
    assert "<script" not in html
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_without_sequence_or_failures(sample_text):
    report = json.loads(sample_text)
    report["sequence"], report["failures"] = None, []
    report["failures"] = [{**json.loads(sample_text)["failures"][0], "series": {"error": "diverged"}}]
    html = render_html(report)
    assert "diverged" in html and 'id="sequence"' not in html
