"""What changed between two verified reports: edges gained and lost, class changes, windows
narrowed, robust edges lost, new inconclusive cells, assertions that changed status.

The comparison reads both report.json files as they are (their structure checked as plan checks
it); a report whose integrity record does not match this machine's key (written on another machine,
such as a CI artifact, or edited since) is compared all the same, with a note saying so, since a
diff decides nothing about what is safe. A regression is a lost edge, a class change, a lost robust
edge or an assertion that passed and now fails.
"""
from __future__ import annotations

import json
from pathlib import Path

from ..errors import gh_escape_data, gh_escape_property, gh_plain
from .trust import (ReportError, _all_finite, _check_classes, _check_project, _check_robust, _refuse, check_graph,
                    check_integrity)

__all__ = ["diff_reports", "load_for_diff", "format_diff"]

HINT = "pass the report.json `mpgspec verify` wrote, or its folder"
WIDTH_TOL = 1e-9
"""Window widths (seconds) closer than this are the same."""


def load_for_diff(path) -> tuple[dict, str]:
    """(report, note): a report.json (or its folder) whose structure plan could use; the note says
    when its integrity record does not match this machine's key. ReportError when unusable."""
    p = Path(path)
    if p.is_dir():
        p = p / "report.json"
    try:
        with open(p, encoding="utf-8") as f:
            report = json.load(f)
    except FileNotFoundError:
        raise _refused(p, "no report.json here", "a report.json or its folder", "nothing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise _refused(p, f"not a readable report.json ({type(e).__name__})", "JSON", str(e)[:120]) from None
    if not isinstance(report, dict):
        raise _refused(p, "the report is malformed", "a JSON object", type(report).__name__)
    try:
        _all_finite(report, p)
        _check_project(report.get("project"), p)
        names, edges, transitions = check_graph(report, p)
        _check_classes(edges, transitions, p)
        _check_robust(report.get("robust"), names, p)
    except ReportError as e:
        e.hint = HINT
        raise
    note = ""
    try:
        check_integrity(report, p)
    except ReportError as e:
        note = f"{p}: {e.message}; compared as it is"
    return report, note


def _refused(p, message: str, expected: str, found: str) -> ReportError:
    e = _refuse(p, "", message, expected, found)
    e.hint = HINT
    return e


def _count(t: dict, key: str) -> float:
    """A transition's count `key` (0 where the report has none or not a number)."""
    c = t.get("counts")
    v = c.get(key, 0) if isinstance(c, dict) else 0
    return v if isinstance(v, (int, float)) and not isinstance(v, bool) else 0


def _statuses(report: dict) -> dict:
    items = report.get("assertions")
    return {str(a.get("description")): a.get("status") for a in (items if isinstance(items, list) else [])
            if isinstance(a, dict)}


def _pairs(items) -> dict:
    return {(e["from"], e["to"]): e for e in items or []}


def _width(windows) -> float:
    return float(sum(max(0.0, hi - lo) for lo, hi in windows or []))


def _robust(report: dict) -> set:
    rob = report.get("robust") or {}
    return {(e["from"], e["to"]) for e in rob.get("edges") or [] if e.get("survives")}


def _edge(pair) -> dict:
    return {"from": pair[0], "to": pair[1]}


def diff_reports(old: dict, new: dict) -> dict:
    """The changes from report `old` to report `new` (see the module's docstring), as a dict of
    lists plus `regression` (bool)."""
    eo, en = _pairs(old.get("edges")), _pairs(new.get("edges"))
    to, tn = _pairs(old.get("transitions")), _pairs(new.get("transitions"))
    gained = [_edge(p) | {"class": en[p]["class"]} for p in sorted(set(en) - set(eo))]
    lost = [_edge(p) | {"class": eo[p]["class"]} for p in sorted(set(eo) - set(en))]
    classes = [_edge(p) | {"old": eo[p]["class"], "new": en[p]["class"]}
               for p in sorted(set(eo) & set(en)) if eo[p]["class"] != en[p]["class"]]
    narrowed, widened, inconclusive = [], [], []
    for p in sorted(set(to) & set(tn) & set(eo) & set(en)):  # an edge in both: its windows and cells
        wo, wn = _width(to[p].get("windows")), _width(tn[p].get("windows"))
        so, sn = _count(to[p], "safe"), _count(tn[p], "safe")
        row = _edge(p) | {"old_width": wo, "new_width": wn, "old_safe_cells": so, "new_safe_cells": sn}
        if wn < wo - WIDTH_TOL or sn < so:
            narrowed.append(row)
        elif wn > wo + WIDTH_TOL or sn > so:
            widened.append(row)
        io, in_ = _count(to[p], "inconclusive"), _count(tn[p], "inconclusive")
        if in_ > io:
            inconclusive.append(_edge(p) | {"old": io, "new": in_})
    ro, rn = _robust(old), _robust(new)
    ao, an = _statuses(old), _statuses(new)
    assertions = [{"description": d, "old": ao.get(d), "new": an.get(d)}
                  for d in sorted(set(ao) | set(an), key=str) if ao.get(d) != an.get(d)]
    out = {"old": _summary(old), "new": _summary(new), "edges_gained": gained, "edges_lost": lost,
           "class_changed": classes, "windows_narrowed": narrowed, "windows_widened": widened,
           "robust_lost": [_edge(p) for p in sorted(ro - rn)], "robust_gained": [_edge(p) for p in sorted(rn - ro)],
           "inconclusive_more": inconclusive, "assertions_changed": assertions}
    out["regression"] = bool(lost or classes or out["robust_lost"]
                             or any(a["old"] == "pass" and a["new"] != "pass" for a in assertions))
    return out


def _summary(report: dict) -> dict:
    return {"project": (report.get("project") or {}).get("name"), "status": report.get("status"),
            "edges": len(report.get("edges") or []), "generated_at": report.get("generated_at")}


def _pair_text(e: dict) -> str:
    return f"{e['from']} -> {e['to']}"


def _assertion_level(a: dict) -> str:
    return "error" if a["old"] == "pass" and a["new"] != "pass" else "notice"


_CHANGES = (  # (key, level or a function of the row, kind, text of the row), in the order shown
    ("edges_lost", "error", "edge lost", lambda e: f"{_pair_text(e)} (class {e['class']})"),
    ("class_changed", "error", "class changed", lambda e: f"{_pair_text(e)}: class {e['old']} -> {e['new']}"),
    ("robust_lost", "error", "robust edge lost", _pair_text),
    ("assertions_changed", _assertion_level, "assertion",
     lambda a: f"{a['description']}: {a['old'] or 'absent'} -> {a['new'] or 'absent'}"),
    ("windows_narrowed", "warning", "window narrowed", lambda e: _window_text(e)),
    ("inconclusive_more", "warning", "more inconclusive cells", lambda e: f"{_pair_text(e)}: {e['old']} -> {e['new']}"),
    ("edges_gained", "notice", "edge gained", lambda e: f"{_pair_text(e)} (class {e['class']})"),
    ("robust_gained", "notice", "robust edge gained", _pair_text),
    ("windows_widened", "notice", "window widened", lambda e: _window_text(e)),
)


def _lines(d: dict) -> list[tuple[str, str, str]]:
    """(level, kind, text) for every change: level error for regressions, warning for narrowed
    windows and new inconclusive cells, notice for gains."""
    return [(level(row) if callable(level) else level, kind, text(row))
            for key, level, kind, text in _CHANGES for row in d[key]]


def _window_text(e: dict) -> str:
    wide = (f"windows {e['old_width']:.4g} s -> {e['new_width']:.4g} s wide, "
            if e["old_width"] or e["new_width"] else "")
    return f"{e['from']} -> {e['to']}: {wide}safe cells {e['old_safe_cells']} -> {e['new_safe_cells']}"


def _cell(text) -> str:
    """Text for one markdown table cell or line: '|' escaped, line breaks as spaces (names and
    descriptions come from specs and must not break the table)."""
    return str(text).replace("\\", "\\\\").replace("|", "\\|").replace("\r", " ").replace("\n", " ")


def format_diff(d: dict, fmt: str, notes: list[str] = ()) -> str:
    """The diff as text: human, json (compact), markdown or github (workflow commands)."""
    if fmt == "json":
        return json.dumps(d | {"notes": list(notes)}, separators=(",", ":"))
    lines = _lines(d)
    o, n = d["old"], d["new"]
    head = (f"{n['project']}: {o['status']} -> {n['status']}, edges {o['edges']} -> {n['edges']}; "
            + ("REGRESSION" if d["regression"] else "no regression"))
    if fmt == "markdown":
        rows = ["| level | change | what |", "|---|---|---|"] + [f"| {_cell(lv)} | {_cell(k)} | {_cell(t)} |"
                                                                 for lv, k, t in lines]
        return "\n".join([f"**{_cell(head)}**", ""] + [f"> {_cell(x)}" for x in notes]
                         + ([""] + rows if lines else ["", "no changes"]))
    if fmt == "github":
        return "\n".join([f"::{lv} title={gh_escape_property('mpgspec diff: ' + k)}::{gh_escape_data(t)}"
                          for lv, k, t in lines]
                         + [f"::warning title=mpgspec diff::{gh_escape_data(x)}" for x in notes] + [gh_plain(head)])
    body = [f"  {lv:7s} {k}: {t}" for lv, k, t in lines] or ["  no changes"]
    return "\n".join([head] + [f"  note: {x}" for x in notes] + body)
