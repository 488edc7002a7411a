"""The example projects of specs/ that run in seconds pass their own assertions."""
from pathlib import Path

import pytest

from mpgspec import api

SPECS = Path(__file__).parents[1] / "specs"


@pytest.mark.parametrize("name", ["pendulum", "cart", "ladder"])
def test_example_project_passes(example, name):
    res = example(name)
    p = res.projects[0]
    assert p.status == "pass", [a for a in p.report["assertions"] if a["status"] != "pass"]
    assert res.exit_code == 0


def test_cart_radii_are_certified(example):
    p = example("cart").projects[0]
    levels = {q["name"]: (q["roa_level"], q["roa_radius"]) for q in p.report["primitives"]}
    assert levels["ParkA"][0] == levels["ParkB"][0] == "certified"
    assert levels["ParkA"][1] > 0.3
    assert levels["Shuttle"][0] == "empirical"


def test_every_edge_has_its_verified_switch_over_time(example):
    r = example("pendulum").projects[0].report
    assert len(r["edge_traces"]) == len(r["edges"])
    for e in r["edge_traces"]:
        s = e["series"]
        assert e["reason"] == "entered_E"
        k = next(i for i, t in enumerate(s["t"]) if t >= e["t_stop"] - 1e-9)
        assert s["roa_margin"][k] > 0  # inside E at the reported time
        assert all(v is None or v >= 0 for vs in s["h"].values() for v in vs[:k + 1])  # safe until then
        assert s["h_count"] >= len(s["h"]) and all(v >= 0 for v in s["h_least"][:k + 1])  # every function, not only those kept
