"""A sequence run counts every violating sample (violation_totals), not only the first 50 it records."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mpgspec import api

TINY = Path(__file__).resolve().parents[1] / "fixtures" / "cli_tiny"


def test_every_violating_sample_is_counted():
    p = api.verify(TINY)["tiny"]
    run = p.simulate("naive")  # switches Left -> Right at 0.5 s, where right_floor (x >= 0.4) is violated
    assert run.t[1] - run.t[0] == p.compiled.settings.dt  # every sample stored: the count can be checked
    x = np.array([r[0] for r in run.x])
    active = np.array(run.active)
    tol = p.compiled.settings.h_tolerance
    bad = (active == "Right") & (x - 0.4 < -tol)
    tot = {(v["primitive"], v["h"]): v for v in run.violation_totals}
    floor = tot[("Right", "right_floor")]
    assert floor["samples"] == int(bad.sum()) > 0
    assert floor["first"] == run.t[int(np.argmax(bad))] and floor["last"] == run.t[len(bad) - 1 - int(np.argmax(bad[::-1]))]
    assert floor["least"] == float((x[bad] - 0.4).min())
    assert set(tot) == {(v["primitive"], v["h"]) for v in run.violations}
    stored = p.report["sequence"]["runs"]["naive"]["violation_totals"]
    assert [(v["primitive"], v["h"], v["samples"]) for v in stored] == \
        [(v["primitive"], v["h"], v["samples"]) for v in run.violation_totals]
