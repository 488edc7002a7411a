"""An oracle backend from outside mpgspec/ and verifiers/, installed through the entry-point group.

The backend below is a thin wrapper that counts the start points it is given and delegates to the
rk4 backend. A temporary dist-info directory on sys.path declares it under `mpgspec.verifiers`,
the way a third-party package would; a copy of the pendulum project selects it by `oracle.method`
and mpgspec.api verifies the project with it, giving the same graph as rk4. A backend that does
not implement the contract is refused with an error naming its entry point.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from mpgspec import api
from mpgspec.errors import UsageError
from mpgspec.oracle import registry
from mpgspec.oracle.backend import BackendError, OracleBackend
from mpgspec.oracle.executors import InProcess
from verifiers.rk4 import backend as rk4

ROOT = Path(__file__).parents[2]
CALLS: list[int] = []


class CountingRunner:
    """Counts the start points, then lets the rk4 runner evaluate them."""

    def __init__(self, inner):
        self.inner = inner

    def evaluate(self, x0s, t0s, horizons):
        CALLS.append(len(t0s))
        return self.inner.evaluate(x0s, t0s, horizons)


class CountingBackend:
    name = "counted"
    description = "rk4, counting the start points it is given (a test plug-in)"
    capabilities = rk4.capabilities

    @staticmethod
    def is_installed() -> bool:
        return True

    @staticmethod
    def runner(prim, settings):
        return CountingRunner(rk4.runner(prim, settings))


class NoRunner:
    name = "norunner"
    description = "a backend without a runner"
    capabilities = frozenset()

    @staticmethod
    def is_installed() -> bool:
        return True


backend = CountingBackend()
broken = NoRunner()


def install(site: Path, monkeypatch, **targets: str) -> None:
    """A distribution in `site` whose entry points declare `targets` (name -> module:attr) as backends."""
    dist = site / "mpgspec_test_backend-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: mpgspec-test-backend\nVersion: 0.1\n")
    lines = [f"{name} = {target}" for name, target in targets.items()]
    (dist / "entry_points.txt").write_text("[mpgspec.verifiers]\n" + "\n".join(lines) + "\n")
    monkeypatch.syspath_prepend(str(site))


@pytest.fixture
def fresh_registry():
    registry.backends.cache_clear()
    yield
    registry.backends.cache_clear()


def _graph(report: dict) -> str:
    """Verdicts, edges and failed pairs, and each assertion's outcome (its location is the copy's)."""
    outcomes = [(a["description"], a["status"], a["message"]) for a in report["assertions"]]
    return json.dumps([report["verdicts"], report["edges"], report["failures"], outcomes], sort_keys=True)


def test_a_backend_installed_by_entry_point_verifies_the_pendulum(tmp_path, monkeypatch, fresh_registry):
    install(tmp_path / "site", monkeypatch, counted=f"{__name__}:backend")
    assert isinstance(registry.get_backend("counted"), OracleBackend)
    project = tmp_path / "pendulum"
    shutil.copytree(ROOT / "specs" / "pendulum", project)
    text = (project / "project.yaml").read_text()
    (project / "project.yaml").write_text(text.replace("oracle:\n", "oracle:\n  method: counted\n", 1))
    CALLS.clear()
    (mine,) = api.verify([project], out_dir=None, executor=InProcess()).projects
    assert mine.status == "pass", mine.errors
    assert mine.report["settings"]["method"] == "counted"
    assert sum(CALLS) > 0
    (ref,) = api.verify([ROOT / "specs" / "pendulum"], out_dir=None, executor=InProcess()).projects
    assert _graph(mine.report) == _graph(ref.report)


def test_a_backend_without_a_runner_is_refused_naming_its_entry_point(tmp_path, monkeypatch, fresh_registry):
    install(tmp_path / "site", monkeypatch, norunner=f"{__name__}:broken")
    with pytest.raises(BackendError, match=r"entry point norunner = .*:broken.*lacks method runner\(\)") as err:
        registry.get_backend("rk4")
    assert isinstance(err.value, UsageError)


def test_a_backend_that_cannot_be_imported_is_named_with_its_import_error(tmp_path, monkeypatch, fresh_registry):
    """A declared backend whose module fails to import: the spec error says so, with the import error."""
    from mpgspec.errors import SpecError
    from mpgspec.pipeline.settings import settings_for
    from mpgspec.spec.loader import load_project

    install(tmp_path / "site", monkeypatch, halfway="mpgspec_no_such_module_xyz:backend")
    project = tmp_path / "pendulum"
    shutil.copytree(ROOT / "specs" / "pendulum", project)
    text = (project / "project.yaml").read_text()
    (project / "project.yaml").write_text(text.replace("oracle:\n", "oracle:\n  method: halfway\n", 1))
    with pytest.raises(SpecError) as err:
        settings_for(load_project(project / "project.yaml"))
    msg = str(err.value)
    assert "halfway" in msg and "could not be imported" in msg and "mpgspec_no_such_module_xyz" in msg, msg
