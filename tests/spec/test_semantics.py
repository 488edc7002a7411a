"""Semantic checks of specs from untrusted pull requests: nothing passes by accident, and no user
mistake gives an internal error (MPG900) or a traceback.

Each case writes a small single-file project to tmp_path and runs it through `mpgspec.api.verify`
(or the loader and compiler), then checks the exit code, the error code and the shape of the
message: `project.yaml:LINE:COL CODE key: message; expected ...; found ...`.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec import api
from mpgspec.compile.expr_casadi import to_casadi
from mpgspec.compile.closed_loop import function_name as _ident
from mpgspec.spec.expr import MAX_DEPTH, evaluate, parse
from mpgspec.spec.loader import load_project

BASE = """\
project: sem
system:
  name: line
  kind: analytic
  states: [x]
  inputs: [u]
  parameters: {k: 2}
  dynamics: {f: ["0"], g: [[1]]}
  input_bounds: {u: [-10, 10]}
primitives:
  - name: A
    class: fixed
    setpoint: {expr: [0]}
    controller: {type: expression, u: ["-k*x"]}
    safe_set: [{name: wall, h: "2 - x"}]
    roa: {radius: 0.1}
  - name: B
    class: fixed
    setpoint: {expr: [1]}
    controller: {type: expression, u: ["-k*(x - 1)"]}
    roa: {radius: 0.1}
oracle: {horizon: 3, dt: 0.01, accuracy: low, grid: {t_A: 2, t_B: 2}}
"""
FAST = {"jit": False}
LOCATED = re.compile(r"project\.yaml:(\d+):(\d+) (MPG\d{3}) ")


def edit(*pairs: str, text: str = BASE) -> str:
    """BASE with each (old, new) pair replaced exactly once."""
    for old, new in zip(pairs[::2], pairs[1::2]):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


def line_of(text: str, needle: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), 1) if needle in ln)


def run(tmp_path: Path, text: str):
    path = tmp_path / "project.yaml"
    path.write_text(text)
    res = api.verify([path], out_dir=None, overrides=FAST)
    (p,) = res.projects
    for e in p.errors:  # never an internal error, never a traceback
        assert e["code"] != "MPG900", e
        assert "Traceback" not in e.get("text", ""), e
    return res.exit_code, p


def spec_error(tmp_path: Path, text: str, code: str, *parts: str, at: str | None = None) -> dict:
    """The run exits with 2 and reports `code` at file:line:col; `parts` are in its text; `at` is a
    piece of the offending line."""
    rc, p = run(tmp_path, text)
    assert rc == 2, p.errors
    hits = [e for e in p.errors if e["code"] == code]
    assert hits, [e.get("text") for e in p.errors]
    err = hits[0]
    m = LOCATED.search(err["text"])
    assert m, err["text"]
    assert int(m.group(1)) >= 1 and int(m.group(2)) >= 1
    for part in parts:
        assert part in err["text"], err["text"]
    if at is not None:
        assert err["line"] == line_of(text, at), err["text"]
    return err


# ----------------------------------------------------------------------------- booleans are not numbers
def test_yaml_boolean_as_safety_function(tmp_path):
    text = edit('{name: wall, h: "2 - x"}', "{name: wall, h: true}")
    err = spec_error(tmp_path, text, "MPG104", "boolean", "number-valued expression", at="h: true")
    assert err["key"].endswith("safe_set.0.h")


def test_comparison_as_control_law(tmp_path):
    text = edit('u: ["-k*x"]', 'u: ["x > 0"]')
    err = spec_error(tmp_path, text, "MPG206", "controller.u.0", "a comparison is not a number",
                     "expected a number-valued expression", "found 'x > 0'", at='u: ["x > 0"]')
    assert err["column"] == text.splitlines()[err["line"] - 1].index("x > 0") + 1 + 2  # at the '>'


def test_logic_inside_arithmetic_of_a_safety_function(tmp_path):
    text = edit('h: "2 - x"', 'h: "2 - (x < 1 and x > -1)"')
    spec_error(tmp_path, text, "MPG206", "safe_set.0.h", "logical 'and'", "an operand of '-'")


def test_comparison_as_setpoint_and_boolean_parameter(tmp_path):
    spec_error(tmp_path, edit("setpoint: {expr: [1]}", 'setpoint: {expr: ["t >= 0"]}'), "MPG206",
               "setpoint.expr.0", "number-valued")
    spec_error(tmp_path, edit("parameters: {k: 2}", "parameters: {k: true}"), "MPG104",
               "parameters.k", "boolean", at="parameters: {k: true}")


def test_comparisons_stay_allowed_in_conditions(tmp_path):
    text = edit('u: ["-k*x"]', 'u: ["if_else(x > 0 and not (x > 5), -k*x, piecewise(x < -1, 1, -x))"]')
    prims = api.compile_project(load_project(_write(tmp_path, text)))
    u = prims["A"].control(np.array([0.5]), 0.0, 0.0, np.array([0.0]))[0]
    assert float(u) == pytest.approx(-1.0)


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "project.yaml"
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- NaN propagates
NAN_CASES = ["min(a, b)", "max(a, b)", "min(a, b, 1)", "clip(a, -1, b)", "sat(b, a, 3)", "if_else(a > 0, 1, 2)",
             "piecewise(a < 0, 1, b > 0, 2, 3)", "norm_inf(a, b)", "if_else(a < b or b > 3, 1, 0)",
             "if_else(not (a > 0), 1, 0)"]


@pytest.mark.parametrize("kind", [ca.SX, ca.MX], ids=["SX", "MX"])
@pytest.mark.parametrize("text", NAN_CASES)
def test_nan_is_never_swallowed(kind, text):
    a, b = kind.sym("a"), kind.sym("b")
    f = ca.Function("f", [a, b], [to_casadi(parse(text), {"a": a, "b": b})])
    for args in [(math.nan, 1.0), (1.0, math.nan)]:
        if math.isnan(args[1]) and "b" not in text:
            continue
        assert math.isnan(float(f(*args))), (text, args)
        assert math.isnan(evaluate(parse(text), dict(zip("ab", args)))), (text, args)
    assert not math.isnan(float(f(0.5, -2.0)))


def test_min_of_h_and_nan_in_the_compiled_safety_function(tmp_path):
    text = edit('h: "2 - x"', 'h: "min(2 - x, sqrt(x + 1))"')
    prim = api.compile_project(load_project(_write(tmp_path, text)))["A"]
    h = lambda x: float(prim.h(np.array([x]), 0.0, 0.0, np.array([0.0])))  # noqa: E731
    assert h(0.0) == pytest.approx(1.0)
    assert math.isnan(h(-3.0))  # sqrt(-2) is NaN: fmin would have answered 5


def test_nan_input_bound_rejected_infinite_allowed(tmp_path):
    spec_error(tmp_path, edit("u: [-10, 10]", "u: [.nan, 1]"), "MPG104", "input_bounds.u.0", "NaN",
               at="input_bounds")
    prims = api.compile_project(load_project(_write(tmp_path, edit("u: [-10, 10]", "u: [-.inf, 10]"))))
    sys = prims["A"].system
    assert sys.u_lo[0] == -math.inf and sys.u_hi[0] == 10


@pytest.mark.parametrize("old, new, key", [
    ("horizon: 3", "horizon: .inf", "oracle.horizon"),
    ("dt: 0.01", "dt: .inf", "oracle.dt"),
    ("accuracy: low", "accuracy: low, h_tolerance: .inf", "oracle.h_tolerance"),
    ("roa: {radius: 0.1}\n  - name: B", "roa: {radius: .nan}\n  - name: B", "roa.radius"),
])
def test_infinite_or_nan_settings_rejected(tmp_path, old, new, key):
    spec_error(tmp_path, edit(old, new), "MPG104", key, "finite")


def test_constants_must_evaluate_to_numbers(tmp_path):
    spec_error(tmp_path, edit("  - name: B\n", "  - name: B\n    let: {w: inf - inf}\n"), "MPG205", "let.w", "NaN",
               at="let: {w")
    periodic = edit("  - name: B\n    class: fixed\n", "  - name: B\n    class: periodic\n    period: 2*inf\n")
    spec_error(tmp_path, periodic, "MPG205", "period", "finite", at="period:")


@pytest.mark.parametrize("when, ok", [("[0.5, 1.5]", True), ("[0, 2]", True), ("[2.5, 3]", False), ("[1, 2.5]", False),
                                      ("[-1, 1]", False)])
def test_a_periodic_primitives_windows_lie_in_its_period(tmp_path, when, ok):
    text = edit("  - name: B\n    class: fixed\n", "  - name: B\n    class: periodic\n    period: 2\n",
                "{name: wall, h: \"2 - x\"}", f"{{name: wall, h: \"2 - x\", when: {when}}}",
                "  - name: A\n    class: fixed\n", "  - name: A\n    class: periodic\n    period: 2\n")
    if ok:
        assert run(tmp_path, text)[0] in (0, 1)
    else:
        err = spec_error(tmp_path, text, "MPG104", "outside the primitive's period", "safe_set.0.when", at="when:")
        assert "within [0, 2]" in err["expected"]


@pytest.mark.parametrize("h", ["1/0", "0/0", "-1/0"])
def test_a_safety_function_that_is_no_finite_constant_is_refused(tmp_path, h):
    text = edit("{name: wall, h: \"2 - x\"}", f"{{name: wall, h: \"{h}\"}}")
    spec_error(tmp_path, text, "MPG205", "safe_set.0.h", "not a finite number", at="wall")


@pytest.mark.parametrize("radius", ["1e300", "1e9"])
def test_a_region_of_attraction_reaching_far_outside_c_fails_its_check(tmp_path, radius):
    """E larger than C: h on E's boundary is hugely negative, never taken for a parked (inactive) h."""
    rc, p = run(tmp_path, edit("roa: {radius: 0.1}\n  - name: B", f"roa: {{radius: {radius}}}\n  - name: B"))
    (chk,) = [a for a in p.report["assumptions"] if a["primitive"] == "A" and a["name"] == "roa_in_safe_set"]
    assert rc == 1 and chk["status"] == "fail" and chk["numbers"]["min_h"] < -1e8, chk


@pytest.mark.parametrize("own, block, at", [("2 - zz", "3 - x", "name: own"), ("2 - x", "3 - yy", "name: w2")])
def test_an_error_in_a_used_block_points_at_the_block(tmp_path, own, block, at):
    """A project block's function is located where the block writes it, and a primitive's own
    function after a block at its own entry (not at the resolved list's index)."""
    text = edit("safe_set: [{name: wall, h: \"2 - x\"}]", f"safe_set: [{{use: walls}}, {{name: own, h: \"{own}\"}}]")
    text += f"safe_sets:\n  walls:\n    - {{name: w1, h: \"1 - x\"}}\n    - {{name: w2, h: \"{block}\"}}\n"
    spec_error(tmp_path, text, "MPG204", at=at)


# ----------------------------------------------------------------------------- no shadowing
@pytest.mark.parametrize("insert, key, what", [
    ("    let: {x: 3}\n", "let.x", "a state of the system"),
    ("    let: {u: 3}\n", "let.u", "an input of the system"),
    ("    let: {pi: 3}\n", "let.pi", "a built-in constant"),
    ("    let: {k: 3}\n", "let.k", "a parameter of the system"),
    ("    let: {x_star: 3}\n", "let.x_star", "the setpoint of state x"),
    ("    arguments: {sin: [1, 2]}\n", "arguments.sin", "a function of the expression language"),
    ("    arguments: {t: [1, 2]}\n", "arguments.t", "the primitive's clock"),
])
def test_let_and_arguments_shadow_nothing(tmp_path, insert, key, what):
    text = edit("  - name: B\n", "  - name: B\n" + insert)
    spec_error(tmp_path, text, "MPG105", key, f"({what})", "shadows", at=insert.strip()[:8])


@pytest.mark.parametrize("params, what", [("{e: 2}", "a built-in constant"), ("{s: 2}", "the time since switch-in"),
                                          ("{max: 2}", "a function of the expression language")])
def test_parameters_shadow_nothing(tmp_path, params, what):
    spec_error(tmp_path, edit("parameters: {k: 2}", f"parameters: {params}"), "MPG105", "shadows", what,
               at="parameters:")


# ----------------------------------------------------------------------------- enumerated options
def test_roa_method_typo_gets_a_suggestion(tmp_path):
    text = edit("roa: {radius: 0.1}\n  - name: B", "roa: {method: lyapnov}\n  - name: B")
    err = spec_error(tmp_path, text, "MPG104", "roa.method", "unknown region-of-attraction method",
                     "did you mean 'lyapunov'?", at="method: lyapnov")
    assert "given" in err["expected"] and "sos" in err["expected"]


@pytest.mark.parametrize("key, suggestion", [("QQ", "'Q'"), ("mult_half_degre", "'mult_half_degree'")])
def test_unknown_verifier_option(tmp_path, key, suggestion):
    text = edit("roa: {radius: 0.1}\n  - name: B", f"roa: {{method: lyapunov, options: {{{key}: 1}}}}\n  - name: B")
    err = spec_error(tmp_path, text, "MPG102", f"roa.options.{key}", "unknown option of the lyapunov verifier",
                     f"did you mean {suggestion}?", at="options:")
    assert "tol_eig" in err["expected"]  # the accepted keys are listed


def test_given_radius_takes_no_options(tmp_path):
    text = edit("roa: {radius: 0.1}\n  - name: B", "roa: {radius: 0.1, options: {samples: 9}}\n  - name: B")
    spec_error(tmp_path, text, "MPG102", "roa.options.samples", "takes no options")


@pytest.mark.parametrize("method, options, key, found", [
    ("lyapunov", "{degree: 50}", "degree", "50"),            # a 41 GB Gram matrix before any message
    ("sos", "{samples: 100000000}", "samples", "100000000"),
    ("floquet", "{steps: 0}", "steps", "0"),
    ("floquet", "{steps: abc}", "steps", "'abc'"),
    ("sampling", "{samples: 1e8}", "samples", "100000000.0"),
    ("sampling", "{rtol: 2}", "rtol", "2"),
])
def test_verifier_sizes_and_types_are_bounded_before_work_starts(tmp_path, method, options, key, found):
    text = edit("roa: {radius: 0.1}\n  - name: B", f"roa: {{method: {method}, options: {options}}}\n  - name: B")
    err = spec_error(tmp_path, text, "MPG104", f"roa.options.{key}", f"invalid option of the {method} verifier")
    assert err["found"] == found


# ----------------------------------------------------------------------------- the robust stage's budget
def test_a_robust_stage_beyond_its_budget_is_refused_before_it_starts(tmp_path):
    unc = ("uncertainty:\n  parameters: {k: {range: [1, 3]}}\n  disturbance: {inputs: [u], bound: 1}\n"
           "  corners: 1024\n  samples: 1000\n  cells: 1000\n  search: 50\n")
    err = spec_error(tmp_path, BASE + unc, "MPG104", "more rollouts than its budget", "uncertainty",
                     at="uncertainty:")
    assert "at most 1,000,000" in err["expected"] and "2 edges x 1000 cells" in err["found"]
    err = spec_error(tmp_path, BASE + unc + "  budget: 1000\n", "MPG104", "uncertainty.budget", at="budget: 1000")


def test_an_empty_parameter_box_runs_the_nominal_scenario(tmp_path):
    unc = "uncertainty:\n  parameters: {}\n  disturbance: {inputs: [u], bound: 0.5}\n  samples: 0\n  runs: 0\n"
    rc, p = run(tmp_path, BASE + unc)
    assert rc == 0 and p.report["robust"]["scenarios"]["per_cell"] == 3, p.errors


# ----------------------------------------------------------------------------- transient hand-overs
TRANSIENT_B = "  - name: B\n    class: transient\n    domain: [0, 1]\n    next: {next}\n"


def test_transient_next_to_itself(tmp_path):
    text = edit("  - name: B\n    class: fixed\n", TRANSIENT_B.format(next="B"))
    spec_error(tmp_path, text, "MPG306", "next", "cycle", "B -> B", at="next: B")


def test_cycle_of_transients(tmp_path):
    text = edit("  - name: B\n    class: fixed\n", TRANSIENT_B.format(next="A"),
                "  - name: A\n    class: fixed\n", "  - name: A\n    class: transient\n    domain: [0, 1]\n    next: B\n")
    err = spec_error(tmp_path, text, "MPG306", "A -> B -> A")
    assert sum(e["code"] == "MPG306" for e in run(tmp_path, text)[1].errors) == 1  # one cycle, one error
    assert err["line"] in (line_of(text, "next: A"), line_of(text, "next: B"))


def test_next_must_name_an_existing_primitive(tmp_path):
    text = edit("  - name: B\n    class: fixed\n", TRANSIENT_B.format(next="Bee"))
    spec_error(tmp_path, text, "MPG304", "next", "'Bee'", at="next: Bee")


# ----------------------------------------------------------------------------- former internal errors
def test_negative_and_fractional_argument_values(tmp_path):
    text = edit("  - name: B\n", "  - name: B\n    arguments: {amp: [-1.0, 2.5]}\n",
                "setpoint: {expr: [1]}", "setpoint: {expr: [amp]}", '"-k*(x - 1)"', '"-k*(x - amp)"')
    rc, p = run(tmp_path, text)
    assert rc in (0, 1) and not p.errors
    assert {"B(-1)", "B(2.5)"} <= {q["name"] for q in p.report["primitives"]}


@pytest.mark.parametrize("name", ["B(-1)", "B(1)", "_B", "A__B", "W(slow down)", "Zé(1)", "B(1e-05)"])
def test_function_names_are_valid_and_distinct(name):
    x = ca.SX.sym("x")
    ca.Function(f"f_cl_{_ident(name)}", [x], [x])  # CasADi accepts it
    assert _ident(name) != _ident(name + "x")
    assert _ident("B(-1)") != _ident("B(1)")


@pytest.mark.parametrize("old, new, key", [
    ("project: sem", "project: sem\ndescription: [a, b]", "description"),
    ("  - name: B\n", "  - name: [B]\n", "name"),
    ("{name: wall,", "{name: {w: 1},", "safe_set.0.name"),
])
def test_text_field_given_a_list_or_mapping(tmp_path, old, new, key):
    spec_error(tmp_path, edit(old, new), "MPG104", key, "expected text")


def test_lqr_with_zero_mass_names_the_controller(tmp_path):
    text = edit("parameters: {k: 2}", "parameters: {k: 2, m: 0}", 'g: [[1]]', 'g: [["m"]]',
                'controller: {type: expression, u: ["-k*x"]}', "controller: {type: lqr, Q: [1], R: [1]}")
    spec_error(tmp_path, text, "MPG111", "primitive 'A': controller", "not stabilisable", at="type: lqr")


@pytest.mark.parametrize("Q, R, part", [("[1]", "[0]", "R must be positive definite"),
                                        ("[-1]", "[1]", "Q must be positive semidefinite"),
                                        ("[1, 2]", "[1]", "Q must be 1 numbers")])
def test_lqr_ill_posed_weights(tmp_path, Q, R, part):
    text = edit('controller: {type: expression, u: ["-k*x"]}', f"controller: {{type: lqr, Q: {Q}, R: {R}}}")
    code = "MPG106" if "numbers" in part else "MPG111"
    spec_error(tmp_path, text, code, part, "controller", at="type: lqr")


def test_lqr_with_non_finite_dynamics_at_the_setpoint(tmp_path):
    text = edit('f: ["0"]', 'f: ["sqrt(x - 1)"]', 'controller: {type: expression, u: ["-k*x"]}',
                "controller: {type: lqr, Q: [1], R: [1]}")
    spec_error(tmp_path, text, "MPG111", "not finite at the setpoint")


def test_blow_up_in_a_sequence_is_an_unsafe_run(tmp_path):
    text = edit("  input_bounds: {u: [-10, 10]}\n", "", '"-k*(x - 1)"', '"x^3*x^3 + 1"') + (
        "assertions:\n  - simulation_safe: naive\n  - simulation_safe: naive\n    expect: false\n"
        "sequence: {start: A, duration: 3, commands: [{t: 0.1, goal: B}]}\n")
    rc, p = run(tmp_path, text)
    assert rc == 1
    sims = [a for a in p.report["assertions"] if a["kind"] == "simulation_safe"]
    assert [a["status"] for a in sims] == ["fail", "pass"]
    assert "non-finite state" in sims[0]["message"]
    assert p.report["sequence"]["runs"]["naive"]["safe"] is False


def test_long_sums_compile_and_deep_nesting_is_limited(tmp_path):
    long_sum = "-k*x + " + " + ".join(["0.001*sin(x)"] * 1000)
    prims = api.compile_project(load_project(_write(tmp_path, edit('"-k*x"', f'"{long_sum}"'))))
    u = float(prims["A"].control(np.array([0.5]), 0.0, 0.0, np.array([0.0]))[0])
    assert u == pytest.approx(-1.0 + math.sin(0.5))
    deep = "(" * 500 + "-k*x" + ")" * 500
    spec_error(tmp_path, edit('"-k*x"', f'"{deep}"'), "MPG207",
               f"expression nested too deeply (limit {MAX_DEPTH})", "controller.u.0")
    spec_error(tmp_path, edit('"-k*x"', '"' + "x^" * 300 + 'x"'), "MPG207", "nested too deeply")


def test_pd_output_must_be_a_function_of_the_state(tmp_path):
    text = edit('controller: {type: expression, u: ["-k*x"]}',
                'controller: {type: pd, outputs: ["x + s"], kp: [1], kd: [1]}')
    spec_error(tmp_path, text, "MPG106", "controller.outputs.0", "depend only on the state", "names s")


def test_the_unchanged_base_project_verifies(tmp_path):
    rc, p = run(tmp_path, BASE)
    assert rc in (0, 1) and not p.errors and p.report is not None


# ----------------------------------------------------------------------------- sequence.keep
SEQ = "sequence:\n  start: A\n  duration: 1\n  commands: [{t: 0, goal: B}]\n  keep: {KEEP}\n"


def test_keep_must_name_a_safety_function_family(tmp_path):
    err = spec_error(tmp_path, BASE + SEQ.replace("KEEP", "wal: 1"), "MPG304", "unknown safety function family",
                     "'wal'", "wall", at="keep:")
    assert err["key"] == "sequence.keep.wal"


@pytest.mark.parametrize("keep", ["'wall[0]': 1", "wall: -1", "wall: 0", "wall: .nan"])
def test_keep_needs_a_family_and_a_positive_value(tmp_path, keep):
    rc, p = run(tmp_path, BASE + SEQ.replace("KEEP", keep))
    assert rc == 2 and p.errors and "keep" in p.errors[0]["text"], p.errors


def test_keep_of_a_known_family_runs(tmp_path):
    rc, p = run(tmp_path, BASE + SEQ.replace("KEEP", "wall: 1"))
    assert rc in (0, 1) and not p.errors
    assert p.report["lookup_table"]["keep"] == {"wall": 1.0}
