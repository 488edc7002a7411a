"""`mpgspec schema --kind project|primitive|system`: every example spec file validates against the
schema of its kind, the schemas carry $schema, $id and descriptions, and a wrong key is caught."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from mpgspec.cli import main
from mpgspec.spec.schema import KINDS, spec_schema

jsonschema = pytest.importorskip("jsonschema")
SPECS = Path(__file__).resolve().parents[2] / "specs"


def _spec_files() -> dict[Path, str]:
    """Every project file under specs/ (project.yaml) and the primitive and system files it
    names, with their kind."""
    out = {}
    for proj in sorted(SPECS.rglob("project.yaml")):
        out[proj] = "project"
        doc = yaml.safe_load(proj.read_text(encoding="utf-8"))
        if isinstance(doc.get("system"), str):
            out[proj.parent / doc["system"]] = "system"
        for p in doc.get("primitives", []):
            if isinstance(p, str):
                out[proj.parent / p] = "primitive"
    return out


FILES = _spec_files()
EXAMPLES = sorted(FILES)


def _kind(path: Path) -> str:
    return FILES[path]


@pytest.fixture(scope="module")
def validators() -> dict:
    return {k: jsonschema.Draft202012Validator(spec_schema(k)) for k in KINDS}


@pytest.mark.parametrize("path", EXAMPLES, ids=[str(p.relative_to(SPECS)) for p in EXAMPLES])
def test_example_spec_files_validate(path, validators):
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    errors = sorted(validators[_kind(path)].iter_errors(doc), key=lambda e: list(e.path))
    assert not errors, "\n".join(f"{'/'.join(map(str, e.path))}: {e.message}" for e in errors[:5])


@pytest.mark.parametrize("kind", KINDS)
def test_schemas_are_complete(kind, validators):
    s = spec_schema(kind)
    jsonschema.Draft202012Validator.check_schema(s)
    assert s["$schema"].endswith("2020-12/schema") and s["$id"].endswith(f"{kind}.json")
    text = json.dumps(s)
    assert "discriminator" not in text

    def props(node):
        if isinstance(node, dict):
            for name, sub in (node.get("properties") or {}).items():
                yield name, sub
            for v in node.values():
                yield from props(v)
        elif isinstance(node, list):
            for v in node:
                yield from props(v)

    missing = [n for n, sub in props(s) if isinstance(sub, dict) and not sub.get("description")]
    assert not missing


@pytest.mark.parametrize("when, valid", [
    ([0.5, 1.0], True),
    ({"before": "first_touchdown"}, True),
    ({"after": "takeoff", "delay": 0.02, "for": 0.01}, True),
    ({"after": "touchdown"}, False),  # not an event
    ({"after": "takeoff", "for": 0}, False),  # an empty window
    ({"for": 0.01}, False),  # anchored on nothing
])
def test_windows_anchored_on_contact_events(validators, when, valid):
    doc = yaml.safe_load((SPECS / "pendulum" / "primitives" / "hang.yaml").read_text())
    doc["safe_set"] = [{"name": "h", "h": "1", "when": when}]
    assert (not list(validators["primitive"].iter_errors(doc))) is valid


def test_a_misspelled_key_is_invalid(validators):
    doc = yaml.safe_load((SPECS / "pendulum" / "primitives" / "hang.yaml").read_text())
    doc["controller"]["kdd"] = doc["controller"].pop("kd")
    assert list(validators["primitive"].iter_errors(doc))


@pytest.mark.parametrize("kind", KINDS + ("report",))
def test_cli_prints_each_schema(capsys, kind):
    assert main(["schema", "--kind", kind]) == 0
    s = json.loads(capsys.readouterr().out)
    assert "$id" in s and "$schema" in s
