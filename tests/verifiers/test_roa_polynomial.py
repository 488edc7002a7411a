"""Degree-4 SOS Lyapunov certificates against the true region of attraction of the reversed Van der Pol."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mpgspec.certify.problem import RoAProblem
from verifiers import polyv, sos

x = ca.SX.sym("x", 2)
VDP = RoAProblem(ca.Function("f", [x], [ca.vertcat(-x[1], x[0] + (x[0] ** 2 - 1) * x[1])]), np.zeros(2),
                 name="reversed Van der Pol")
TRUE_BALL = 1.5317  # largest ball inside the true region of attraction (distance to the limit cycle)


def _vdp(t, z):
    a, b = z.reshape(2, -1)
    return np.concatenate([-b, a + (a ** 2 - 1) * b])


def _V(ev: dict, pts: np.ndarray) -> np.ndarray:
    """V / rho at the points: the certified set is {_V <= 1}."""
    mons = np.array(ev["V"]["monomials"], float)
    c = np.array(ev["V"]["coefficients"], float)
    return (np.prod(pts[:, None, :] ** mons[None], axis=2) * c).sum(axis=1) / ev["rho"]


def _boundary(ev: dict, n: int = 360) -> np.ndarray:
    """First point with V = rho on each of n rays from the origin (bisection)."""
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    u = np.c_[np.cos(th), np.sin(th)]
    lo, hi = np.zeros(n), np.full(n, 0.01)
    for _ in range(1000):  # march outwards until the level is crossed
        out = _V(ev, hi[:, None] * u) > 1
        if out.all():
            break
        lo, hi = np.where(out, lo, hi), np.where(out, hi, hi + 0.01)
    assert out.all()
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        out = _V(ev, mid[:, None] * u) > 1
        lo, hi = np.where(out, lo, mid), np.where(out, mid, hi)
    return lo[:, None] * u


@pytest.fixture(scope="module")
def degree4():
    return sos.verifier.estimate(VDP, {"degree": 4, "iterations": 4})


def test_degree4_reaches_the_true_ball_and_never_exceeds_it(degree4):
    res = degree4
    assert res.level == "certified", res.message
    assert 0.9 * TRUE_BALL <= res.radius <= TRUE_BALL
    quadratic = sos.verifier.estimate(VDP, {})
    assert res.radius > quadratic.radius * 1.2
    ev = res.evidence
    assert ev["degree"] == 4 and max(sum(m) for m in ev["V"]["monomials"]) == 4
    assert all(p["level"] == "certified" and p["certificate"]["ok"] for p in ev["parts"])
    assert ev["ball"]["certificate"]["ok"] and ev["positivity"]["ok"]
    # the certified ball lies in {V <= 1}
    th = np.linspace(0, 2 * np.pi, 2000)
    assert _V(ev, res.radius * np.c_[np.cos(th), np.sin(th)]).max() <= 1 + 1e-9


def test_every_boundary_point_of_the_level_set_converges(degree4):
    ev = degree4.evidence
    bnd = _boundary(ev)
    assert np.allclose(_V(ev, bnd), 1, atol=1e-9)
    z = solve_ivp(_vdp, (0, 25), bnd.T.ravel(), method="DOP853", rtol=1e-10, atol=1e-12).y[:, -1]
    assert np.abs(z).max() < 1e-4


def test_lie_derivative_and_quadratic_part():
    V = {(2, 0): 1.0, (1, 1): 0.5, (0, 4): 2.0}
    f = [{(0, 1): 1.0}, {(1, 0): -1.0, (0, 1): -1.0}]  # x1' = x2, x2' = -x1 - x2
    # dV = (2 x1 + 0.5 x2) x2 + (0.5 x1 + 8 x2^3) (-x1 - x2)
    want = sos.padd(sos.pmul({(1, 0): 2.0, (0, 1): 0.5}, f[0]), sos.pmul({(1, 0): 0.5, (0, 3): 8.0}, f[1]))
    assert polyv.lie_derivative(V, f) == pytest.approx(want)
    assert np.allclose(polyv.quadratic_part(V, 2), [[1.0, 0.25], [0.25, 0.0]])


def test_odd_degree_is_refused():
    res = sos.verifier.estimate(VDP, {"degree": 3})
    assert res.level == "failed" and "even integer" in res.message


@pytest.mark.parametrize("key, suggestion", [("degre", "'degree'"), ("iteration", "'iterations'")])
def test_misspelled_sos_option_exits_2_at_its_place(tmp_path, capsys, key, suggestion):
    import re
    import shutil
    from pathlib import Path

    from mpgspec.cli import main

    src = Path(__file__).resolve().parents[2] / "specs" / "cart"
    shutil.copytree(src, tmp_path / "cart")
    p = tmp_path / "cart" / "project.yaml"
    text = p.read_text()
    first = "roa: {method: sos, require: certified}"
    p.write_text(text.replace(first, f"roa: {{method: sos, require: certified, options: {{{key}: 4}}}}", 1))
    rc = main(["verify", str(p), "--no-write", "-q"])
    err = capsys.readouterr().err
    assert rc == 2
    assert re.search(r"project\.yaml:\d+:\d+ MPG102", err) and f"did you mean {suggestion}" in err


@pytest.mark.parametrize("value, what", [("3", "even"), ("true", "valid integer"), ("four", "valid integer"),
                                         ("0", "greater than or equal to 2")])
def test_wrong_degree_is_a_located_spec_error(tmp_path, value, what):
    import shutil
    from pathlib import Path

    from mpgspec.certify.roa import check_roa_specs
    from mpgspec.errors import SpecErrors
    from mpgspec.spec.loader import load_project

    shutil.copytree(Path(__file__).resolve().parents[2] / "specs" / "cart", tmp_path / "cart")
    p = tmp_path / "cart" / "project.yaml"
    p.write_text(p.read_text().replace("roa: {method: sos, require: certified}",
                                       f"roa: {{method: sos, require: certified, options: {{degree: {value}}}}}", 1))
    with pytest.raises(SpecErrors) as ei:
        check_roa_specs(load_project(p))
    err = ei.value.errors[0]
    assert err.code == "MPG104" and err.key.endswith("roa.options.degree") and what in err.message
    assert err.location.line > 0
