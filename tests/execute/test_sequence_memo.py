"""The goal-sequence runs kept between verifies are taken again only when everything that decides them is
unchanged: the closed loops, the sequence, and the project's oracle block and its primitives' roa.boundary_samples,
whose counts decide the share of E_A each switch of the graph run was checked from."""
from __future__ import annotations

from pathlib import Path

from mpgspec import api
from mpgspec.oracle.executors import make_executor
from mpgspec.pipeline import stages

ROOT = Path(__file__).parents[2]


def test_a_changed_from_roa_runs_the_sequence_again(tmp_path, monkeypatch):
    monkeypatch.setenv("MPGSPEC_CACHE", str(tmp_path / "cache"))
    calls = []
    real = stages._simulated

    def counted(shared, mode):
        calls.append(mode)
        return real(shared, mode)

    monkeypatch.setattr(stages, "_simulated", counted)
    project = tmp_path / "pendulum"
    project.mkdir()
    for f in (ROOT / "specs" / "pendulum").rglob("*.yaml"):
        (project / f.relative_to(ROOT / "specs" / "pendulum")).parent.mkdir(parents=True, exist_ok=True)
        (project / f.relative_to(ROOT / "specs" / "pendulum")).write_text(f.read_text())
    run = lambda: api.verify([project], out_dir=None, executor=make_executor(1, cache=True))  # noqa: E731
    run()
    assert sorted(calls) == ["graph", "naive"]
    run()
    assert len(calls) == 2  # nothing changed: both runs from the memo
    text = (project / "project.yaml").read_text()
    assert "\noracle:\n" in text
    (project / "project.yaml").write_text(text.replace("\noracle:\n", "\noracle:\n  from_roa: 4\n", 1))
    run()
    assert len(calls) == 4  # the graph run follows shares checked from E_A's boundary now: both run again
    hang = project / "primitives" / "hang.yaml"
    text = hang.read_text()
    assert "roa: {radius: 0.15, method: lyapunov}" in text
    hang.write_text(text.replace("roa: {radius: 0.15, method: lyapunov}",
                                 "roa: {radius: 0.15, method: lyapunov, boundary_samples: 6}"))
    run()
    assert len(calls) == 6  # switches out of Hang checked from 6 samples: both run again
