"""The compact forms report.json uses (schema 2): columnar oracle cells and sequence runs, rounded
floats, and the functions that turn them back into one dict per cell or one row per sample.

- A transition's `cells` holds one grid per field (`cells["margin"][i_A][i_B]`); per-input and
  per-safety-function fields hold one grid per component (`cells["min_margins"][k][i_A][i_B]`,
  k in the order of `h_families`, the functions grouped by family, or of `h_names`); `status`, `reason` and the flags `checked`, `refined`,
  `saturated` are one string of digits per t_A row (a character per t_B: the index into STATUS
  or REASONS, 0/1 for flags), `violated` an index into the target's safety functions (`h_names`
  before 2.2, the target primitive's `safety_functions` since; or null), and non-empty
  messages are listed sparsely as `[i_A, i_B, text]`; the verdict of a cell is the transition's
  `verdicts[i_A][i_B]`. `method` (schema 2.1) is a string of digits per row too, an index into
  METHODS: how the cell's verdict was obtained (a backend's other names count as simulated, never
  as certified); reports without it are simulated throughout.
- A sequence run stores at most MAX_RUN samples, its first RUN_STATES states by column (`x[k]` is
  state k over `t`) and the active primitive as runs `[[name, samples], ...]`; its `body` series (CoM height,
  trunk angles) are sampled at the same `t`; switches, violations and poses are kept in full.
- Floats keep 6 significant digits (oracle evidence, times; error bounds 3, peak inputs and per-function margins 4); plotted traces keep 4
  and at most MAX_TRACE samples (every k-th, the last, and the first at or after the decision).
- A trace (schema 2.2) keeps what its picture shows: the BINDING safety functions (the violated one
  first, then those with the least minimum), `h_least` (the least of all `h_count` functions at each
  sample: the safety margin) and the RoA margin; not the states and inputs.
"""
from __future__ import annotations

import math

STATUS = ("safe", "unsafe", "inconclusive")
REASONS = ("entered_E", "left_C", "horizon_reached", "integration_failed", "inconclusive", "error")
METHODS = ("simulated", "certified", "validated", "empirical")
"""certified: proved; validated: validated integration that proved neither verdict; simulated: a rollout."""
CELL_NUMBERS = ("t_stop", "t_enter", "margin", "error_bound", "best_roa_margin")
CELL_VECTORS = ("peak_input", "peak_demand", "min_margins")
CELL_FLAGS = ("checked", "refined", "saturated")
DIGITS, TRACE_DIGITS, BOUND_DIGITS = 6, 4, 3
MAX_TRACE, MAX_RUN = 200, 600
BINDING = 3
"""Safety functions a trace keeps by name."""
TRACE_BUDGET = 5600
"""Samples of all a report's traces together: each keeps min(MAX_TRACE, TRACE_BUDGET / traces)."""
RUN_STATES = 8
"""States a sequence run keeps (the first ones: a floating base's pose); the rest are not drawn."""


def rnd(v, digits: int = DIGITS):
    """v with every float rounded to `digits` significant digits (non-finite -> None), recursively."""
    if isinstance(v, bool) or v is None or isinstance(v, (str, int)) and not isinstance(v, float):
        return v
    if isinstance(v, float):
        return float(f"{v:.{digits}g}") if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: rnd(x, digits) for k, x in v.items()}
    if isinstance(v, (list, tuple)):  # the long series of traces: no recursive call per finite float
        fmt = f"{{:.{digits}g}}".format
        return [float(fmt(x)) if type(x) is float and -math.inf < x < math.inf else rnd(x, digits) for x in v]
    try:  # numpy scalars
        return rnd(float(v), digits)
    except (TypeError, ValueError):
        return v


def compact_cells(rows: list[list[dict]], h_names: list[str]) -> dict:
    """One grid per field from a grid of cell dicts (see the module docstring)."""
    hidx = {h: k for k, h in enumerate(h_names)}
    def code(v, table, other):
        return str(table.index(v) if v in table else table.index(other))

    out: dict = {
        "status": ["".join(code(c["status"], STATUS, "unsafe") for c in row) for row in rows],
        "reason": ["".join(code(c["reason"], REASONS, "error") for c in row) for row in rows],
        "violated": [[hidx.get(c["violated"]) if c.get("violated") is not None else None for c in row] for row in rows],
        "method": ["".join(code(c.get("method", "simulated"), METHODS, "simulated") for c in row) for row in rows],
    }
    for k in CELL_NUMBERS:
        out[k] = [[rnd(c.get(k), BOUND_DIGITS if k == "error_bound" else DIGITS) for c in row] for row in rows]
    for k in CELL_VECTORS:
        n = max((len(c.get(k) or []) for row in rows for c in row), default=0)
        d = TRACE_DIGITS  # 4 digits of a torque, a force or a margin: what tables and plots show
        out[k] = [[[rnd((c.get(k) or [])[m], d) if m < len(c.get(k) or []) else None for c in row] for row in rows]
                  for m in range(n)]
    for k in CELL_FLAGS:
        out[k] = ["".join("1" if c.get(k) else "0" for c in row) for row in rows]
    out["messages"] = [[i, j, c["message"]] for i, row in enumerate(rows) for j, c in enumerate(row) if c.get("message")]
    return out


def expand_cells(tr: dict) -> list[list[dict]]:
    """A transition's cells as a grid of dicts (verdict, status, reason, ... message)."""
    c = tr.get("cells")
    if isinstance(c, list):  # already one dict per cell
        return c
    if not c:
        return [[{"verdict": v, "status": "safe" if v else "unsafe", "reason": "entered_E" if v else "left_C"}
                 for v in row] for row in tr.get("verdicts", [])]
    h_names, verdicts = tr.get("h_names", []), tr.get("verdicts", [])
    msgs = {(i, j): m for i, j, m in c.get("messages", [])}
    rows = []
    for i, vrow in enumerate(verdicts):
        row = []
        for j, v in enumerate(vrow):
            s, r, h = c["status"][i][j], c["reason"][i][j], c["violated"][i][j]
            cell = {"verdict": v, "status": STATUS[int(s)], "reason": REASONS[int(r)],
                    "violated": h_names[h] if h is not None and h < len(h_names) else None}
            for k in CELL_NUMBERS:
                cell[k] = c[k][i][j]
            for k in CELL_VECTORS:
                cell[k] = [comp[i][j] for comp in c[k]]
            for k in CELL_FLAGS:
                cell[k] = c[k][i][j] == "1"
            cell["message"] = msgs.get((i, j), "")
            cell["method"] = METHODS[int(c["method"][i][j])] if c.get("method") else "simulated"
            row.append(cell)
        rows.append(row)
    return rows


def _every(n: int, m: int) -> list[int]:
    idx = list(range(0, n, max(1, math.ceil(n / m))))
    return idx + [n - 1] if n and idx[-1] != n - 1 else idx


def trace_samples(n_traces: int) -> int:
    """Samples each of n_traces traces keeps under TRACE_BUDGET (at least 40, at most MAX_TRACE)."""
    return max(40, min(MAX_TRACE, TRACE_BUDGET // max(1, n_traces)))


def h_families(h_names: list[str]) -> tuple[list[str], list[list[str]]]:
    """Safety functions grouped by family, the name before an index (friction_cone[FR_foot] ->
    friction_cone[4]): the family names and their members, in order of first appearance. A family of
    one function keeps its full name."""
    groups: dict[str, list[str]] = {}
    for k in h_names:
        groups.setdefault(k.split("[", 1)[0], []).append(k)
    names = [ms[0] if len(ms) == 1 else f"{fam}[{len(ms)}]" for fam, ms in groups.items()]
    return names, list(groups.values())


def binding(h: dict, violated: str | None = None, k: int = BINDING) -> list[str]:
    """The k safety functions a trace is drawn with: the violated one, then the least ones."""
    low = {n: min((v for v in c if v is not None), default=math.inf) for n, c in h.items()}
    names = sorted(h, key=lambda n: (n != violated, low[n]))
    return names[:k]


def least(h: dict, n: int) -> list:
    """The least of the functions in h at each of n samples (None where none has a value)."""
    cols = list(h.values())
    return [min((c[i] for c in cols if i < len(c) and c[i] is not None), default=None) for i in range(n)]


def compact_series(s: dict, t_keep=None, violated: str | None = None, samples: int = MAX_TRACE) -> dict:
    """A dense rollout for pictures: at most `samples` samples (every k-th, the first at or after
    t_keep and the one where the safety margin is least), values rounded to TRACE_DIGITS (times to
    DIGITS); its safety functions reduced to the binding ones and their least (see the module
    docstring), states and inputs left out."""
    if "t" not in s:
        return dict(s)
    s = {k: v for k, v in s.items() if k not in ("x", "u")}
    h = s.get("h")
    if isinstance(h, dict) and h:
        s["h_least"] = least(h, len(s["t"]))
        s["h_count"] = len(h)
        s["h"] = {n: h[n] for n in binding(h, violated)}
    t = list(s["t"])
    n = len(t)
    idx = set(_every(n, samples))
    if t_keep is not None:
        k = next((i for i, v in enumerate(t) if v is not None and v >= t_keep - 1e-9), None)
        if k is not None:
            idx.add(k)
    low = [(v, i) for i, v in enumerate(s.get("h_least") or []) if v is not None]
    if low:
        idx.add(min(low)[1])
    idx = sorted(idx)

    def pick(v):
        return [v[i] for i in idx if i < len(v)]

    out = {}
    for key, v in s.items():
        if key == "t":
            out[key] = rnd(pick(v))
        elif key == "crossings":  # located guard crossings: a count and their times, not a series
            out[key] = {"count": v.get("count"), "t": rnd(v.get("t") or [])}
        elif key == "h_count":
            out[key] = v
        elif isinstance(v, dict):
            out[key] = {name: rnd(pick(c), TRACE_DIGITS) for name, c in v.items()}
        elif isinstance(v, list) and v and isinstance(v[0], list):
            out[key] = [rnd(pick(c), TRACE_DIGITS) for c in v]
        elif isinstance(v, list):
            out[key] = rnd(pick(v), TRACE_DIGITS)
        else:
            out[key] = v
    return out


def compact_run(run: dict) -> dict:
    """A sequence run with its states by column and the active primitive run-length encoded."""
    out = dict(run)
    idx = _every(len(run.get("t") or []), MAX_RUN)
    x = [run["x"][i] for i in idx if i < len(run.get("x") or [])]
    n = max((len(r) for r in x), default=0)
    out["x"] = [rnd([r[k] if k < len(r) else None for r in x], TRACE_DIGITS) for k in range(min(n, RUN_STATES))]
    out["t"] = rnd([run["t"][i] for i in idx])
    out["min_h"] = rnd([run["min_h"][i] for i in idx if i < len(run.get("min_h") or [])], TRACE_DIGITS)
    active: list = []
    for name in [run["active"][i] for i in idx if i < len(run.get("active") or [])]:
        if active and active[-1][0] == name:
            active[-1][1] += 1
        else:
            active.append([name, 1])
    out["active"] = active
    out["switches"] = rnd(run.get("switches") or [])
    out["violations"] = rnd(run.get("violations") or [])
    out["body"] = {k: rnd([v[i] for i in idx if i < len(v)], TRACE_DIGITS) for k, v in (run.get("body") or {}).items()}
    out["poses"] = [{**rnd({k: v for k, v in p.items() if k != "t"}, TRACE_DIGITS), "t": rnd(p["t"])}
                    for p in run.get("poses") or []]
    out["violation_totals"] = rnd(run.get("violation_totals") or [])
    return out


def run_rows(run: dict) -> dict:
    """A sequence run with `x` as one row per sample and `active` one name per sample."""
    out = dict(run)
    x = run.get("x") or []
    n = len(run.get("t") or [])
    out["x"] = [[col[i] if i < len(col) else None for col in x] for i in range(n)] if x else []
    act = run.get("active") or []
    if act and isinstance(act[0], list):
        out["active"] = [name for name, k in act for _ in range(int(k))]
    return out


def readable(report: dict) -> dict:
    """A copy of a report (schema 1 or 2) with one dict per oracle cell and one row per sample of
    each sequence run: the form the HTML and pictures are drawn from."""
    major = str(report.get("schema_version", "1")).split(".")[0]
    if major == "1":
        return report
    out = dict(report)
    names = {p.get("name"): p.get("safety_functions") or [] for p in report.get("primitives") or []}
    trs = [t if "h_names" in t else {**t, "h_names": names.get(t.get("to"), [])} for t in report.get("transitions", [])]
    out["transitions"] = [{**t, "cells": expand_cells(t)} for t in trs]
    seq = report.get("sequence")
    if seq:
        out["sequence"] = {**seq, "runs": {m: run_rows(r) for m, r in (seq.get("runs") or {}).items()}}
    return out
