"""E inside C on the contact manifold: the projection of states onto feet-on-the-ground-and-still,
and the roa_in_safe_set check of the A1 primitives on it."""
import numpy as np
import pinocchio as pin

from mpgspec.check.assumptions import largest_radius_in_safe_set, roa_in_safe_set
from mpgspec.check.roa_flows import boundary_starts

FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")


def _feet(sys, x):
    """Foot heights and world velocities from pinocchio (independent of the CasADi kinematics)."""
    m = sys.model
    pm = m.pin_model
    pd = pm.createData()
    q, v = x[:m.nq], x[m.nq:m.nq + m.nv]
    pin.forwardKinematics(pm, pd, q, v)
    pin.updateFramePlacements(pm, pd)
    z, vel = {}, {}
    for f in FEET:
        fid = pm.getFrameId(f)
        z[f] = pd.oMf[fid].translation[2]
        vel[f] = pin.getFrameVelocity(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED).linear
    return z, vel


def _wdist(W, dx):
    return float(np.sqrt(dx @ W @ dx))


def _offsets(W, r, n, seed):
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])
    d = np.random.default_rng(seed).normal(size=(n, L.shape[1]))
    return (r * d / np.linalg.norm(d, axis=1, keepdims=True)) @ L.T


def test_projection_puts_feet_on_the_ground_at_rest(a1):
    _, prims, _ = a1
    lie = prims["Lie"]
    sys, W = lie.system, np.asarray(lie.info["roa_W"])
    xs = lie.x_star(0.0)
    assert np.allclose(sys.project_to_contacts(xs, FEET, W), xs, atol=1e-10)  # already on the manifold
    for dx in _offsets(W, 0.08, 5, seed=3):
        x0 = xs + dx
        z0, _ = _feet(sys, np.r_[x0[:3], x0[3:7] / np.linalg.norm(x0[3:7]), x0[7:]])
        assert max(abs(h) for h in z0.values()) > 1e-4  # the sample lifts or sinks feet
        x = sys.project_to_contacts(x0, FEET, W)
        assert abs(np.linalg.norm(x[3:7]) - 1) < 1e-12
        z, vel = _feet(sys, x)
        for f in FEET:
            assert abs(z[f]) < 1e-8 and np.abs(vel[f]).max() < 1e-8
        assert _wdist(W, x - xs) <= 0.08  # the projection stays inside E
    # two feet in contact: only they are held
    x = sys.project_to_contacts(xs + _offsets(W, 0.08, 1, seed=4)[0], ("FL_foot", "RR_foot"), W)
    z, vel = _feet(sys, x)
    for f in ("FL_foot", "RR_foot"):
        assert abs(z[f]) < 1e-8 and np.abs(vel[f]).max() < 1e-8
    assert max(np.abs(vel[f]).max() for f in ("FR_foot", "RL_foot")) > 1e-3


def test_e_lies_inside_c_on_the_contact_manifold(a1):
    spec, prims, _ = a1
    assert spec.project.assumptions.get("roa_in_safe_set", "fail") == "fail"
    for name in ("Lie", "Stand"):
        p = prims[name]
        c = roa_in_safe_set(p, 1e-9)
        n = c.numbers
        assert c.status == "pass", c.message
        assert c.level == "empirical" and "contact manifold" in c.message
        assert n["min_h"] >= 0 and n["contacts"] == list(FEET)
        assert n["projected"] == 2 * n["samples"]
        assert 0 < n["projection_distance_median"] <= n["projection_distance_max"] <= p.radius
        assert n["projected_radius_max"] <= 1.0
        assert n["min_h_unprojected"] < 0  # the ball in the full state lifts feet: C holds only on the manifold


def test_e_too_large_fails_on_the_contact_manifold(a1, a1_pd_lie):
    """Lie under the paper's joint PD at the radius of the ID-QP's E: joint offsets make the PD push the
    feet out of the friction cone, where the ID-QP's forces keep a margin; Stand with joint offsets of
    1.5 rad crosses the joint limits."""
    _, prims, _ = a1
    c = roa_in_safe_set(a1_pd_lie[1]["Lie"], 1e-9, radius=0.08)
    assert c.status == "fail" and c.numbers["min_h"] < -1, c.message
    c = roa_in_safe_set(prims["Stand"], 1e-9, samples=50, radius=1.5)
    assert c.status == "fail" and c.numbers["min_h"] < -0.1, c.message


def test_the_joint_pd_lies_radius_is_within_the_largest_safe_one(a1_pd_lie):
    lie = a1_pd_lie[1]["Lie"]
    r = largest_radius_in_safe_set(lie, r_max=0.08, samples=40, rel_tol=0.05)
    assert lie.radius <= r < 0.08


def test_boundary_starts_lie_on_e_and_the_contact_manifold(a1):
    """roa_invariant's starts for the A1's Stand: 16 on the W-sphere of E, feet on the ground and still."""
    _, prims, _ = a1
    stand = prims["Stand"]
    X = boundary_starts(stand, 16, 0)
    W, xs = np.asarray(stand.W), np.asarray(stand.x_star(0.0)).ravel()
    d = np.sqrt(np.einsum("ij,ik,kj->j", X - xs[:, None], W, X - xs[:, None]))
    assert np.allclose(d, stand.radius, rtol=1e-3)
    sys = stand.system
    for j in range(X.shape[1]):
        x = X[:, j]
        assert np.allclose(sys.project_to_contacts(x, ("FL_foot", "FR_foot", "RL_foot", "RR_foot"), W), x, atol=1e-8)


def test_roa_invariant_runs_stands_held_law_as_the_oracle_does(a1):
    """The flow roa_invariant runs Stand on (its ID-QP solved at each 1 ms step's start and held) is the
    oracle's own chunk, settled (long after the motion profile), bit for bit; and the check passes."""
    from mpgspec.certify.hybrid_orbit import S_LONG, HybridFlow
    from mpgspec.check.roa_flows import roa_invariant
    from mpgspec.oracle.integrator import build_chunk, initial_state

    _, prims, settings = a1
    stand = prims["Stand"]
    assert stand.sampled is not None
    X0 = boundary_starts(stand, 2, 5)
    XT, _ = HybridFlow(stand, 0.001, 0.1).run(X0, np.zeros(2), 1)
    chunk = build_chunk(stand, 0.001, 100, True, settings.jit_flags, with_state=True, boundaries=False)
    nx = stand.system.nx
    for j in range(2):
        z = initial_state(stand, X0[:, j], 0.0)
        z[nx + 1], z[nx + 2:2 * nx + 2] = S_LONG, stand.x_star(0.0)
        zf, _ = chunk.run(z[:, None])
        assert np.array_equal(zf[:nx, 0], XT[:, j])
        assert np.abs(XT[:, j] - X0[:, j]).max() > 0.01  # the flow moved
    chk = roa_invariant(stand)
    assert chk.status == "pass" and chk.numbers["unsafe"] == 0 and chk.numbers["outside_at_end"] == 0, chk.message
    assert chk.numbers["contact_manifold"] and 0.5 < chk.numbers["final_distance_max"] < 1
