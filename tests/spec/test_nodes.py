"""`nodes:` sets keys of one node of a primitive family (an argument's label, as in Swing(2)): its
entry merges into the family's keys for that node only, and a wrong entry is a located spec error."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from mpgspec.errors import SpecErrors
from mpgspec.spec.loader import load_project

PENDULUM = Path(__file__).parents[2] / "specs" / "pendulum"


def _pendulum(tmp_path: Path, nodes: str) -> Path:
    """A copy of specs/pendulum whose Swing family carries `nodes` (YAML text of the mapping)."""
    d = tmp_path / "pendulum"
    shutil.copytree(PENDULUM, d)
    swing = d / "primitives" / "swing.yaml"
    text = swing.read_text()
    assert "arguments: {amp: [1.0, 2.0, 2.6]}\n" in text
    swing.write_text(text.replace("arguments: {amp: [1.0, 2.0, 2.6]}\n",
                                  f"arguments: {{amp: [1.0, 2.0, 2.6]}}\nnodes: {nodes}\n"))
    return d / "project.yaml"


def _nodes(project: Path) -> dict:
    return {i.name: i for i in load_project(project).primitives}


def test_a_node_entry_merges_into_its_node_only(tmp_path):
    plain = _nodes(PENDULUM / "project.yaml")
    nodes = _nodes(_pendulum(tmp_path, "{'2': {controller: {kp: [20]}, roa: {radius: 0.1}}}"))
    two, one = nodes["Swing(2)"].spec, nodes["Swing(1)"].spec
    assert two.controller.kp == [20] and two.controller.kd == plain["Swing(2)"].spec.controller.kd  # merged
    assert two.roa.radius == 0.1 and two.roa.method == plain["Swing(2)"].spec.roa.method
    assert two.roa.options == plain["Swing(2)"].spec.roa.options
    assert one == plain["Swing(1)"].spec and nodes["Swing(2.6)"].spec == plain["Swing(2.6)"].spec
    assert not two.nodes and not one.nodes  # a node's spec is its own: the family's entries are not carried
    assert two.model_copy(update={"controller": plain["Swing(2)"].spec.controller, "roa": plain["Swing(2)"].spec.roa}) \
        == plain["Swing(2)"].spec


def test_a_key_a_node_sets_is_located_in_its_entry(tmp_path):
    project = _pendulum(tmp_path, "{'2': {roa: {radius: 0.1}}}")
    node = _nodes(project)["Swing(2)"]
    where = node.locate(("roa", "radius"))
    assert where.file.endswith("swing.yaml") and where.line == 7  # the nodes line, not the family's roa
    assert node.locate(("controller", "kp")).line > 7  # a key the node does not set: the family's


@pytest.mark.parametrize("nodes, says, line", [
    ("{'3': {roa: {radius: 0.1}}}", "no node of that label", 7),
    ("{'2': {name: Other}}", "a node cannot set this key", 7),
    ("{'2': {roa: {radius: -1}}}", "greater than 0", 7),
    ("{'2': {controller: {kp: [1, 2]}}}", "one gain per output", 7),
])
def test_a_wrong_node_entry_is_a_located_error(tmp_path, nodes, says, line):
    with pytest.raises(SpecErrors) as err:
        load_project(_pendulum(tmp_path, nodes))
    errors = err.value.errors
    hit = [e for e in errors if says in e.format()]
    assert hit, [e.format() for e in errors]
    assert hit[0].location is not None and hit[0].location.file.endswith("swing.yaml") and hit[0].location.line == line


def test_nodes_need_arguments(tmp_path):
    d = tmp_path / "pendulum"
    shutil.copytree(PENDULUM, d)
    hang = d / "primitives" / "hang.yaml"
    hang.write_text(hang.read_text() + "nodes: {a: {roa: {radius: 0.1}}}\n")
    with pytest.raises(SpecErrors) as err:
        load_project(d / "project.yaml")
    assert any("needs 'arguments'" in e.format() for e in err.value.errors)


def test_a_numeric_label_is_written_as_the_node_name_writes_it(tmp_path):
    nodes = _nodes(_pendulum(tmp_path, "{2.6: {roa: {radius: 0.1}}, 2: {roa: {radius: 0.12}}}"))
    assert nodes["Swing(2.6)"].spec.roa.radius == 0.1 and nodes["Swing(2)"].spec.roa.radius == 0.12
    assert nodes["Swing(1)"].spec.roa.radius == 0.15
