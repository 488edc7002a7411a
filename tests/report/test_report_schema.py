"""The report schema: the sample validates, mismatches raise, and the committed schema file is current."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from pydantic import ValidationError

from mpgspec.report.schema import report_schema, schema_path, validate_report

SAMPLE = Path(__file__).with_name("data") / "sample_report.json"


@pytest.fixture
def sample() -> dict:
    return json.loads(SAMPLE.read_text(encoding="utf-8"))


def test_sample_validates(sample):
    validate_report(sample)


def test_committed_schema_matches_models():
    committed = json.loads(schema_path().read_text(encoding="utf-8"))
    assert committed == report_schema(), "run: python -m mpgspec.report.schema"


def test_free_form_info_and_settings_accept_extra_keys(sample):
    sample["primitives"][0]["info"] = {"anything": [1, {"nested": None}]}
    sample["settings"]["new_option"] = 3
    validate_report(sample)


@pytest.mark.parametrize("mutate", [
    lambda r: r.pop("edges"),
    lambda r: r.__setitem__("unexpected", 1),
    lambda r: r.__setitem__("status", "maybe"),
    lambda r: r["primitives"][0].__setitem__("class", "looping"),
    lambda r: r["edges"][0].__setitem__("class", 0),
    lambda r: r["transitions"][0]["cells"]["reason"].__setitem__(0, "x"),
    lambda r: r["transitions"][0]["cells"]["margin"].pop(),
    lambda r: r["transitions"][0]["cells"]["min_margins"][0][0].append(1.0),
    lambda r: r["transitions"][0]["cells"].pop("status"),
    lambda r: r.__setitem__("schema_version", "1.0"),
    lambda r: r["transitions"][0].__setitem__("method", "guessed"),
])
def test_mismatch_raises(sample, mutate):
    mutate(sample)
    with pytest.raises(ValidationError):
        validate_report(sample)


def test_schema_uses_report_keys():
    s = report_schema()
    assert s["$id"].endswith("report-v2.json") and "$schema" in s
    assert "from" in s["$defs"]["Edge"]["properties"] and "class" in s["$defs"]["Edge"]["properties"]
    assert s["additionalProperties"] is False
