"""Render the self-contained HTML report from the JSON report dict alone (no pipeline objects).

The template lives in templates/report.html.j2 and is loaded from the installed package; all text
is autoescaped, and the pictures are inline SVG built by svg.py (the graph laid out by Graphviz's
`dot` when it is installed). The page works offline and without scripts; one small inline script
adds a filter box, "hide passing" and sortable columns to its longer tables.
"""
from __future__ import annotations

import re
from collections import Counter
from functools import lru_cache

import jinja2
from markupsafe import Markup

from . import fig6, svg
from .compact import h_families, least, readable
from .findings import disagreements, nominal_only_path, path_text, waiting_why
from .proved import proved_text
from .sections.registry import report_sections, section_data
from .traversal import command_rows

SYMBOLS = {"fixed": "□", "periodic": "○", "transient": "◇"}
EVIDENCE = (("certified", "proved, not sampled: a checked certificate, or validated integration (ball arithmetic) "
                          "enclosing the closed loop's flow; an edge is certified when every safe cell it rests on "
                          "is proved at its grid point (t_A, t_B), and covers the t_A between grid points only in "
                          "the intervals it lists as certified for every t_A"),
            ("simulated", "a rollout of the safety oracle: the closed loop integrated from each grid point"),
            ("empirical", "sampled executions"))


def _spec_link(loc) -> Markup:
    """file:line of a spec position, linked to the file (a file: address, for a local browser)."""
    from html import escape
    from pathlib import Path

    if not isinstance(loc, dict) or not loc.get("file") or not loc.get("line"):
        return Markup("–")
    f = Path(str(loc["file"]))
    label = escape(f"{f.name}:{int(loc['line'])}")
    href = escape(f.as_uri()) if f.is_absolute() else escape(str(loc["file"]))
    return Markup(f'<a href="{href}" title="{escape(str(loc["file"]))}">{label}</a>')


@lru_cache(maxsize=1)
def _env() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.PackageLoader("mpgspec.report", "templates"), autoescape=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    env.filters["num"] = _num
    env.filters["waiting_why"] = waiting_why
    env.filters["spec_link"] = _spec_link
    env.filters["windows"] = lambda ws: ", ".join(f"[{_num(a)}, {_num(b)}]" for a, b in ws) or "–"
    return env


def _num(v, digits: int = 4) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    return str(v) if isinstance(v, int) else f"{v:.{digits}g}"


def _period(p: dict) -> str:
    if p.get("period") is not None:
        return f"T = {_num(p['period'])} s"
    if p.get("domain"):
        return f"t ∈ [{_num(p['domain'][0])}, {_num(p['domain'][1])}] s"
    return "–"


class Anchors:
    """Element ids of primitives, grids, traces and failures (by position, so any name is safe)."""

    def __init__(self, report: dict):
        self.index = {p["name"]: i for i, p in enumerate(report["primitives"])}

    def prim(self, name) -> str:
        return f"prim-{self.index.get(name, 'x')}"

    def pair(self, kind: str, a, b) -> str:
        return f"{kind}-{self.index.get(a, 'x')}-{self.index.get(b, 'x')}"


def _transitions(report: dict, ids: Anchors) -> list[dict]:
    """Every ordered pair in primitive order, with its grid picture."""
    order = ids.index
    trs = sorted(report["transitions"], key=lambda t: (order.get(t["from"], 1e9), order.get(t["to"], 1e9)))
    return [{"tr": t, "has_edge": t["class"] in (1, 2), "svg": Markup(svg.grid_svg(t)), "proved": proved_text(t),
             "id": ids.pair("grid", t["from"], t["to"])} for t in trs]


def _pair_in(text: str, report: dict) -> tuple[str, str] | None:
    """The ordered pair 'A -> B' named in an assertion's description (the longest match)."""
    names = sorted((p["name"] for p in report["primitives"]), key=len, reverse=True)
    best = None
    for a in names:
        for b in names:
            if a != b and f"{a} -> {b}" in text and (best is None or len(a) + len(b) > len(best[0]) + len(best[1])):
                best = (a, b)
    return best


def assertion_link(a: dict, report: dict, ids: Anchors) -> str:
    """Where the evidence of an assertion is shown in the page."""
    kind, text = a.get("kind", ""), a.get("description", "")
    if kind in ("edge", "no_edge"):
        pair = _pair_in(text, report)
        if pair:
            return "#" + ids.pair("grid", *pair)
        return "#grids"
    if kind == "simulation_safe":
        mode = next((m for m in ("naive", "graph") if text.startswith(m)), None)
        return f"#run-{mode}" if mode else "#sequence"
    if kind == "roa_level":
        m = re.match(r"E of (.+) is \w+$", text)
        return "#" + ids.prim(m.group(1)) if m else "#primitives"
    return {"plan": "#plans", "reachable_from": "#lookup", "max_inconclusive": "#edges"}.get(kind, "#assertions")


def _disagreements(report: dict) -> list[dict]:
    """The summary's WARN items for cross-check disagreements (findings.disagreements) and for a graph
    run through edges that are nominal only (findings.nominal_only_path)."""
    out = [{"status": "warn", "what": f"cross-check of the {d['mode']} run", "text": d["text"],
            "href": "#crosscheck", "row": "#crosscheck"} for d in disagreements(report)]
    bad = nominal_only_path(report)
    if bad is not None:
        out.append({"status": "warn", "what": "the graph run's path", "text": path_text(bad),
                    "href": "#robust", "row": "#robust"})
    return out


def _summary(report: dict, ids: Anchors) -> dict:
    """The verdict line, the counts and every FAIL, ERROR and WARN with a link to its evidence."""
    asserts, assumed = report["assertions"], report.get("assumptions", [])
    problems = []
    for a in asserts:
        if a["status"] != "pass":
            problems.append({"status": a["status"], "what": "assertion", "text": f"{a['description']}: {a['message']}",
                             "href": assertion_link(a, report, ids), "row": f"#assertion-{a['index']}"})
    for k, c in enumerate(assumed):
        if c["status"] != "pass":
            problems.append({"status": c["status"], "what": f"assumption of {c['primitive']}",
                             "text": f"{c['name']}: {c['message']}", "href": "#" + ids.prim(c["primitive"]),
                             "row": f"#assumption-{k}"})
    problems[:0] = _disagreements(report)
    order = {"error": 0, "fail": 1, "warn": 2, "info": 3}
    problems.sort(key=lambda p: order.get(p["status"], 1))  # stable: FAIL, then WARN, then INFO last
    runs = ((report.get("sequence") or {}).get("runs") or {})
    warns = sum(p["status"] == "warn" for p in problems)
    status = report["status"]
    label = status.upper() + (f" with {warns} warning{'s' if warns != 1 else ''}" if warns and status == "pass" else "")
    edges = report["edges"]
    return {
        "label": label, "warns": warns, "problems": problems,
        "counts": [
            ("primitives", len(report["primitives"]), ""),
            ("edges", len(edges), f"{sum(e['class'] == 1 for e in edges)} Class 1, "
                                  f"{sum(e['class'] == 2 for e in edges)} Class 2"
                                  + (f", {sum(e.get('usable') is False for e in edges)} not usable by the planner"
                                     if any(e.get("usable") is False for e in edges) else "")),
            *_section_counts(report, "edges"),
            ("oracle calls", (report.get("verdicts") or {}).get("total", "–"),
             ", ".join(f"{(report.get('verdicts') or {}).get(k, 0)} {k}" for k in ("safe", "unsafe", "inconclusive"))),
            ("assertions", len(asserts), _counts(asserts)),
            ("assumption checks", len(assumed), _counts(assumed)),
            *([("sequence runs", len(runs), ", ".join(f"{m} {'safe' if r.get('safe') else 'unsafe'}"
                                                       for m, r in runs.items()))] if runs else []),
            *_section_counts(report, "sequence"),
        ],
    }


def _present(report: dict, after: str):
    """The registered report sections placed after the page section `after`, with their data, where
    the report has some."""
    for section in report_sections().values():
        data = section_data(report, section)
        if data and section.after == after:
            yield section, data


def _section_counts(report: dict, after: str) -> list[tuple]:
    """The summary lines of the sections placed after `after`."""
    return [c for section, data in _present(report, after) if section.count and (c := section.count(data))]


@lru_cache(maxsize=None)
def _section_template(name: str, text: str) -> jinja2.Template:
    """A section's template part; it keeps its last newline, so that it ends its own lines in the page."""
    env = jinja2.Environment(autoescape=True, trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                             undefined=jinja2.StrictUndefined)
    env.filters.update(_env().filters)
    return env.from_string(text)


def _sections(report: dict, v: dict) -> dict[str, list[dict]]:
    """Each registered section present in the report, rendered, by the page section it follows."""
    out = {}
    for after in ("edges", "sequence"):
        out[after] = [{"anchor": s.anchor or s.name, "label": s.label or s.name,
                       "html": Markup(_section_template(s.name, s.template).render(
                           r=report, v=v, s=data, sv=s.view(data) if s.view else None))}
                      for s, data in _present(report, after)]
    return out


def _counts(items) -> str:
    c = Counter(x["status"] for x in items)
    return ", ".join(f"{c[k]} {k}" for k in ("pass", "info", "warn", "fail", "error") if c.get(k))


def _floquet(p: dict) -> dict | None:
    """Floquet multipliers of a periodic primitive's orbit, from its region-of-attraction evidence."""
    ev = p.get("roa_evidence") or {}
    mus = ev.get("multipliers")
    if not isinstance(mus, list) or not mus:
        return None
    trivial = ev.get("trivial_multiplier")
    rows = []
    for k, z in enumerate(mus):
        re_, im = (z + [0.0, 0.0])[:2] if isinstance(z, list) else (z, 0.0)
        mod = (re_ ** 2 + im ** 2) ** 0.5 if isinstance(re_, (int, float)) and isinstance(im, (int, float)) else None
        rows.append({"re": re_, "im": im, "mod": mod, "trivial": k == trivial})
    neutral = [n for n in ev.get("neutral") or [] if isinstance(n, dict)]
    return {"rows": rows, "rho": ev.get("spectral_radius"), "verdict": ev.get("verdict"), "neutral": neutral}


PARKED = 1e3
"""h values at or above this are drawn as gaps: a function parked while it does not apply (a foot's
contact functions in swing hold 1e3, functions outside their clock window 1e9), which would
otherwise flatten the plot's scale."""


def _unparked(vs: list) -> list:
    return [None if v is not None and v >= PARKED else v for v in vs]


def _failures(report: dict, ids: Anchors, key: str = "failures") -> list[dict]:
    out = []
    for f in report.get(key, []):
        s = f["series"]
        title = f"h of {f['to']} after switching from {f['from']} at t_A = {_num(f['t_A'], 3)} s"
        series, shade, mark = (dict(s["h"]) if "t" in s else {}), True, None
        if "t" in s:
            floor_ = s.get("h_least") or least(s["h"], len(s["t"]))
            n = s.get("h_count") or len(s["h"])
            if key != "edge_traces" and n > len(series):  # the binding functions and the rest's floor
                series[f"least of all {n}"] = floor_
            series = {k: _unparked(vs) for k, vs in series.items()}
        if key == "edge_traces" and "t" in s:  # the safety margin and the approach to E, not every h
            series = {"least h (safety margin)": floor_, "E margin r - ||x - x*||": s["roa_margin"]}
            shade, title = "least h (safety margin)", f"{f['to']} after switching from {f['from']} at t_A = {_num(f['t_A'], 3)} s"
            mark = (f.get("t_stop"), "enters E")
        pic = Markup(svg.series_svg(s["t"], series, title=title, shade_negative=shade, ylabel="margin"
                                    if key == "edge_traces" else "h", mark=mark)) if "t" in s else None
        kind = "trace" if key == "edge_traces" else "fail"
        out.append({"f": f, "svg": pic, "error": s.get("error"), "id": ids.pair(kind, f["from"], f["to"])})
    return out


def _sequence(report: dict) -> dict | None:
    seq = report.get("sequence")
    if seq is None:
        return None
    lims = svg.run_limits(seq["runs"].values(), len(seq["state_names"]))
    runs = [{"name": name, "run": run,
             "svg": Markup(svg.trajectory_svg(run, seq["state_names"], seq["commands"], limits=lims))}
            for name, run in seq["runs"].items()]
    body = fig6.body_svg(seq["runs"], seq["commands"], [p["name"] for p in report["primitives"]], seq["duration"])
    tiles = [{**row, "tiles": [Markup(t) for t in row["tiles"]]} for row in fig6.gait_tiles(seq["runs"])]
    return {"seq": seq, "runs": runs, "commands": command_rows(seq), "body_svg": Markup(body) if body else None,
            "tiles": tiles, "colors": {m: fig6.run_color(m, k) for k, m in enumerate(seq["runs"])}}


def _evidence(tr: dict | None) -> dict:
    """An edge's evidence for the page: its level, how many of its safe cells are proved, and the t_A
    intervals proved for every t_A."""
    if not tr:
        return {"method": None, "cells_proved": "", "proved": ""}
    safe = [c for row in tr["cells"] for c in row if c.get("verdict") == 1]
    n = sum(c.get("method") == "certified" for c in safe)
    return {"method": tr["method"], "proved": proved_text(tr),
            "cells_proved": f"{n} of {len(safe)} safe cells certified" if n and tr["method"] != "certified" else ""}


def view(report: dict) -> dict:
    """Everything the template shows, derived from the report dict."""
    report = readable(report)
    names = [p["name"] for p in report["primitives"]]
    ids = Anchors(report)
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    edges = [{"e": e, "tr": trs.get((e["from"], e["to"])), "grid": ids.pair("grid", e["from"], e["to"]),
              "trace": ids.pair("trace", e["from"], e["to"]), **_evidence(trs.get((e["from"], e["to"])))}
             for e in report["edges"]]
    edge_methods = Counter(x["tr"]["method"] if x["tr"] else "unknown" for x in edges)
    graph = svg.graphviz_svg(report)
    v = {
        "ids": ids,
        "summary": _summary(report, ids),
        "assertion_links": {a["index"]: assertion_link(a, report, ids) for a in report["assertions"]},
        "floquet": {p["name"]: _floquet(p) for p in report["primitives"]},
        "graph_engine": "Graphviz dot" if graph else "built-in layout",
        "unusable": [x["e"] for x in edges if x["e"].get("usable") is False],
        "symbols": SYMBOLS,
        "evidence": EVIDENCE,
        "edge_methods": dict(edge_methods),
        "roa_methods": dict(Counter(p["roa_method"] for p in report["primitives"])),
        "all_simulated": bool(edges) and set(edge_methods) == {"simulated"},
        "any_certified": "certified" in edge_methods,
        "graph_svg": Markup(graph or svg.graph_svg(report)),
        "periods": {p["name"]: _period(p) for p in report["primitives"]},
        "families": {p["name"]: h_families(list(p.get("safety_functions") or []))[0] for p in report["primitives"]},
        "edges": edges,
        "transitions": _transitions(report, ids),
        "failures": _failures(report, ids),
        "edge_traces": _failures(report, ids, "edge_traces"),
        "names": names,
        "sequence": _sequence(report),
        "assert_counts": dict(Counter(a["status"] for a in report["assertions"])),
        "cell_colors": svg.CELL_COLORS,
    }
    v["sections"] = _sections(report, v)
    return v


def render_html(report: dict) -> str:
    """The report as one self-contained HTML page (inline CSS and SVG, no scripts)."""
    return _env().get_template("report.html.j2").render(r=readable(report), v=view(report))
