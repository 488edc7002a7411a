"""Whether a report.json read back may be planned and simulated on.

First its integrity record: the content hash the writer stored (an edit changes it) and the mac of
that hash under this machine's key (mpgspec.integrity), so that a report edited by hand, or whose
hash was recomputed by someone without the key, is refused. Then the structure that plan and
simulate rely on: primitives with unique names, edges and transitions between them, classes 1 or 2,
finite non-negative weights, finite windows, a lookup table whose next hops are edges, the robust
section's surviving edges, and no NaN or infinity anywhere (the writer stores them as null).

A refusal is a ReportError: the file, the key path in it, what was expected and what was found.
"""
from __future__ import annotations

import json
import math

from ..errors import Location, SpecError
from ..integrity import authentic, content_hash, mac
from ..plan.planner import WEIGHTS

UNHASHED = ("integrity", "generated_at", "timing")
"""Keys left out of the content hash: the record itself and the wall-clock figures, so that two runs
that verified the same thing store the same record (plan and simulate read neither)."""
PRIMITIVE_CLASSES = ("fixed", "periodic", "transient")
HINT = "run `mpgspec verify` to write it again, or pass --rebuild"


class ReportError(SpecError):
    """A report.json that plan and simulate refuse: edited, written with another key, or malformed."""

    code = "MPG410"


# ----------------------------------------------------------------------------- integrity
def integrity_record(report: dict) -> dict:
    """The integrity record of a report made of JSON types: the content hash of what is hashed of it
    (all but UNHASHED) and the mac of that hash under this machine's key."""
    digest = content_hash(_hashed(report))
    return {"sha256": digest, "mac": mac("report", digest)}


def _hashed(report: dict) -> dict:
    return {k: v for k, v in report.items() if k not in UNHASHED}


def check_integrity(report: dict, where) -> None:
    """Refuse a report without its integrity record, edited since it was written, or whose record
    was not made with this machine's key."""
    record = report.get("integrity")
    if not isinstance(record, dict):
        raise _refuse(where, "integrity", "the report has no integrity record: `mpgspec verify` did not write it",
                      "the record of its content hash", _found(record))
    digest = content_hash(_hashed(report))
    if record.get("sha256") != digest:
        raise _refuse(where, "integrity.sha256",
                      "the report was edited after `mpgspec verify` wrote it: its content does not match its hash")
    if not authentic(record.get("mac"), "report", digest):
        raise _refuse(where, "integrity.mac", "the report was not written by `mpgspec verify` on this machine or "
                                              "with this key (MPGSPEC_CACHE_KEY)")


# ----------------------------------------------------------------------------- structure
def check_report(report, where) -> None:
    """Refuse a report.json (as read from `where`) that was not written here by `mpgspec verify` or
    that plan and simulate could not use: integrity first, then structure."""
    _need(isinstance(report, dict), where, "", "a JSON object", report)
    check_integrity(report, where)
    _all_finite(report, where)
    _check_project(report.get("project"), where)
    names, edges, transitions = check_graph(report, where)
    _check_classes(edges, transitions, where)
    _check_lookup_table(report.get("lookup_table"), names, edges, where)
    _check_robust(report.get("robust"), names, where)


def check_graph(report, where="report") -> tuple[list[str], dict, dict]:
    """Refuse a report whose graph ReportGraph cannot rebuild (primitives, edges and the transition
    of each edge); returns the primitive names, the edges and the transitions by (from, to)."""
    _need(isinstance(report, dict), where, "", "a JSON object", report)
    names = _check_primitives(report.get("primitives"), where)
    edges = _check_edges(report.get("edges"), names, where)
    transitions = _check_transitions(report.get("transitions"), names, where)
    for pair, (i, _) in edges.items():
        _need(pair in transitions, where, f"edges[{i}]", f"the transition {pair[0]} -> {pair[1]} among the "
                                                        "transitions", "none")
    return names, edges, transitions


def _check_project(project, where) -> None:
    _need(isinstance(project, dict), where, "project", "an object", project)
    _need(isinstance(project.get("name"), str), where, "project.name", "a string", project.get("name"))


def _check_primitives(prims, where) -> list[str]:
    names: list[str] = []
    for i, p in enumerate(_objects(prims, "primitives", where)):
        key = f"primitives[{i}]"
        name = p.get("name")
        _need(isinstance(name, str) and name and name not in names, where, f"{key}.name",
              "a name no other primitive has", name)
        names.append(name)
        _need(isinstance(p.get("class"), str) and p["class"] in PRIMITIVE_CLASSES, where, f"{key}.class",
              " or ".join(PRIMITIVE_CLASSES), p.get("class"))
        _number(p.get("period"), f"{key}.period", where, positive=True)
        if p.get("domain") is not None:
            _window(p["domain"], f"{key}.domain", where)
    for i, p in enumerate(prims):
        _need(p.get("next") is None or p.get("next") in names, where, f"primitives[{i}].next",
              "a primitive of the report, or null", p.get("next"))
    return names


def _check_edges(edges, names: list[str], where) -> dict:
    out = {}
    for i, key, pair, e in _between(edges, "edges", names, where):
        _need(_int_in(e.get("class"), (1, 2)), where, f"{key}.class", "1 or 2", e.get("class"))
        _need(isinstance(e.get("usable", True), bool), where, f"{key}.usable", "true or false", e.get("usable"))
        for w in WEIGHTS:
            _number(e.get(w), f"{key}.{w}", where)
        out[pair] = (i, e)
    return out


def _check_transitions(trs, names: list[str], where) -> dict:
    """The transitions' grids, switch-in clocks, windows and weights; returns them by (from, to)."""
    out = {}
    for i, key, pair, t in _between(trs, "transitions", names, where):
        t_A = _numbers(t.get("t_A"), f"{key}.t_A", where)
        best = t.get("best_t_B")
        _need(isinstance(best, (list, tuple)) and len(best) == len(t_A), where, f"{key}.best_t_B",
              f"a list of {len(t_A)} entries (one per t_A)", best)
        for j, b in enumerate(best):
            _number(b, f"{key}.best_t_B[{j}]", where)
        rows = t.get("row_margins")
        if rows is not None:
            _need(isinstance(rows, (list, tuple)) and len(rows) == len(t_A), where, f"{key}.row_margins",
                  f"a list of {len(t_A)} entries (one per t_A)", rows)
            for j, m in enumerate(rows):
                _number(m, f"{key}.row_margins[{j}]", where)
        fr = t.get("from_roa")
        if fr is not None:
            rows = fr.get("rows") if isinstance(fr, dict) else None
            _need(isinstance(rows, (list, tuple)) and len(rows) == len(t_A), where, f"{key}.from_roa.rows",
                  f"a list of {len(t_A)} entries (one per t_A)", rows)
            for j, r in enumerate(rows):
                ok = r is None or (isinstance(r, (list, tuple)) and len(r) == 3 and
                                   isinstance(r[0], (int, float)) and not isinstance(r[0], bool) and 0 <= r[0] <= 1 and
                                   all(isinstance(k, int) and not isinstance(k, bool) and k >= 0 for k in r[1:]) and
                                   r[1] <= r[2])
                _need(ok, where, f"{key}.from_roa.rows[{j}]", "null or [share of r_A in [0, 1], safe, drawn], "
                      "0 <= safe <= drawn", r)
        _windows(t.get("windows"), f"{key}.windows", where)
        weights = t.get("weights", {})
        _need(isinstance(weights, dict), where, f"{key}.weights", "an object", weights)
        for w, v in weights.items():
            _number(v, f"{key}.weights{_sub(w)}", where)
        out[pair] = (i, t)
    return out


def _check_classes(edges: dict, transitions: dict, where) -> None:
    """Each transition's class is 0 (no edge), 1 or 2; each edge's transition was verified (1 or 2)."""
    for i, t in transitions.values():
        _need(_int_in(t.get("class"), (0, 1, 2)), where, f"transitions[{i}].class", "0, 1 or 2", t.get("class"))
    for pair, (i, _) in edges.items():
        cls = transitions[pair][1]["class"]
        _need(cls != 0, where, f"edges[{i}]", f"an edge whose transition {pair[0]} -> {pair[1]} was verified "
                                              "(class 1 or 2)", "a transition of class 0")


def _check_lookup_table(table, names: list[str], edges: dict, where) -> None:
    """Every primitive has a row; every entry names a primitive that is the current one or reached
    from it by an edge the planner may take (null: the goal is unreachable)."""
    _need(isinstance(table, dict) and isinstance(table.get("next"), dict), where, "lookup_table",
          "an object with `next`", table)
    rows = table["next"]
    for a in names:
        _need(isinstance(rows.get(a), dict), where, f"lookup_table.next{_sub(a)}", "a row for each primitive",
              rows.get(a))
    for a, row in rows.items():
        _need(a in names, where, f"lookup_table.next{_sub(a)}", "a primitive of the report", a)
        for goal, nxt in row.items():
            key = f"lookup_table.next{_sub(a)}{_sub(goal)}"
            _need(goal in names, where, key, "a goal that is a primitive of the report", goal)
            entry = edges.get((a, nxt)) if isinstance(nxt, str) else None
            ok = nxt is None or nxt == a or (entry is not None and entry[1].get("usable", True))
            _need(ok, where, key, f"a primitive reached from {a} by an edge the planner may take, or null", nxt)


def _check_robust(rob, names: list[str], where) -> None:
    """The surviving edges of the robust section (the robust graph is rebuilt from them)."""
    if rob is None:
        return
    _need(isinstance(rob, dict), where, "robust", "an object or null", rob)
    for _, key, _, r in _between(rob.get("edges", []), "robust.edges", names, where):
        _need(isinstance(r.get("survives", False), bool), where, f"{key}.survives", "true or false", r.get("survives"))
        if not r.get("survives"):
            continue
        _need(_int_in(r.get("robust_class"), (1, 2)), where, f"{key}.robust_class", "1 or 2", r.get("robust_class"))
        _windows(r.get("robust_windows", []), f"{key}.robust_windows", where)
        weights = r.get("robust_weights") or {}
        _need(isinstance(weights, dict), where, f"{key}.robust_weights", "an object", weights)
        for w, v in weights.items():
            _need(w in WEIGHTS, where, f"{key}.robust_weights{_sub(w)}", " or ".join(WEIGHTS), w)
            _number(v, f"{key}.robust_weights{_sub(w)}", where)
        cells = r.get("cells")
        _need(isinstance(cells, dict) and isinstance(cells.get("row"), list)
              and isinstance(cells.get("robust_safe"), list), where, f"{key}.cells",
              "an object with the lists `row` and `robust_safe`", cells)
        for j, row in enumerate(cells["row"]):
            _need(_int_in(row, range(1 << 31)), where, f"{key}.cells.row[{j}]", "a row index", row)


# ----------------------------------------------------------------------------- pieces
def _all_finite(report: dict, where) -> None:
    """No NaN or infinity anywhere (the writer stores non-finite numbers as null)."""
    try:
        json.dumps(report, allow_nan=False)
    except ValueError:
        key, value = _first_non_finite(report, "") or ("", None)
        raise _refuse(where, key, "the report is malformed", "a finite number or null", _found(value)) from None


def _first_non_finite(v, key: str):
    if isinstance(v, float) and not math.isfinite(v):
        return key, v
    items = v.items() if isinstance(v, dict) else enumerate(v) if isinstance(v, list) else ()
    for k, x in items:
        found = _first_non_finite(x, f"{key}[{k}]" if isinstance(k, int) else f"{key}{_sub(k)}" if key else k)
        if found is not None:
            return found
    return None


def _objects(v, key: str, where) -> list:
    _need(isinstance(v, (list, tuple)), where, key, "a list of objects", v)
    for i, x in enumerate(v):
        _need(isinstance(x, dict), where, f"{key}[{i}]", "an object", x)
    return v


def _between(v, name: str, names: list[str], where):
    """(index, key path, (from, to), object) of each entry of the list `name` of objects that each
    name two primitives of the report (edges, transitions, robust edges)."""
    for i, e in enumerate(_objects(v, name, where)):
        key = f"{name}[{i}]"
        yield i, key, _pair(e, key, names, where), e


def _pair(e: dict, key: str, names: list[str], where) -> tuple[str, str]:
    for end in ("from", "to"):
        _need(isinstance(e.get(end), str) and e.get(end) in names, where, f"{key}.{end}", "a primitive of the report",
              e.get(end))
    return e["from"], e["to"]


def _finite(v) -> bool:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:  # an integer beyond every float
        return False


def _number(v, key: str, where, positive: bool = False) -> None:
    """A finite number >= 0 (> 0 when positive), or null."""
    ok = v is None or (_finite(v) and (v > 0 if positive else v >= 0))
    _need(ok, where, key, f"a finite number {'> 0' if positive else '>= 0'}, or null", v)


def _numbers(v, key: str, where) -> list:
    _need(isinstance(v, (list, tuple)), where, key, "a list of finite numbers", v)
    for j, x in enumerate(v):
        _need(_finite(x), where, f"{key}[{j}]", "a finite number", x)
    return v


def _window(w, key: str, where) -> None:
    ok = isinstance(w, (list, tuple)) and len(w) == 2 and all(_finite(x) for x in w) and w[0] <= w[1]
    _need(ok, where, key, "a pair [start, end] of finite numbers, start <= end", w)


def _windows(ws, key: str, where) -> None:
    _need(isinstance(ws, (list, tuple)), where, key, "a list of windows [start, end]", ws)
    for j, w in enumerate(ws):
        _window(w, f"{key}[{j}]", where)


def _int_in(v, allowed) -> bool:
    return type(v) is int and v in allowed


def _sub(name) -> str:
    """A key path step naming a dict key: .key for plain words, ["..."] otherwise (primitive names)."""
    return f".{name}" if isinstance(name, str) and name.isidentifier() else f"[{json.dumps(name)}]"


def _found(v) -> str:
    """What a refused value is, briefly."""
    if v is None:
        return "null (or missing)"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int) and len(str(abs(v))) > 15:
        return f"an integer of {len(str(abs(v)))} digits"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return f"the string {json.dumps(v)[:60]}"
    return "a list" if isinstance(v, list) else "an object" if isinstance(v, dict) else type(v).__name__


def _need(ok, where, key: str, expected: str, value) -> None:
    if not ok:
        raise _refuse(where, key, "the report is malformed", expected, _found(value))


def _refuse(where, key: str, message: str, expected: str = "", found: str = "") -> ReportError:
    return ReportError(message, location=Location(str(where)), key=key, expected=expected, found=found, hint=HINT)
