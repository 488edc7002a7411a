"""CasADi translation of spec expressions and tabulated-sample interpolation."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from mpgspec.compile.expr_casadi import compile_vector, interp_cubic, interp_linear, to_casadi
from mpgspec.errors import ExprError
from mpgspec.spec.expr import FUNCTIONS, evaluate, parse

KINDS = [ca.SX, ca.MX]


def numeric(text: str, kind: type, **values: float) -> float:
    """Compile text with symbols for values and evaluate through a casadi.Function."""
    syms = {name: kind.sym(name) for name in values}
    out = to_casadi(parse(text), syms)
    f = ca.Function("f", list(syms.values()), [out])
    return float(f(*values.values()))


CASES = [
    ("sin(x)", 0.7), ("cos(x)", 0.7), ("tan(x)", 0.7), ("asin(x)", 0.3), ("acos(x)", 0.3),
    ("atan(x)", -2.0), ("atan2(x, -1.5)", 0.4), ("sinh(x)", 1.3), ("cosh(x)", 1.3),
    ("tanh(x)", 1.3), ("exp(x)", 1.1), ("log(x)", 2.5), ("log10(x)", 250.0), ("sqrt(x)", 2.0),
    ("abs(x)", -3.5), ("sign(x)", -3.5), ("sign(x)", 0.0), ("sign(x)", 2.0), ("floor(x)", -1.5),
    ("ceil(x)", -1.5), ("fmod(x, 3)", -7.5), ("fmod(x, 3)", 7.5), ("min(x, 2, -1)", 0.5),
    ("max(x, 2, -1)", 3.5), ("clip(x, -1, 1)", 2.5), ("clip(x, -1, 1)", -2.5),
    ("clip(x, -1, 1)", 0.25), ("sat(x, 0, 2)", 3.0), ("if_else(x > 0, 10, 20)", 1.0),
    ("if_else(x > 0, 10, 20)", -1.0), ("piecewise(x < 0, -1, x < 1, x, 1)", -0.5),
    ("piecewise(x < 0, -1, x < 1, x, 1)", 0.5), ("piecewise(x < 0, -1, x < 1, x, 1)", 5.0),
    ("norm_2(x, 4)", 3.0), ("norm_1(x, -4, 1)", 3.0), ("norm_inf(x, -4, 1)", 3.0),
    ("norm_inf(x, -4, 1)", -5.0), ("sq(x)", -3.0), ("hypot(x, 4)", 3.0),
    ("-x^2", 3.0), ("x^3", -2.0), ("2^x^2", 1.5), ("x ** 0.5", 4.0), ("x / 4 - 1", 2.0),
    ("x < 1", 0.5), ("x <= 1", 1.0), ("x > 1", 0.5), ("x >= 1", 1.0), ("x == 1", 1.0),
    ("x != 1", 1.0), ("x > 0 and x < 1", 0.5), ("x > 0 and x < 1", 1.5),
    ("x < 0 or x > 1", 0.5), ("x < 0 || x > 1", 1.5), ("not (x > 0)", 0.5), ("!x", 0.0),
    ("x * pi + e", 2.0),
]


@pytest.mark.parametrize("kind", KINDS, ids=["SX", "MX"])
@pytest.mark.parametrize("text, x", CASES)
def test_matches_python_evaluation(kind: type, text: str, x: float) -> None:
    assert numeric(text, kind, x=x) == pytest.approx(evaluate(parse(text), {"x": x}), abs=1e-12)


def test_every_function_is_translated() -> None:
    used = {text.split("(")[0] for text, _ in CASES if "(" in text and text[0].isalpha()}
    assert set(FUNCTIONS) <= used


@pytest.mark.parametrize("text, reference", [
    ("atan2(x, y)", math.atan2), ("hypot(x, y)", math.hypot), ("fmod(x, y)", math.fmod),
    ("x ^ y", math.pow),
])
def test_two_argument_functions_vs_math(text: str, reference) -> None:
    for x, y in [(1.5, 2.0), (-1.5, 0.7), (3.0, -2.0)]:
        if text == "x ^ y" and x < 0:
            continue
        assert numeric(text, ca.SX, x=x, y=y) == pytest.approx(reference(x, y))


def test_numpy_reference_for_norms() -> None:
    v = np.array([0.3, -4.0, 2.5])
    env = dict(a=v[0], b=v[1], c=v[2])
    assert numeric("norm_2(a, b, c)", ca.SX, **env) == pytest.approx(np.linalg.norm(v, 2))
    assert numeric("norm_1(a, b, c)", ca.SX, **env) == pytest.approx(np.linalg.norm(v, 1))
    assert numeric("norm_inf(a, b, c)", ca.SX, **env) == pytest.approx(np.linalg.norm(v, np.inf))


def test_norm_of_vector_argument() -> None:
    v = ca.SX.sym("v", 3)
    out = to_casadi(parse("norm_2(v)"), {"v": v})
    f = ca.Function("f", [v], [out])
    assert float(f([3, 4, 12])) == pytest.approx(13.0)


def test_result_types() -> None:
    x_sx, x_mx = ca.SX.sym("x"), ca.MX.sym("x")
    assert isinstance(to_casadi(parse("x + 1"), {"x": x_sx}), ca.SX)
    assert isinstance(to_casadi(parse("x + 1"), {"x": x_mx}), ca.MX)
    assert isinstance(to_casadi(parse("x + 1"), {"x": 2.0, "y": x_mx}), ca.MX)
    constant = to_casadi(parse("2 * pi"), {})
    assert isinstance(constant, ca.SX) and float(ca.evalf(constant)) == pytest.approx(2 * math.pi)
    with pytest.raises(TypeError):
        to_casadi(parse("x + y"), {"x": x_sx, "y": x_mx})


def test_float_environment_values() -> None:
    x = ca.SX.sym("x")
    out = to_casadi(parse("m * x + g"), {"x": x, "m": 2.0, "g": 9.81})
    assert float(ca.Function("f", [x], [out])(1.0)) == pytest.approx(11.81)


def test_env_overrides_constant() -> None:
    e = ca.SX.sym("e")
    out = to_casadi(parse("e + 1"), {"e": e})
    assert float(ca.Function("f", [e], [out])(5.0)) == 6.0


def test_power_derivative_at_negative_base() -> None:
    x = ca.SX.sym("x")
    for text, expected in [("x^2", -4.0), ("x^3", 12.0), ("x**2", -4.0)]:
        d = ca.jacobian(to_casadi(parse(text), {"x": x}), x)
        assert float(ca.Function("d", [x], [d])(-2.0)) == pytest.approx(expected)


def test_unknown_name() -> None:
    names = {f"v{i:02d}": ca.SX.sym(f"v{i:02d}") for i in range(30)}
    names["speed"] = ca.SX.sym("speed")
    with pytest.raises(ExprError) as info:
        to_casadi(parse("1 + sped * 2"), names)
    err = info.value
    assert (err.code, err.offset, err.found) == ("MPG204", 4, "sped")
    assert "'speed'" in err.hint and "..." in err.hint and "v29" not in err.hint


def test_compile_vector() -> None:
    x = ca.SX.sym("x")
    out = compile_vector([parse("x + 1"), "2 * x", 3], {"x": x})
    assert out.shape == (3, 1)
    assert np.allclose(np.array(ca.Function("f", [x], [out])(2.0)).ravel(), [3, 4, 3])
    assert compile_vector([], {"x": x}).shape == (0, 1)
    assert isinstance(compile_vector([], {"m": ca.MX.sym("m")}), ca.MX)


# ---------------------------------------------------------------------------------------------
# Interpolation

TS = np.array([0.0, 0.4, 1.0, 1.7, 2.0, 3.1])
YS = np.sin(TS) + 0.3 * TS**2
QUERY = np.linspace(-0.5, 3.6, 401)


def _sample(expr, t, query):
    f = ca.Function("f", [t], [expr])
    return np.array([np.array(f(q)).ravel() for q in query])


@pytest.mark.parametrize("kind", KINDS, ids=["SX", "MX"])
def test_interp_linear_matches_numpy(kind: type) -> None:
    t = kind.sym("t")
    got = _sample(interp_linear(t, TS, YS), t, QUERY).ravel()
    assert np.allclose(got, np.interp(QUERY, TS, YS), atol=1e-12)


@pytest.mark.parametrize("bc_type", ["not-a-knot", "natural", "clamped"])
@pytest.mark.parametrize("kind", KINDS, ids=["SX", "MX"])
def test_interp_cubic_matches_scipy(kind: type, bc_type: str) -> None:
    t = kind.sym("t")
    got = _sample(interp_cubic(t, TS, YS, bc_type=bc_type), t, QUERY).ravel()
    ref = CubicSpline(TS, YS, bc_type=bc_type)(np.clip(QUERY, TS[0], TS[-1]))
    assert np.allclose(got, ref, atol=1e-10)


def test_interp_cubic_default_is_not_a_knot_and_derivative_matches() -> None:
    t = ca.SX.sym("t")
    expr = interp_cubic(t, TS, YS)
    inside = np.linspace(0.01, 3.09, 97)
    d = _sample(ca.jacobian(expr, t), t, inside).ravel()
    assert np.allclose(d, CubicSpline(TS, YS).derivative()(inside), atol=1e-9)
    outside = _sample(ca.jacobian(expr, t), t, [-1.0, 4.0]).ravel()
    assert np.allclose(outside, 0.0)


def test_interp_exact_at_knots_and_clamped() -> None:
    t = ca.SX.sym("t")
    for expr in (interp_linear(t, TS, YS), interp_cubic(t, TS, YS)):
        assert np.allclose(_sample(expr, t, TS).ravel(), YS, atol=1e-12)
        assert np.allclose(_sample(expr, t, [-10.0, 10.0]).ravel(), [YS[0], YS[-1]])


def test_interp_vector_samples() -> None:
    t = ca.SX.sym("t")
    ys = np.column_stack([YS, np.cos(TS)])
    lin = _sample(interp_linear(t, TS, ys), t, QUERY)
    assert lin.shape == (len(QUERY), 2)
    assert np.allclose(lin[:, 1], np.interp(QUERY, TS, np.cos(TS)))
    cub = _sample(interp_cubic(t, TS, ys), t, QUERY)
    assert np.allclose(cub, CubicSpline(TS, ys)(np.clip(QUERY, TS[0], TS[-1])), atol=1e-10)


def test_interp_two_samples_is_linear() -> None:
    t = ca.SX.sym("t")
    for make in (interp_linear, interp_cubic):
        got = _sample(make(t, [0.0, 2.0], [1.0, 5.0]), t, [0.5, 1.0]).ravel()
        assert np.allclose(got, [2.0, 3.0])


def test_interp_many_samples() -> None:
    t = ca.SX.sym("t")
    ts = np.linspace(0.0, 10.0, 1001)
    ys = np.sin(ts)
    q = np.linspace(0.0, 10.0, 333)
    got = _sample(interp_cubic(t, ts, ys), t, q).ravel()
    assert np.allclose(got, CubicSpline(ts, ys)(q), atol=1e-10)


@pytest.mark.parametrize("ts, ys", [
    ([0.0], [1.0]), ([0.0, 0.0, 1.0], [1, 2, 3]), ([1.0, 0.0], [1, 2]), ([0.0, 1.0], [1.0]),
    ([0.0, math.nan], [1, 2]), ([0.0, 1.0], [1, math.inf]),
])
def test_interp_rejects_bad_samples(ts, ys) -> None:
    t = ca.SX.sym("t")
    for make in (interp_linear, interp_cubic):
        with pytest.raises(ValueError):
            make(t, ts, ys)
