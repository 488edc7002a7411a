"""The compiled A1 and the verified examples shared by the modules that test them unedited, and the
order in which the test modules are handed to pytest-xdist's workers.

a1_project: specs/a1 loaded and compiled once per test process (its eight closed loops); the oracle
chunks compiled for it are remembered on the primitives, so each later module reuses them instead
of generating the same C code again. example(name): the in-process verify of specs/<name> that several
modules read (the pendulum's report, its edges, the cart's radii), run once per test process.

Scheduling (pyproject.toml runs `--dist loadfile --no-loadscope-reorder`): every module is one unit
of work, so its module-scoped fixtures are built on one worker only, and the modules that use
a1_project (A1_MODULES) form one unit, so the A1 is compiled once per run. Units are queued longest
first (COST: seconds of a cold run, relative) so that the two workers finish together instead of one
running a long module alone at the end. (xdist_group marks cannot merge modules: pytest-xdist 3.8
renames the items through an attribute pytest 9 no longer reads.)
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from a1_lie import pd_lie as _pd_lie
from mpgspec.api import compile_project, settings_for
from mpgspec.spec.loader import load_project

SPECS = Path(__file__).parents[1] / "specs"
A1 = SPECS / "a1" / "project.yaml"
A1_GROUP = "a1"
A1_MODULES = ("tests/gait/", "tests/rigidbody/", "tests/robust/test_robust_events.py", "tests/oracle/test_looplib.py",
              "tests/report/test_browser.py")
"""The modules (by path prefix) whose tests use a1_project, and the page check, whose A1 verify then
finds the A1's loop, jump and robot libraries in the compile cache: one unit of work, so the A1 is
compiled once per run (a module here that does not use a1_project only runs on the same worker)."""

COST = {
    "tests/report/test_browser.py": 185, "tests/oracle/test_executors.py": 121, "tests/test_anymal_project.py": 93,
    "tests/oracle/test_adversarial.py": 87, "tests/gait/test_walk.py": 59, "tests/robust/test_robust_events.py": 56,
    "tests/oracle/test_event_windows.py": 48, "tests/oracle/test_pieces.py": 46, "tests/test_cli.py": 45,
    "tests/oracle/test_cache_integrity.py": 36, "tests/robust/test_robust_rigid.py": 33,
    "tests/robust/test_robust_map.py": 33, "tests/oracle/test_looplib.py": 28, "tests/robust/test_robust.py": 27,
    "tests/gait/test_jump_land.py": 26, "tests/validated/test_validated_adversarial.py": 26,
    "tests/test_cli_channels.py": 24, "tests/verifiers/test_roa_level_set.py": 23,
    "tests/execute/test_crosscheck.py": 22, "tests/gait/test_walk_edges.py": 21,
    "tests/execute/test_crosscheck_variants.py": 20, "tests/rigidbody/test_robot_library.py": 19,
    "tests/validated/test_validated_oracle.py": 19, "tests/oracle/test_executor_map.py": 16,
    "tests/rigidbody/test_contact_events.py": 15, "tests/rigidbody/test_a1_project.py": 15,
    "tests/oracle/test_soundness.py": 14, "tests/oracle/test_backend_plugin.py": 14,
    "tests/rigidbody/test_robust_loop_parts.py": 14, "tests/report/test_report_fuzz.py": 13,
    "tests/oracle/test_held_control.py": 12, "tests/graph/test_trace_memo.py": 12, "tests/spec/test_fuzz.py": 12,
    "tests/verifiers/test_roa_executor.py": 10,
}
"""Seconds per module (pytest --durations) in a cold run of the whole suite on 2 cores, those of 10 s or more
(only their order matters)."""


@pytest.fixture(scope="session")
def a1_project():
    """(spec, primitives, settings) of specs/a1; callers that edit the primitives' dict copy it."""
    spec = load_project(A1)
    return spec, compile_project(spec), settings_for(spec)


@pytest.fixture(scope="session")
def pd_lie():
    """pd_lie(folder): the Lie of a copy of specs/a1 runs the paper's joint PD (tests/a1_lie.py)."""
    return _pd_lie


@pytest.fixture(scope="session")
def a1_pd_lie(tmp_path_factory):
    """(spec, primitives, settings) of specs/a1 with Lie under the paper's joint PD (_pd_lie), the other
    primitives left out (the spec's assertions, sequence and uncertainty still name them: for reading the
    compiled Lie, the A1's continuous law on four grounded feet, not for a build)."""
    import dataclasses

    dst = tmp_path_factory.mktemp("pd_lie") / "a1"
    shutil.copytree(A1.parent, dst)
    _pd_lie(dst)
    spec = load_project(dst / "project.yaml")
    spec = dataclasses.replace(spec, primitives=[p for p in spec.primitives if p.name == "Lie"])
    return spec, compile_project(spec), settings_for(spec)


@pytest.fixture(scope="session")
def example():
    """name -> api.verify([specs/<name>], out_dir=None), run once per test process for every module
    that checks the unedited example in this process (callers only read the result)."""
    from mpgspec import api

    runs: dict = {}

    def verified(name: str):
        if name not in runs:
            runs[name] = api.verify([SPECS / name], out_dir=None)
        return runs[name]

    return verified


def _unit(nodeid: str) -> str:
    """The unit of work a test belongs to: A1_GROUP for A1_MODULES, else its module."""
    module = nodeid.split("::", 1)[0]
    return A1_GROUP if module.startswith(A1_MODULES) else module


def pytest_collection_modifyitems(config, items):
    """Under xdist, units longest first (the controller queues them in the order collected)."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return  # one process runs everything: keep the files' order
    cost: dict[str, float] = {}
    for module in {item.nodeid.split("::", 1)[0] for item in items}:
        cost[_unit(module)] = cost.get(_unit(module), 0.0) + COST.get(module, 0.0)
    first: dict[str, int] = {}
    for k, item in enumerate(items):
        first.setdefault(_unit(item.nodeid), k)
    order = {id(item): (-cost[_unit(item.nodeid)], first[_unit(item.nodeid)], k) for k, item in enumerate(items)}
    items.sort(key=lambda item: order[id(item)])


def pytest_xdist_make_scheduler(config, log):
    """--dist loadfile with the A1 modules merged into one unit."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class ModuleScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _unit(nodeid)

    return ModuleScheduling(config, log)


def _fixed(name: str, u: str, h: str, radius) -> str:
    return (f"  - name: {name}\n    class: fixed\n    setpoint: {{expr: [0]}}\n"
            f"    controller: {{type: expression, u: [\"{u}\"]}}\n"
            f"    safe_set: [{{name: wall, h: \"{h}\"}}]\n    roa: {{radius: {radius}}}\n")


@pytest.fixture
def line_spec():
    """A project on the line x' = x + u (|u| <= bound): line_spec(project, bound, primitives, tail) with
    primitives as (name, u, h, radius) of fixed primitives at x* = 0, and tail the YAML after them."""
    def make(project: str, bound: float, prims: list[tuple], tail: str = "") -> str:
        head = (f"project: {project}\nsystem:\n  name: line\n  kind: analytic\n  states: [x]\n  inputs: [u]\n"
                f"  dynamics: {{f: [\"x\"], g: [[1]]}}\n  input_bounds: {{u: [-{bound}, {bound}]}}\nprimitives:\n")
        return head + "".join(_fixed(*p) for p in prims) + tail
    return make
