"""Fuzzing what `plan` reads back: a verified report.json mutated (leaves replaced by hostile
values, keys deleted or added, as tests/spec/test_fuzz.py mutates specs) and sealed again with
this machine's key, as a bug in a writer or a holder of the key could leave it. `mpgspec plan`
either answers from it or refuses it with a located error (exit 2); never an internal error, and
never a plan through an edge the report does not hold. Fixed budget (MPGSPEC_FUZZ_BUDGET),
derandomised."""
from __future__ import annotations

import copy
import json
import shutil
import sys
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from mpgspec import api  # noqa: E402
from mpgspec.cli import main  # noqa: E402
from mpgspec.errors import MpgError  # noqa: E402
from mpgspec.report.trust import integrity_record  # noqa: E402

sys.path.insert(0, str(Path(__file__).parents[1] / "spec"))
from test_fuzz import BUDGET, MUTATION, _mutate  # noqa: E402

TINY = Path(__file__).parents[1] / "fixtures" / "cli_tiny"


@pytest.fixture(scope="module")
def verified(tmp_path_factory):
    """(project folder, reports folder, report) of the tiny CLI project, verified once."""
    root = tmp_path_factory.mktemp("fuzz_report")
    shutil.copytree(TINY, root / "tiny")
    assert main(["verify", str(root / "tiny"), "--out", str(root / "reports"), "-q"]) == 0
    (path,) = (root / "reports").glob("*/report.json")
    return root / "tiny", path, json.loads(path.read_text())


@settings(max_examples=BUDGET, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4), goal=st.sampled_from(["Mid", "Right", "Left"]))
def test_plan_never_fails_internally_on_a_mutated_report(verified, mutations, goal):
    project, path, report = verified
    doc = copy.deepcopy(report)
    _mutate(doc, mutations)
    if isinstance(doc, dict):
        doc.pop("integrity", None)
        try:
            doc["integrity"] = integrity_record(json.loads(json.dumps(doc)))
        except (TypeError, ValueError):  # a value JSON cannot hold
            return
    try:
        text = json.dumps(doc)
    except (TypeError, ValueError):
        return
    path.write_text(text)
    try:
        out = api.plan(project, "Left", goal, out=path.parents[1])
    except MpgError as err:  # refused: located and printable
        assert err.format()
        return
    finally:
        path.write_text(json.dumps(report))
    held = {(e.get("from"), e.get("to")) for e in doc.get("edges", []) if isinstance(e, dict)}
    if out["path"] is not None:
        assert all((a, b) in held for a, b in zip(out["path"], out["path"][1:])), out
