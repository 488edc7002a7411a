"""The region of a level-set verifier as {V <= rho} and as the W-ball inside it; E as the level set itself."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mpgspec import api
from mpgspec.certify.level_set import level_set_of, use_level_set
from mpgspec.spec.loader import load_project

CART = Path(__file__).resolve().parents[2] / "specs" / "cart"


def _cart(tmp_path: Path, park_a: str, park_b: str) -> Path:
    """The cart project with ParkA's and ParkB's roa options replaced."""
    shutil.copytree(CART, tmp_path / "cart")
    p = tmp_path / "cart" / "project.yaml"
    text = p.read_text()
    text = text.replace("roa: {method: sos, require: certified, options: {degree: 4}}",
                        f"roa: {{method: sos, require: certified, options: {park_a}}}", 1)
    text = text.replace("roa: {method: sos, require: certified}\n",
                        f"roa: {{method: sos, require: certified, options: {park_b}}}\n", 1)
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    """(compiled project, graph) of the cart with E the ball (as specs/cart) and E the level set."""
    out = {}
    for kind in ("ball", "level_set"):
        p = _cart(tmp_path_factory.mktemp(kind), f"{{degree: 4, region: {kind}}}", f"{{region: {kind}}}")
        spec = load_project(p)
        out[kind] = api.build(spec, api.settings_for(spec))
    return out


def test_level_set_from_quadratic_and_polynomial_evidence():
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    ls = level_set_of({"P": P.tolist(), "rho": 0.7})
    Y = np.random.default_rng(0).normal(size=(50, 2))
    assert ls.degree == 2 and ls.rho == 0.7
    assert np.allclose(ls.value(Y), np.einsum("ki,ij,kj->k", Y, P, Y), rtol=1e-14)
    ls4 = level_set_of({"V": {"monomials": [[2, 0], [0, 2], [4, 0]], "coefficients": [1.0, 2.0, 0.5]}, "rho": 1.0})
    assert ls4.degree == 4 and np.allclose(ls4.value(Y), Y[:, 0] ** 2 + 2 * Y[:, 1] ** 2 + 0.5 * Y[:, 0] ** 4)
    assert level_set_of({"rho": 1.0}) is None and level_set_of({"P": P.tolist(), "rho": 0.0}) is None


def test_region_is_reported_as_level_set_and_ball(both):
    for kind, (cp, _) in both.items():
        for name, degree in (("ParkA", 4), ("ParkB", 2)):
            rec = cp.roa[name]
            rg = rec.evidence["region"]
            assert rec.level == "certified" and rg["E"] == kind
            assert rg["level_set"]["degree"] == degree and rg["level_set"]["rho"] > 0
            assert rg["ball"]["radius"] == pytest.approx(rec.radius)
            if kind == "level_set":
                assert rg["check"]["ok"] and rg["check"]["max_margin_error"] < 1e-12
                assert rg["check"]["max_V_over_rho_on_ball"] <= 1 and rec.message.startswith("E is the level set")


def test_level_set_E_is_the_level_set_and_holds_the_ball(both):
    cp_ball, _ = both["ball"]
    cp, _ = both["level_set"]
    p, rec = cp.prims["ParkA"], cp.roa["ParkA"]
    ls = level_set_of(rec.evidence)
    r, xs = rec.radius, p.x_star(0.0)
    th = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    u = np.c_[np.cos(th), np.sin(th)]
    margin = lambda y: float(p.roa_margin(xs + y, 0.0))  # noqa: E731
    ball_margin = lambda y: float(cp_ball.prims["ParkA"].roa_margin(xs + y, 0.0))  # noqa: E731
    assert all(margin(0.999 * r * d) > 0 for d in u)  # the certified ball lies inside E
    beyond = [s * d for d in u for s in (1.05 * r, 1.2 * r) if ls.value(s * d)[0] < 0.99 * ls.rho]
    assert beyond, "the level set reaches past the ball somewhere"
    assert all(margin(y) > 0 and ball_margin(y) < 0 for y in beyond)  # in E, not in the ball
    outside = [2 * r * d for d in u if ls.value(2 * r * d)[0] > 1.01 * ls.rho]
    assert outside and all(margin(y) < 0 for y in outside)


def test_entering_the_larger_E_is_sooner(both):
    gb, gl = both["ball"][1].graph, both["level_set"][1].graph
    into = [(a, b) for (a, b), t in gb.transitions.items() if b == "ParkA" and int(t.cls)]
    assert into
    for a, b in into:
        assert int(gl.edge(a, b).cls) == 1
        assert gl.edge(a, b).weights["duration"] <= gb.edge(a, b).weights["duration"]
    assert any(gl.edge(a, b).weights["duration"] < 0.9 * gb.edge(a, b).weights["duration"] for a, b in into)


def test_a_level_set_that_does_not_hold_the_ball_is_refused(both):
    cp, _ = both["ball"]
    rec = cp.roa["ParkA"]
    ev = dict(rec.evidence)
    ev["rho"] = 0.5 * ev["rho"]  # the certified ball no longer lies inside
    new, info = use_level_set(cp.prims["ParkA"], ev, rec.radius)
    assert new is None and info["E"] == "ball" and "float64" in info["reason"]
    assert info["check"]["max_V_over_rho_on_ball"] > 1


def test_region_value_is_checked(tmp_path):
    from mpgspec.certify.roa import check_roa_specs
    from mpgspec.errors import SpecErrors

    p = _cart(tmp_path, "{degree: 4, region: levelset}", "{}")
    with pytest.raises(SpecErrors) as ei:
        check_roa_specs(load_project(p))
    err = ei.value.errors[0]
    assert err.code == "MPG104" and err.key.endswith("roa.options.region") and "level_set" in err.message
    assert err.location.line == 27
