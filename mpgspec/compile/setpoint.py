"""x*(t) of a primitive (Definition 1): named states, expressions of t, or a table (samples in the
spec or a CSV file next to it), wrapped into one period for periodic primitives."""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import SpecError
from ..spec.loader import PrimitiveInstance
from ..spec.paths import MAX_FILE_BYTES, ReadProblem, clip, clip_repr, confine, in_project, read_text_bounded
from .contacts import wrap_clock
from .expr_casadi import interp_cubic, interp_linear
from .exprs import ExprCompiler
from .system import CompiledSystem


def compile_setpoint(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, consts: dict, contacts,
                     t: ca.SX, tc: ca.SX, period: float | None, ident: str):
    """(setpoint, x*, d/dt x*): the Function t -> x*(t) and x*, its rate, at the wrapped clock tc."""
    x_star_t, table = _setpoint_expr(inst, sys, ec, consts, contacts, t)
    x_star_raw = ca.Function("x_star_raw", [t], [x_star_t])
    x_star = x_star_raw(tc)
    x_star_dot = ca.jacobian(x_star_raw(t), t)
    x_star_dot = ca.substitute(x_star_dot, t, tc)
    setpoint = ca.Function(f"setpoint_{ident}", [t], [x_star])
    if table is not None and len(table[0]) > TABLE_KNOTS:  # a lookup, not a tree of thousands of branches
        setpoint = _table_setpoint(f"setpoint_{ident}", *table, period)
    return setpoint, x_star, x_star_dot


def _setpoint_expr(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, consts: dict, contacts, t: ca.SX):
    """x*(t) as an expression of the raw clock t, and (times, samples, interpolation) of a table."""
    sp = inst.spec.setpoint
    if sp.named is not None:
        return _named(inst, sys, ec, consts, contacts, t), None
    if sp.expr is not None:
        if len(sp.expr) != sys.nx:
            raise SpecError("setpoint needs one expression per state", location=inst.locate(("setpoint", "expr")),
                            key=f"primitive '{inst.name}': setpoint.expr", expected=f"{sys.nx}", found=f"{len(sp.expr)}",
                            code="MPG106")
        return ec.vector(sp.expr, ("setpoint", "expr"), {**consts, "t": t}), None
    if sp.file is not None:
        ts, ys = _samples_from_csv(inst, sys, contacts)
    else:
        if any(len(r) != sys.nx for r in sp.samples):
            raise SpecError("each sample needs one value per state", location=inst.locate(("setpoint", "samples")),
                            key=f"primitive '{inst.name}': setpoint.samples", expected=f"{sys.nx} values",
                            found=f"{sorted({len(r) for r in sp.samples})}", code="MPG106")
        ts = np.asarray(sp.times, float)
        ys = np.asarray(sp.samples, float)
    interp = interp_cubic if sp.interpolation == "cubic" else interp_linear
    return interp(t, ts, ys.reshape(len(ts), sys.nx)), (ts, ys, sp.interpolation)


def _named(inst: PrimitiveInstance, sys: CompiledSystem, ec: ExprCompiler, consts: dict, contacts, t: ca.SX):
    """x*(t) from `named` states, the others at the system's default; with `feet_on_ground`, the
    system puts the lowest foot on the ground."""
    sp = inst.spec.setpoint
    unknown = [k for k in sp.named if k not in sys.state_names]
    if unknown:
        raise SpecError("setpoint names an unknown state", location=inst.locate(("setpoint", "named", unknown[0])),
                        key=f"primitive '{inst.name}': setpoint.named", expected="state names of the system",
                        found=repr(unknown[0]), code="MPG106")
    base = sys.default_state(contacts)
    x_star_t = ca.vertcat(*[ec.sx(sp.named[n], ("setpoint", "named", n), {**consts, "t": t}) if n in sp.named
                            else ca.SX(base[i]) for i, n in enumerate(sys.state_names)])
    if not sp.feet_on_ground:
        return x_star_t
    grounded = sys.ground_setpoint(x_star_t, t)
    if grounded is None:
        raise SpecError("feet_on_ground needs a system with feet", location=inst.locate(("setpoint", "feet_on_ground")),
                        key=f"primitive '{inst.name}': setpoint.feet_on_ground", expected="system kind rigid_body",
                        found="an analytic system", code="MPG108")
    return grounded


def spec_file(inst: PrimitiveInstance, raw: str, where, key: str):
    """(name, path) of a file a primitive names: `{<argument>}` takes the node's value (one file per
    node), and the path must stay inside the project folder or an allowed folder (spec.paths)."""
    for k, v in inst.argument.items():
        raw = raw.replace("{" + k + "}", f"{v:g}")
    if not inst.roots:  # an instance built without the loader: no project folder known
        return raw, (inst.source.parent / raw).resolve()
    return raw, confine(raw, inst.source.parent, inst.roots, where=where, key=key)


def _samples_from_csv(inst: PrimitiveInstance, sys: CompiledSystem, contacts) -> tuple[np.ndarray, np.ndarray]:
    """Times and full-state samples of a setpoint table; states without a column take their default.

    The table must lie inside the project folder (or an allowed folder), be a regular UTF-8 file
    of at most MAX_FILE_BYTES, name each column once and hold finite numbers; errors never echo
    more than a short piece of a line, and nothing of a table outside the project folder.
    """
    where = inst.locate(("setpoint", "file"))
    key = f"primitive '{clip(inst.name, 60)}': setpoint.file"
    raw, path = spec_file(inst, inst.spec.setpoint.file, where, key)
    quote = in_project(path, inst.roots)

    def fail(msg, expected, found, line=0):
        loc = where if not line else type(where)(str(path), line, 1, quote)
        raise SpecError(msg, location=loc, key=key, expected=expected, found=found, code="MPG110")

    try:
        lines = ["" if ln.startswith("#") else ln for ln in read_text_bounded(path, MAX_FILE_BYTES).splitlines()]
    except ReadProblem as p:
        fail(f"cannot read the setpoint table: {p.message}", p.expected or "a CSV file relative to the spec",
             f"{clip_repr(raw)} ({p.found})" if p.found else clip_repr(raw))
    first = next((k for k, ln in enumerate(lines) if ln.strip()), len(lines))  # after `# key: value` lines
    header = [h.strip() for h in lines[first].split(",")] if first < len(lines) else []
    if not header or header[0] != "t":
        fail("the first column must be the time", "a header 't,<state>,...'",
             clip_repr(lines[first] if first < len(lines) else ""), first + 1)
    unknown = [h for h in header[1:] if h not in sys.state_names]
    if unknown:
        fail("unknown state in the header", "state names of the system", clip_repr(unknown[0]), first + 1)
    twice = _named_twice(header)
    if twice:
        fail("a column is named twice in the header", "each state in one column at most",
             f"{clip_repr(twice[0])} in columns {twice[1]} and {twice[2]}", first + 1)
    rows = []
    for n, text in enumerate(lines[first + 1:], start=first + 2):
        if not text.strip():
            continue
        try:
            vals = [float(v) for v in text.split(",")]
        except ValueError:
            fail("not a number", "numbers separated by commas", repr(text[:60]), n)
        if not all(np.isfinite(vals)):
            fail("not a finite number", "finite numbers (no nan or inf)", repr(text[:60]), n)
        if len(vals) != len(header):
            fail("wrong number of columns", f"{len(header)}", f"{len(vals)}", n)
        rows.append(vals)
    data = np.asarray(rows, float).reshape(-1, len(header))
    if data.shape[0] < 2 or np.any(np.diff(data[:, 0]) <= 0):
        fail("times must be strictly increasing, with at least two rows", "increasing t", f"{data.shape[0]} rows")
    ys = np.tile(sys.default_state(contacts), (data.shape[0], 1))
    for j, name in enumerate(header[1:], start=1):
        ys[:, sys.state_names.index(name)] = data[:, j]
    return data[:, 0], ys


def _named_twice(header: list[str]) -> tuple[str, int, int] | None:
    """The first column name that appears again and both its column numbers (1-based): a second
    column of a state would silently replace the first."""
    seen: dict[str, int] = {}
    for k, name in enumerate(header, start=1):
        if name in seen:
            return name, seen[name], k
        seen[name] = k
    return None


TABLE_KNOTS = 64
"""Tabulated setpoints with more samples than this are evaluated by a linear lookup (CasADi's
interpolant) in an MX Function instead of an SX expression tree."""


def _table_setpoint(name: str, ts: np.ndarray, ys: np.ndarray, interpolation: str, period) -> ca.Function:
    """t -> x*(t) from a table by linear lookup, held outside its range, wrapped into one period."""
    if interpolation != "linear":
        ts_f = np.linspace(ts[0], ts[-1], 8 * len(ts))  # cubic tables: sampled densely, then linear
        from scipy.interpolate import CubicSpline  # imported when used: scipy's start-up is a process's slowest
        ys, ts = CubicSpline(ts, ys, axis=0)(ts_f), ts_f
    lookup = ca.interpolant(name + "_lookup", "linear", [np.asarray(ts, float)],
                            np.asarray(ys, float).ravel(order="C"))
    t = ca.MX.sym("t")
    tc = wrap_clock(t, period)
    return ca.Function(name, [t], [lookup(ca.fmin(ca.fmax(tc, float(ts[0])), float(ts[-1])))])
