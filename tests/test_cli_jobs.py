"""The default of `verify -j`: the usable cores; -j 1 keeps everything in this process."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.cli import main
from mpgspec.cores import usable_cores
from mpgspec.oracle.executors import InProcess, ProcessPool, make_executor

TINY = Path(__file__).parent / "fixtures" / "cli_tiny" / "project.yaml"


@pytest.fixture()
def asked(monkeypatch):
    """The jobs each `verify` asked api.executor for (run in this process all the same)."""
    seen = []

    def record(jobs=1, dask=None, cache=True):
        seen.append(jobs)
        return InProcess()

    monkeypatch.setattr(api, "executor", record)
    return seen


def test_default_jobs_are_the_usable_cores(asked):
    assert main(["verify", str(TINY), "-q", "--no-write"]) == 0
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert asked == [cores] == [usable_cores()]


def test_one_job_is_asked_for_with_j1(asked):
    assert main(["verify", str(TINY), "-q", "--no-write", "-j", "1"]) == 0
    assert asked == [1]


def test_help_states_the_default(capsys):
    assert main(["verify", "--help"]) == 0
    assert "default: the number of usable cores" in " ".join(capsys.readouterr().out.split())


def test_make_executor_caps_jobs_at_the_usable_cores():
    ex = make_executor(64)
    assert isinstance(ex, ProcessPool if usable_cores() > 1 else InProcess)
    assert ex.workers == usable_cores()
