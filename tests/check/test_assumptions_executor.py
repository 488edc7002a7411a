"""The Definition 1 checks through an executor's map: the same checks in this process and on a pool,
from the memo the second time, and a primitive whose checks raise raises."""
from __future__ import annotations

from pathlib import Path

import pytest

from mpgspec.api import compile_project
from mpgspec.check import severity
from mpgspec.check.severity import check_assumptions
from mpgspec.oracle.executors import InProcess, ProcessPool
from mpgspec.spec.loader import load_project

PENDULUM = Path(__file__).parents[2] / "specs" / "pendulum" / "project.yaml"


class _Memo:
    """The memo's interface (key, get, put) on a dict."""

    def __init__(self):
        self.kept = {}

    def key(self, *parts):
        return parts

    def get(self, key):
        return self.kept.get(key)

    def put(self, key, value):
        self.kept[key] = value


def _dicts(checks):
    return [c.to_dict() for c in checks]


def test_same_checks_in_process_on_a_pool_and_from_the_memo():
    prims = compile_project(load_project(PENDULUM))
    here = _dicts(check_assumptions(prims, {}, executor=InProcess()))
    assert here and {c["primitive"] for c in here} == set(prims)
    assert _dicts(check_assumptions(prims, {}, executor=ProcessPool(2))) == here
    memo, seen = _Memo(), []
    assert _dicts(check_assumptions(prims, {}, memo)) == here
    assert len(memo.kept) == len(prims)
    assert _dicts(check_assumptions(prims, {}, memo, progress=lambda *a: seen.append(a))) == here
    assert not seen  # every primitive came from the memo: nothing was mapped


def test_a_check_that_raises_raises(monkeypatch):
    prims = compile_project(load_project(PENDULUM))

    def broken(p):
        raise ValueError("no such thing")

    monkeypatch.setattr(severity, "check_primitive", broken)
    with pytest.raises(RuntimeError, match="no such thing"):
        check_assumptions(prims, {})
