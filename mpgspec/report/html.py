"""Render the self-contained HTML report from the JSON report dict alone (no pipeline objects).

The template lives in templates/report.html.j2 and is loaded from the installed package; all text
is autoescaped, and the pictures are inline SVG built by svg.py.
"""
from __future__ import annotations

from collections import Counter
from functools import lru_cache

import jinja2
from markupsafe import Markup

from . import svg

SYMBOLS = {"fixed": "□", "periodic": "○", "transient": "◇"}
EVIDENCE = (("certified", "a checked certificate"),
            ("simulated", "a rollout of the safety oracle: the closed loop integrated from each grid point"),
            ("empirical", "sampled executions"))


@lru_cache(maxsize=1)
def _env() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.PackageLoader("mpgspec.report", "templates"), autoescape=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    env.filters["num"] = _num
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


def _transitions(report: dict) -> list[dict]:
    """Every ordered pair in primitive order, with its grid picture."""
    order = {p["name"]: i for i, p in enumerate(report["primitives"])}
    trs = sorted(report["transitions"], key=lambda t: (order.get(t["from"], 1e9), order.get(t["to"], 1e9)))
    return [{"tr": t, "has_edge": t["class"] in (1, 2), "svg": Markup(svg.grid_svg(t))} for t in trs]


def _failures(report: dict, key: str = "failures") -> list[dict]:
    out = []
    for f in report.get(key, []):
        s = f["series"]
        title = f"h of {f['to']} after switching from {f['from']} at t_A = {_num(f['t_A'], 3)} s"
        series, shade = (dict(s["h"]) if "t" in s else {}), True
        if key == "edge_traces" and "t" in s:  # the safety margin and the approach to E, not every h
            rows = list(s["h"].values())
            least = [min((r[k] for r in rows if r[k] is not None), default=None) for k in range(len(s["t"]))]
            series = {"least h (safety margin)": least, "E margin r - ||x - x*||": s["roa_margin"]}
            shade, title = "least h (safety margin)", f"{f['to']} after switching from {f['from']} at t_A = {_num(f['t_A'], 3)} s"
        pic = Markup(svg.series_svg(s["t"], series, title=title, shade_negative=shade, ylabel="margin"
                                    if key == "edge_traces" else "h")) if "t" in s else None
        out.append({"f": f, "svg": pic, "error": s.get("error")})
    return out


def _sequence(report: dict) -> dict | None:
    seq = report.get("sequence")
    if seq is None:
        return None
    runs = [{"name": name, "run": run, "svg": Markup(svg.trajectory_svg(run, seq["state_names"], seq["commands"]))}
            for name, run in seq["runs"].items()]
    return {"seq": seq, "runs": runs}


def view(report: dict) -> dict:
    """Everything the template shows, derived from the report dict."""
    names = [p["name"] for p in report["primitives"]]
    trs = {(t["from"], t["to"]): t for t in report["transitions"]}
    edges = [{"e": e, "tr": trs.get((e["from"], e["to"]))} for e in report["edges"]]
    edge_methods = Counter(x["tr"]["method"] if x["tr"] else "unknown" for x in edges)
    return {
        "symbols": SYMBOLS,
        "evidence": EVIDENCE,
        "edge_methods": dict(edge_methods),
        "roa_methods": dict(Counter(p["roa_method"] for p in report["primitives"])),
        "all_simulated": bool(edges) and set(edge_methods) == {"simulated"},
        "graph_svg": Markup(svg.graph_svg(report)),
        "periods": {p["name"]: _period(p) for p in report["primitives"]},
        "edges": edges,
        "transitions": _transitions(report),
        "failures": _failures(report),
        "edge_traces": _failures(report, "edge_traces"),
        "names": names,
        "sequence": _sequence(report),
        "assert_counts": dict(Counter(a["status"] for a in report["assertions"])),
        "cell_colors": svg.CELL_COLORS,
    }


def render_html(report: dict) -> str:
    """The report as one self-contained HTML page (inline CSS and SVG, no scripts)."""
    return _env().get_template("report.html.j2").render(r=report, v=view(report))
