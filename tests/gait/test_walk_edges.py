"""Switches into and out of the A1's walks through the safety oracle with step doubling, and its
error estimate against a reference integrated eight times finer.

Walk(in_place) is sized by its own verifier (floquet on the discrete flow, as `mpgspec verify`
does); Stand's E is given by the spec."""
import numpy as np
import pytest

from mpgspec.certify.roa import _estimate
from mpgspec.oracle import SafetyOracle
from mpgspec.oracle.integrator import build_chunk
from mpgspec.oracle.verdict import ENVELOPE_STEPS, Block, Carry, envelope


@pytest.fixture(scope="module")
def sized(a1_project):
    """(prims, settings, the floquet verifier's result for Walk(in_place))."""
    spec, prims, settings = a1_project
    assert settings.error == "doubling"
    prims = dict(prims)  # Walk(in_place) is replaced by its sized copy below
    inst = next(i for i in spec.primitives if i.name == "Walk(in_place)")
    res = _estimate(inst.spec.roa.method, prims["Walk(in_place)"], inst.spec.roa.options)
    assert res.level == "empirical" and 0.002 < res.radius < 0.05
    prims["Walk(in_place)"] = prims["Walk(in_place)"].with_radius(float(res.radius))
    return prims, settings, res


@pytest.fixture(scope="module")
def setup(sized):
    return sized[:2]


def test_definition_1_takes_the_verifiers_orbit_bit_for_bit(sized):
    """The gait's orbit defect, least h and multipliers that Definition 1's checks take from the
    floquet verifier's evidence (seed_hybrid_orbit) are the bits they compute themselves, also when the
    evidence was read back from the cache (JSON); evidence of another step, other neutral directions or
    without a finite monodromy is not taken."""
    import json

    from mpgspec.check.assumptions import _hybrid_orbit, seed_hybrid_orbit

    prims, _s, res = sized
    walk = prims["Walk(in_place)"]
    own, seeded, stored = (walk.with_radius(walk.radius) for _ in range(3))
    for other in ({**res.evidence, "dt": 0.002}, {**res.evidence, "neutral": {}},
                  {**res.evidence, "monodromy": [["nan"]]}, {**res.evidence, "monodromy": None}):
        assert not seed_hybrid_orbit(seeded, other) and "hybrid_orbit" not in seeded.cache
    assert seed_hybrid_orbit(seeded, res.evidence)
    assert seed_hybrid_orbit(stored, json.loads(json.dumps(res.evidence)))
    a = _hybrid_orbit(own)
    for b in (seeded.cache["hybrid_orbit"], stored.cache["hybrid_orbit"]):
        assert a["defect"] == b["defect"] and a["least_h"] == b["least_h"] and a["neutral"] == b["neutral"]
        assert np.array_equal(a["mu"], b["mu"]) and len(a["neutral"]) == 3


def test_the_walks_tube_is_bounded_just_before_a_touchdown(sized):
    """What bounds Walk(in_place)'s E, as its evidence and message say: the starts that failed at the least
    radius that failed leave C at a swing foot's ground functions (above_ground, touchdown_gap) in the last
    milliseconds before a scheduled contact change, where the flow judged them below 0."""
    prims, _s, res = sized
    b = res.evidence["tube"]["bounded_by"]
    assert b["r"] > res.radius and b["located"] >= 1 and b["failed"] >= b["located"]
    for e in b["exits"]:
        assert e["h"].split("[")[0] in ("above_ground", "touchdown_gap") and e["value"] < 0, e
        assert -0.02 <= e["from_change_s"] <= 0, e
    assert b["text"] in res.message and "before a scheduled contact change" in b["text"]
    # the located exit is the flow's own: a start at the orbit stays in C over the period
    from mpgspec.certify.hybrid_orbit import HybridFlow

    walk = prims["Walk(in_place)"]
    assert HybridFlow(walk, 0.001).first_exit(np.asarray(walk.x_star(0.0), float).ravel(), 0.0) is None


def _call(prims, settings, a, b, t_a, t_b, **kw):
    return SafetyOracle(prims[b], settings.replace(**kw)).evaluate(prims[a].x_star(t_a)[None], np.array([t_b]))[0]


def test_stand_to_walk_in_place_is_safe_at_double_support_only(setup):
    prims, s = setup
    ev = _call(prims, s, "Stand", "Walk(in_place)", 0.0, 0.0)
    assert ev.status == "safe" and 0.1 < ev.t_enter < 1.0
    assert ev.entry_margin > ev.entry_error > 0
    # a pair is lifted from standing at once: never safe. The oracle's first sample already finds a
    # swing foot 10 um inside `aerial` against an error of 2.7e-4 (inconclusive); eight times finer,
    # the flow breaks a calf's speed limit
    mid = _call(prims, s, "Stand", "Walk(in_place)", 0.0, 0.09)
    assert mid.status in ("unsafe", "inconclusive")
    fine = _call(prims, s, "Stand", "Walk(in_place)", 0.0, 0.09, dt=s.dt / 8)
    assert fine.status == "unsafe" and fine.violated.startswith("qdot_max")


def test_summed_local_estimates_cannot_resolve_the_walks_tube(setup):
    """Stand -> Walk(fast), which step doubling verifies, judged with summed per-step estimates stays
    inconclusive: their sum on E's margin outgrows the fast walk's tube while the flow converges."""
    prims, s = setup
    assert _call(prims, s, "Stand", "Walk(fast)", 0.0, 0.19).status == "safe"
    ev = _call(prims, s, "Stand", "Walk(fast)", 0.0, 0.19, error="local")
    assert ev.status == "inconclusive"


def test_walks_are_left_for_stand_only_in_place_and_at_double_support(setup):
    prims, s = setup
    assert _call(prims, s, "Walk(in_place)", "Stand", 0.0, 0.0).status == "safe"
    assert _call(prims, s, "Walk(in_place)", "Stand", 0.09, 0.0).status == "unsafe"  # a foot in the air


def test_doubling_error_estimate_covers_the_true_error(setup):
    """E's margin along Stand -> Walk(in_place) at the oracle's step, against the same closed loop
    integrated at dt/8: the true error of the judged rollout stays below the doubling estimate (the
    envelope of the two rollouts' differences; the raw difference falls short by 2x at 4 samples
    10 ms after the swing's lift ramp, where the judged and companion errors cross)."""
    prims, s = setup
    p = prims["Walk(in_place)"]
    x0 = prims["Stand"].x_star(0.0)
    fine = build_chunk(p, s.dt, 64, True, s.jit_flags, error="doubling")
    ref = build_chunk(p, s.dt / 8, 64, True, s.jit_flags, error="local")
    Z, outs = fine.start(x0[None], [0.0]), []
    for _ in range(8):
        Z, out = fine.run(Z)
        outs.append(out)
    out, r = np.concatenate(outs, axis=2), fine.rows
    # the estimate the judge uses: the envelope of the two rollouts' differences
    blk = Block(out[r.h], out[r.lb], out[r.dh], out[r.margin], out[r.err], out[r.s], out[r.dt], out[r.u_raw],
                out[r.u], np.isfinite(out).all(axis=0), out[r.ds], ENVELOPE_STEPS * s.dt)
    M, E, T = out[r.margin][0], envelope(blk, Carry(len(p.h_names), p.system.nu, 1))[2][0], out[r.s][0]
    Zr, Mr, Tr = ref.start(x0[None], [0.0]), [], []
    for _ in range(72):
        Zr, out = ref.run(Zr)
        Mr.append(out[ref.rows.margin][0])
        Tr.append(out[ref.rows.s][0])
    Mr, Tr = np.concatenate(Mr), np.concatenate(Tr)
    # E(t)'s radius is exact at every sample and steps at the narrowed stretches before the touchdowns: the
    # integration error is the distance's, so compare -||x - x*(t)||_W, which the interpolation below assumes smooth
    M, Mr = M - p.radius_at(T), Mr - p.radius_at(Tr)
    # the reference at the judged rollout's sample times: the two step grids part where a located
    # torque-limit crossing cuts a step, so the reference is interpolated between its samples, with
    # the interpolation's own error bound (its second differences / 8) added to the estimate
    keep = T <= Tr[-2]
    M, E, T = M[keep], E[keep], T[keep]
    j = np.clip(np.searchsorted(Tr, T, side="right") - 1, 0, Tr.size - 2)
    w = (T - Tr[j]) / (Tr[j + 1] - Tr[j])
    Mi = (1 - w) * Mr[j] + w * Mr[j + 1]
    a, d = np.maximum(j - 1, 0), np.minimum(j + 2, Tr.size - 1)
    d2 = np.maximum(np.abs(Mr[j + 1] - 2 * Mr[j] + Mr[a]), np.abs(Mr[d] - 2 * Mr[j + 1] + Mr[j]))
    interp = np.where(w * (1 - w) > 0, d2 / 8, 0.0)
    exact = np.abs(Tr[np.clip(np.searchsorted(Tr, T), 0, Tr.size - 1)] - T) < 1e-12
    # enough samples where the grids meet: about a fifth of them (the first torque-limit crossing, which parts
    # the grids, comes a little earlier with the walks' 20 N least stance force than with 10 N)
    assert exact.mean() > 0.15 and M.size > 400
    true = np.abs(M - Mi)
    assert true.max() > 0
    assert (true[exact] <= E[exact] + 1e-12).all()  # where the grids meet, without interpolation
    assert (true <= E + interp + 1e-12).all(), f"worst ratio {np.max(true / np.maximum(E + interp, 1e-300)):.3g}"
    on = exact & (E > 0)
    assert np.median(E[on] / np.maximum(true[on], 1e-300)) > 3  # an over-estimate, as RK4's 16x says
