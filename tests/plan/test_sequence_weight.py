"""`sequence.weight`: the lookup table the graph run follows is built with the weight the project
names (as `mpgspec plan --weight`); an unknown weight is a spec error naming the key."""
from __future__ import annotations

import shutil
from pathlib import Path

from mpgspec import api
from mpgspec.cli import main
from mpgspec.plan.planner import lookup_table

TINY = Path(__file__).resolve().parents[1] / "fixtures" / "cli_tiny"


def _with_weight(tmp_path: Path, weight: str) -> Path:
    proj = tmp_path / "tiny"
    shutil.copytree(TINY, proj)
    spec = proj / "project.yaml"
    spec.write_text(spec.read_text().replace("  duration: 6\n", f"  duration: 6\n  weight: {weight}\n"))
    return proj


def test_the_graph_run_follows_the_table_of_the_named_weight(tmp_path):
    p = api.verify(_with_weight(tmp_path, "margin"))["tiny"]
    table = p.report["lookup_table"]
    assert table["weight"] == "margin" and table["next"] == lookup_table(p.mpg, "margin")
    assert p.report["sequence"]["runs"]["graph"]["safe"]


def test_an_unknown_weight_is_a_spec_error(tmp_path, capsys):
    rc = main(["verify", str(_with_weight(tmp_path, "speed")), "--no-write", "-q", "-j", "1"])
    err = capsys.readouterr().err
    assert rc == 2 and "sequence.weight" in err and "project.yaml:" in err and "Traceback" not in err
