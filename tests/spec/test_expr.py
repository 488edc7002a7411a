"""Parser, evaluator and printer of the spec expression language."""
from __future__ import annotations

import math
import random

import pytest

from mpgspec.errors import ExprError, Location
from mpgspec.spec.expr import (
    FUNCTIONS,
    Binary,
    Call,
    Name,
    Num,
    Unary,
    evaluate,
    free_names,
    parse,
    parse_value,
    relocate,
    to_text,
)


def ev(text: str, **env: float) -> float:
    return evaluate(parse(text), env)


@pytest.mark.parametrize("text, same_as", [
    ("-x^2", "-(x^2)"),
    ("-x**2", "-(x^2)"),
    ("x^y^z", "x^(y^z)"),
    ("x^-y", "x^(-y)"),
    ("-x*y", "(-x)*y"),
    ("a+b*c", "a+(b*c)"),
    ("a-b-c", "(a-b)-c"),
    ("a/b/c", "(a/b)/c"),
    ("a+b < c*d", "(a+b) < (c*d)"),
    ("a < b and c > d or e", "((a < b) and (c > d)) or e"),
    ("not a < b", "not (a < b)"),
    ("not a and b", "(not a) and b"),
    ("a && b || !c", "(a and b) or (not c)"),
    ("+x", "x"),
    ("1e-3 * x", "0.001 * x"),
    ("2.5E+2", "250"),
    (".5", "0.5"),
])
def test_precedence(text: str, same_as: str) -> None:
    assert parse(text) == parse(same_as)


def test_ast_shape_and_positions() -> None:
    e = parse("a + sin(b)")
    assert e == Binary("+", Name("a"), Call("sin", (Name("b"),)))
    assert (e.pos, e.left.pos, e.right.pos, e.right.args[0].pos) == (2, 0, 4, 8)
    assert parse("-2") == Unary("-", Num(2.0))
    assert isinstance(parse("3").value, float)


@pytest.mark.parametrize("text, value", [
    ("-2^2", -4.0), ("2^3^2", 512.0), ("2**-1", 0.5), ("1+2*3", 7.0), ("(1+2)*3", 9.0),
    ("10/2/5", 1.0), ("8-3-2", 3.0), ("2*-3", -6.0), ("--3", 3.0),
    ("1 < 2", 1.0), ("2 <= 1", 0.0), ("3 > 2", 1.0), ("2 >= 3", 0.0), ("2 == 2", 1.0),
    ("2 != 2", 0.0), ("not 0", 1.0), ("!2", 0.0), ("1 and 0", 0.0), ("0 or 3", 1.0),
    ("1 or 0 and 0", 1.0), ("pi", math.pi), ("e", math.e), ("inf", math.inf),
])
def test_evaluate_operators(text: str, value: float) -> None:
    assert ev(text) == pytest.approx(value)


ONE_ARG = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
    "atan": math.atan, "sinh": math.sinh, "cosh": math.cosh, "tanh": math.tanh,
    "exp": math.exp, "log": math.log, "log10": math.log10, "sqrt": math.sqrt, "abs": abs,
    "floor": math.floor, "ceil": math.ceil, "sq": lambda x: x * x,
}


@pytest.mark.parametrize("func", sorted(ONE_ARG))
@pytest.mark.parametrize("x", [0.3, 0.75, 2.5, -0.4])
def test_evaluate_one_argument_functions(func: str, x: float) -> None:
    if func in ("log", "log10", "sqrt") and x < 0 or func in ("asin", "acos") and abs(x) > 1:
        with pytest.raises(ExprError) as info:
            ev(f"{func}(x)", x=x)
        assert info.value.code == "MPG205"
        return
    assert ev(f"{func}(x)", x=x) == pytest.approx(ONE_ARG[func](x))


@pytest.mark.parametrize("text, value", [
    ("sign(-3)", -1.0), ("sign(0)", 0.0), ("sign(2)", 1.0),
    ("atan2(1, -2)", math.atan2(1, -2)), ("fmod(-7, 3)", math.fmod(-7, 3)),
    ("hypot(3, 4)", 5.0), ("min(3, 1, 2)", 1.0), ("max(3, 1, 2)", 3.0), ("min(2, 5)", 2.0),
    ("clip(5, 0, 1)", 1.0), ("clip(-5, 0, 1)", 0.0), ("clip(0.5, 0, 1)", 0.5),
    ("sat(7, -2, 2)", 2.0), ("if_else(1 < 2, 10, 20)", 10.0), ("if_else(0, 10, 20)", 20.0),
    ("piecewise(0, 1, 1, 2, 3)", 2.0), ("piecewise(0, 1, 0, 2, 3)", 3.0),
    ("piecewise(1, 1, 1, 2, 3)", 1.0), ("norm_2(3, 4)", 5.0), ("norm_2(-2)", 2.0),
    ("norm_1(1, -2, 3)", 6.0), ("norm_inf(1, -5, 3)", 5.0),
])
def test_evaluate_multi_argument_functions(text: str, value: float) -> None:
    assert ev(text) == pytest.approx(value)


def test_every_function_is_tested() -> None:
    covered = set(ONE_ARG) | {"sign", "atan2", "fmod", "hypot", "min", "max", "clip", "sat",
                              "if_else", "piecewise", "norm_2", "norm_1", "norm_inf"}
    assert covered == set(FUNCTIONS)


def test_evaluate_takes_only_the_chosen_branch() -> None:
    assert ev("if_else(x > 0, sqrt(x), 0)", x=-1.0) == 0.0
    assert ev("x > 0 and 1 / x > 2", x=0.0) == 0.0


def test_evaluate_env_overrides_constants() -> None:
    assert ev("e * 2", e=3.0) == 6.0


def test_evaluate_unknown_name() -> None:
    with pytest.raises(ExprError) as info:
        ev("1 + masss", mass=2.0, g=9.8)
    err = info.value
    assert err.code == "MPG204" and err.offset == 4 and err.found == "masss"
    assert "'mass'" in err.hint and "g" in err.hint


@pytest.mark.parametrize("text", ["1 / 0", "sqrt(-1)", "log(0)", "(-8)^(1/3)", "exp(1000)"])
def test_evaluate_math_errors(text: str) -> None:
    with pytest.raises(ExprError) as info:
        ev(text)
    assert info.value.code == "MPG205"


@pytest.mark.parametrize("text, code, offset, expected, found", [
    ("x +", "MPG201", 3, "an operand", "end of expression"),
    ("(x + 1", "MPG201", 6, "')'", "end of expression"),
    ("x + )", "MPG201", 4, "an operand", "')'"),
    ("x y", "MPG201", 2, "an operator or end of expression", "'y'"),
    ("", "MPG201", 0, "an expression", "empty text"),
    ("   ", "MPG201", 0, "an expression", "empty text"),
    ("x = 1", "MPG201", 2, "a number, name, operator or parenthesis", "'='"),
    ("a $ b", "MPG201", 2, "a number, name, operator or parenthesis", "'$'"),
    ("2x", "MPG201", 0, "a number", "'2x'"),
    ("1.2.3", "MPG201", 0, "a number", "'1.2.'"),
    ("a < b < c", "MPG201", 6, "'and' between comparisons", "'<'"),
    ("max(1, 2", "MPG201", 8, "',' or ')'", "end of expression"),
    ("max(1,)", "MPG201", 6, "an operand", "')'"),
    ("1 + foo(x)", "MPG202", 4, "a whitelisted function", "'foo'"),
    ("sin(1, 2)", "MPG203", 0, "1 argument", "2 arguments"),
    ("atan2(1)", "MPG203", 0, "2 arguments", "1 argument"),
    ("min(1)", "MPG203", 0, "at least 2 arguments", "1 argument"),
    ("norm_2()", "MPG203", 0, "at least 1 argument", "0 arguments"),
    ("piecewise(a, b, c, d)", "MPG203", 0,
     "an odd number (>= 3) of arguments: c1, v1, ..., default", "4 arguments"),
    ("clip(1, 2)", "MPG203", 0, "3 arguments", "2 arguments"),
])
def test_parse_errors(text: str, code: str, offset: int, expected: str, found: str) -> None:
    with pytest.raises(ExprError) as info:
        parse(text)
    err = info.value
    assert (err.code, err.offset, err.expected, err.found) == (code, offset, expected, found)


def test_parse_error_hints() -> None:
    with pytest.raises(ExprError) as info:
        parse("sinn(x)")
    assert "'sin'" in info.value.hint
    with pytest.raises(ExprError) as info:
        parse("a == b = c")
    assert "==" in info.value.hint
    assert info.value.context == "a == b = c\n       ^"


def test_relocate() -> None:
    with pytest.raises(ExprError) as info:
        parse("x + )")
    moved = relocate(info.value, Location("s.yaml", 3, 10), "guard")
    assert (moved.location.line, moved.location.column, moved.key) == (3, 14, "guard")
    assert moved.code == "MPG201" and moved.offset == 4 and moved.found == "')'"
    assert str(moved).startswith("s.yaml:3:14 MPG201 guard:")
    unknown = relocate(info.value, Location("s.yaml", 0, 0), "guard")
    assert (unknown.location.line, unknown.location.column) == (0, 0)
    exact = relocate(info.value, Location("s.yaml", 3, 10), "guard", shift=False)
    assert exact.location.column == 10
    assert info.value.location.column == 0  # original untouched


def test_parse_value() -> None:
    assert parse_value(3) == Num(3.0)
    assert parse_value(-1.5) == Num(-1.5)
    assert parse_value("x + 1") == parse("x + 1")
    for bad in (True, None, [1], {"a": 1}):
        with pytest.raises(ExprError) as info:
            parse_value(bad)
        assert info.value.code == "MPG201"


def test_free_names() -> None:
    assert free_names(parse("a * sin(b) + if_else(c, pi, 2)")) == {"a", "b", "c", "pi"}
    assert free_names(parse("1 + 2")) == set()


@pytest.mark.parametrize("text", [
    "-x ^ 2", "(-x) ^ 2", "x ^ y ^ z", "(x ^ y) ^ z", "x ^ -y", "a - (b - c)", "a - b - c",
    "a / (b * c)", "-(a + b)", "not (a and b)", "(not a) < b", "x + (not y)", "(a < b) < c",
    "a < (b < c)", "--x", "a or b and c", "(a or b) and c", "max(a, -b, c ^ 2)",
    "piecewise(x < 0, -1, x > 0, 1, 0)", "0.001 * x", "1e+300", "2.5", "-(not x)",
])
def test_to_text_round_trips(text: str) -> None:
    expr = parse(text)
    assert parse(to_text(expr)) == expr
    assert to_text(parse(to_text(expr))) == to_text(expr)


def _random_expr(rng: random.Random, depth: int):
    if depth == 0 or rng.random() < 0.2:
        return rng.choice([Name(rng.choice("abc")), Num(float(rng.randint(0, 9))),
                           Num(rng.choice([0.5, 1e-7, 3.25e12]))])
    kind = rng.random()
    if kind < 0.2:
        return Unary(rng.choice(["-", "not"]), _random_expr(rng, depth - 1))
    if kind < 0.35:
        func = rng.choice(["sin", "max", "atan2", "clip"])
        lo, _ = FUNCTIONS[func]
        return Call(func, tuple(_random_expr(rng, depth - 1) for _ in range(lo)))
    op = rng.choice(["+", "-", "*", "/", "^", "<", "==", "and", "or"])
    return Binary(op, _random_expr(rng, depth - 1), _random_expr(rng, depth - 1))


def test_to_text_round_trips_random_trees() -> None:
    rng = random.Random(7)
    for _ in range(500):
        expr = _random_expr(rng, 5)
        assert parse(to_text(expr)) == expr, to_text(expr)


def test_to_text_of_negative_constant_keeps_value() -> None:
    expr = Binary("^", Name("x"), Num(-2.0))
    assert evaluate(parse(to_text(expr)), {"x": 2.0}) == 0.25
    assert to_text(Binary("-", Name("x"), Num(-2.0))) == "x - -2"
    assert to_text(Binary("^", Num(-2.0), Name("x"))) == "(-2) ^ x"


def test_equality_ignores_positions() -> None:
    assert parse("x+1") == parse("  x  +  1 ")
    assert hash(parse("x+1")) == hash(parse("x + 1"))


def test_module_does_not_import_casadi() -> None:
    import subprocess
    import sys

    code = ("import sys, mpgspec.spec.expr, mpgspec.spec.yamlpos; "
            "sys.exit('casadi' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
