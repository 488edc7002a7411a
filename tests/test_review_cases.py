"""Cases where an earlier version claimed more than it had verified; each must now come out honest."""
from pathlib import Path

import numpy as np

from mpgspec import api
from mpgspec.check.assumptions import floquet_stability
from mpgspec.oracle.oracle import SafetyOracle
from mpgspec.spec.loader import load_project

CASES = Path(__file__).parent / "fixtures" / "review"


def test_transient_hand_over_must_be_verified_at_the_end_of_its_domain():
    """Ramp -> Target is verified only from interior t_A; at t_f the flow leaves Target's floor."""
    p = api.verify([CASES / "transient_handover.yaml"], out_dir=None).projects[0]
    by_kind = {a["kind"]: a for a in p.report["assertions"]}
    assert by_kind["plan"]["status"] == "fail"  # no plan may go through the unverified hand-over
    assert "Ramp" not in (by_kind["plan"]["message"])


def test_transient_oracle_stops_at_the_end_of_its_domain():
    """E is reached only 0.005 s after t_f = 1.005: not a transition."""
    spec = load_project(CASES / "transient_horizon.yaml")
    prims = api.compile_project(spec)
    ev = SafetyOracle(prims["B"], api.settings_for(spec))(np.array([1.0]), 0.0)
    assert ev.verdict == 0 and ev.t_stop <= 1.005 + 1e-12


def test_nan_safety_values_and_blow_ups_are_unsafe_in_execution():
    p = api.verify([CASES / "nan_monitor.yaml"], out_dir=None).projects[0]
    naive = p.report["sequence"]["runs"]["naive"]
    assert naive["safe"] is False
    assert naive["violations"][0]["h"] == "nonneg"


def test_floquet_check_sets_aside_the_trivial_multiplier_not_the_largest():
    spec = load_project(CASES / "floquet.yaml")
    orbit = api.compile_project(spec)["Orbit"]
    c = floquet_stability(orbit)
    assert c.status == "fail" and c.numbers["max_abs_multiplier"] > 10  # exp(0.5 * 2 pi) = 23.1
