"""The units of work tests/conftest.py hands to pytest-xdist: every module that uses the shared
compiled A1 is in the A1's unit (else a second worker compiles it again), and the cost table names
modules that exist (else a renamed slow module silently loses its place at the front)."""
import importlib.util
import re
from pathlib import Path

TESTS = Path(__file__).parent
ROOT = TESTS.parent


def _conftest():
    spec = importlib.util.spec_from_file_location("tests_conftest", TESTS / "conftest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _modules():
    """Test module path -> source, this one left out (it names the fixture)."""
    return {p.relative_to(ROOT).as_posix(): p.read_text() for p in TESTS.rglob("test_*.py") if p != Path(__file__)}


def test_every_module_using_the_shared_a1_is_in_its_unit():
    c = _conftest()
    shared = re.compile(r"\ba1_project\b")
    rigid = re.compile(r"def test_\w+\([^)]*\ba1\b")  # tests/rigidbody's `a1` is a1_project
    users = {m for m, text in _modules().items()
             if shared.search(text) or (m.startswith("tests/rigidbody/") and rigid.search(text))}
    assert "tests/gait/test_walk.py" in users and "tests/robust/test_robust_events.py" in users
    assert {m: c._unit(m) for m in users} == dict.fromkeys(users, c.A1_GROUP)
    assert c._unit("tests/test_anymal_project.py::test_project_verifies") == "tests/test_anymal_project.py"
    # the page check's A1 verify runs beside the A1's unit, to find its libraries compiled
    assert c._unit("tests/report/test_browser.py::test_report_in_chromium[a1-1400]") == c.A1_GROUP


def test_the_cost_table_names_existing_modules():
    c = _conftest()
    assert set(c.COST) <= set(_modules())
