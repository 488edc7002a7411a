"""Small SVG pictures for the HTML report, built from plain report data without a plotting library.

All text is escaped and long series are decimated, so each picture stays a few tens of kB and the
report remains one self-contained file.
"""
from __future__ import annotations

import math
from html import escape

import networkx as nx

from .proved import proved_text

# Okabe-Ito colours: distinguishable with the common colour-vision deficiencies.
BLUE, ORANGE, VERMILLION, SKY, GREEN, YELLOW, PURPLE, BLACK = ("#0072B2", "#E69F00", "#D55E00", "#56B4E9",
                                                               "#009E73", "#F0E442", "#CC79A7", "#000000")
PALETTE = (BLUE, VERMILLION, GREEN, PURPLE, ORANGE, SKY, "#7f7f7f", YELLOW)
CELL_COLORS = {"safe": BLUE, "left_C": VERMILLION, "horizon_reached": "#bbbbbb", "inconclusive": ORANGE,
               "integration_failed": BLACK, "error": BLACK}
UNUSABLE = "#9a9a9a"
CELL_LABELS = (("safe", "safe (entered E)"), ("left_C", "left C"), ("horizon_reached", "horizon reached"),
               ("inconclusive", "inconclusive (margin within error bound)"), ("error", "integration failed / error"))
SHAPES = {"fixed": "box", "periodic": "ellipse", "transient": "diamond"}
NODE_FILL = {"fixed": "#d6e8f5", "periodic": "#e4f1fa", "transient": "#fbe6c6"}
ARROW_ID = "mpg-arrow"
DASH = "6 4"
DOT = "1.5 3.5"
NOMINAL_ONLY = VERMILLION
"""Nominal-only edges (safe for the nominal model, lost under the project's uncertainty): vermillion, in the
line style of their class (solid Class 1, dashed Class 2): class and robustness never share a channel."""


def _n(v: float) -> str:
    """Compact pixel coordinate."""
    s = f"{v:.1f}"
    return s[:-2] if s.endswith(".0") else s


def fmt(v, digits: int = 3) -> str:
    """Number label with a few significant digits; '–' for missing values."""
    return "–" if v is None else f"{v:.{digits}g}"


def _el(tag: str, inner: str = "", **attrs) -> str:
    """One element; floats are rounded, '_' in names becomes '-', empty attributes are dropped."""
    a = "".join(f' {k.replace("_", "-")}="{_n(v) if isinstance(v, float) else escape(str(v))}"'
                for k, v in attrs.items() if v not in (None, ""))
    return f"<{tag}{a}>{inner}</{tag}>" if inner else f"<{tag}{a}/>"


def _text(x: float, y: float, s, size: int = 11, anchor: str = "middle", **attrs) -> str:
    return _el("text", escape(str(s)), x=float(x), y=float(y), font_size=size, text_anchor=anchor, **attrs)


def _tip(s: str) -> str:
    """Hover text of the enclosing element."""
    return _el("title", escape(s))


def _svg(w: float, h: float, body: list[str], title: str = "") -> str:
    head = _tip(title) if title else ""
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{_n(w)}" height="{_n(h)}" viewBox="0 0 {_n(w)} {_n(h)}" '
            f'font-family="Helvetica,Arial,sans-serif" role="img">{head}{"".join(body)}</svg>')


def _num(v) -> float | None:
    """A finite float, or None for missing / non-finite values (they break lines)."""
    v = None if v is None or isinstance(v, bool) else float(v)
    return v if v is not None and math.isfinite(v) else None


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """Round tick values covering [lo, hi]."""
    hi = hi if hi > lo else lo + 1.0
    raw = (hi - lo) / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw * (1 - 1e-9))
    start = math.ceil(lo / step - 1e-9) * step
    return [start + i * step for i in range(int((hi - start) / step + 1e-9) + 1)]


def _limits(values, include_zero: bool = False) -> tuple[float, float]:
    vals = [v for v in values if v is not None] + ([0.0] if include_zero else [])
    if not vals:
        return 0.0, 1.0
    lo, hi = min(vals), max(vals)
    pad = 0.05 * (hi - lo) if hi > lo else max(1.0, abs(lo) * 0.1)
    return lo - pad, hi + pad


def _decimate(n: int, max_points: int) -> list[int]:
    """Indices of every k-th sample plus the last one."""
    idx = list(range(0, n, max(1, math.ceil(n / max(max_points, 2)))))
    return idx + [n - 1] if n and idx[-1] != n - 1 else idx


class _Panel:
    """Maps data coordinates into a pixel box and draws axes, lines and bands there."""

    def __init__(self, x0: float, y0: float, w: float, h: float, xlim, ylim):
        self.x0, self.y0, self.w, self.h, self.xlim, self.ylim = x0, y0, w, h, xlim, ylim

    def px(self, x: float) -> float:
        a, b = self.xlim
        return self.x0 + (x - a) / ((b - a) or 1.0) * self.w

    def py(self, y: float) -> float:
        a, b = self.ylim
        return self.y0 + self.h - (y - a) / ((b - a) or 1.0) * self.h

    def axes(self, xlabel: str, ylabel: str) -> list[str]:
        out = [_el("rect", x=self.x0, y=self.y0, width=self.w, height=self.h, fill="none", stroke="#888")]
        for v in _ticks(*self.ylim, n=4):
            out += [self.hline(v, "#eee", ""), _text(self.x0 - 4, self.py(v) + 3.5, fmt(v), 10, "end")]
        if xlabel:
            out += [_text(self.px(v), self.y0 + self.h + 13, fmt(v), 10) for v in _ticks(*self.xlim, n=8)]
            out.append(_text(self.x0 + self.w / 2, self.y0 + self.h + 27, xlabel))
        yc = self.y0 + self.h / 2
        return out + [_text(12, yc, ylabel, transform=f"rotate(-90 12 {_n(yc)})")]

    def line(self, xs, ys, color: str) -> str:
        """A path broken wherever a value is missing."""
        d, pen = [], False
        for x, y in zip(xs, ys):
            if x is not None and y is not None:
                d.append(f"{'L' if pen else 'M'}{_n(self.px(x))} {_n(self.py(y))}")
            pen = x is not None and y is not None
        return _el("path", d="".join(d), fill="none", stroke=color, stroke_width=1.4) if d else ""

    def hline(self, y: float, color: str = "#444", dash: str = "4 3") -> str:
        return _el("line", x1=self.x0, x2=self.x0 + self.w, y1=self.py(y), y2=self.py(y), stroke=color,
                   stroke_dasharray=dash)

    def vline(self, x: float, color: str, dash: str = "", top: float | None = None) -> str:
        return _el("line", x1=self.px(x), x2=self.px(x), y1=self.y0 if top is None else top, y2=self.y0 + self.h,
                   stroke=color, stroke_dasharray=dash)


def _legend(x: float, y: float, names) -> list[str]:
    """Colour key of line plots; it needs 34 + 6 px per character of the longest name."""
    out = []
    for k, name in enumerate(names):
        out += [_el("line", x1=x, x2=x + 16.0, y1=y + 13.0 * k, y2=y + 13.0 * k, stroke=PALETTE[k % len(PALETTE)],
                    stroke_width=2), _text(x + 20, y + 13 * k + 3.5, name, 10, "start")]
    return out


def _rows(xs_widths, n_rows: int = 4) -> list[int]:
    """Greedy label rows so that labels at nearby x do not overlap."""
    ends, out = [], []
    for x, w in xs_widths:
        r = next((k for k, e in enumerate(ends) if e < x), None)
        if r is None:
            r = len(ends) if len(ends) < n_rows else min(range(len(ends)), key=ends.__getitem__)
            ends += [0.0] * (r + 1 - len(ends))
        ends[r] = x + w
        out.append(r)
    return out


def _intervals(t: list, flags: list[bool]) -> list[tuple[float, float]]:
    """Maximal runs of True as (t_first, t_last)."""
    out, start = [], None
    for i, f in enumerate(list(flags) + [False]):
        if f != (start is not None):
            out, start = (out, i) if f else (out + [(t[start], t[i - 1])], None)
    return out


def _band(p: _Panel, a: float, b: float) -> str:
    """Vermillion shading over [a, b]: times when some h < 0, i.e. the state was outside C."""
    return _el("rect", x=p.px(a), y=p.y0, width=max(p.px(b) - p.px(a), 1.5), height=p.h, fill=VERMILLION,
               fill_opacity=0.15)


def series_svg(t, series: dict, *, title: str = "", ylabel: str = "h", zero_line: bool = True,
               shade_negative: bool | str = True, width: int = 560, height: int = 220, max_points: int = 400,
               mark: tuple[float, str] | None = None) -> str:
    """Line plot of named series over t; None breaks a line, times where any value < 0 are shaded
    (or, when shade_negative names a series, where that one is < 0); mark = (t, label) draws a
    labelled vertical line (e.g. where the flow enters E)."""
    t = [_num(v) for v in t]
    data = {str(k): [_num(v) for v in vs] + [None] * (len(t) - len(vs)) for k, vs in series.items()}
    ts = [v for v in t if v is not None]
    top = 22 if title else 8
    p = _Panel(48, top, width - 90 - 6 * max(map(len, data), default=0), height - top - 34,
               (min(ts), max(ts) if max(ts) > min(ts) else ts[0] + 1.0) if ts else (0.0, 1.0),
               _limits([v for vs in data.values() for v in vs], zero_line))
    body = [_text(48, 15, title, 12, "start", font_weight="bold")] if title else []
    if shade_negative:
        watch = [data[shade_negative]] if isinstance(shade_negative, str) and shade_negative in data else data.values()
        neg = [x is not None and any(vs[i] is not None and vs[i] < 0 for vs in watch) for i, x in enumerate(t)]
        body += [_band(p, a, b) for a, b in _intervals(t, neg)]
    body += p.axes("t (s)", ylabel) + ([p.hline(0.0)] if zero_line else [])
    idx = _decimate(len(t), max_points)
    body += [p.line([t[i] for i in idx], [vs[i] for i in idx], PALETTE[k % len(PALETTE)])
             for k, vs in enumerate(data.values())]
    if mark is not None and mark[0] is not None and ts and p.xlim[0] <= mark[0] <= p.xlim[1]:
        body += [p.vline(float(mark[0]), GREEN, "5 3"),
                 _text(p.px(float(mark[0])) - 3, p.y0 + 11, mark[1], 10, "end", fill="#00664a")]
    if not ts or all(v is None for vs in data.values() for v in vs):
        body.append(_text(p.x0 + p.w / 2, p.y0 + p.h / 2, "no data", 12))
    return _svg(width, height, body + _legend(p.x0 + p.w + 10, top + 6, data), title)


def run_limits(runs, n_states: int) -> tuple[tuple[float, float], tuple[float, float]]:
    """y ranges (states, min h) covering every run, so that runs drawn one above the other compare."""
    runs = list(runs)
    xs = [_num(row[k]) for r in runs for row in r.get("x", []) for k in range(min(n_states, len(row)))]
    return _limits(xs), _limits([_num(v) for r in runs for v in r.get("min_h", [])], True)


def trajectory_svg(run: dict, state_names, commands=(), *, width: int = 760, max_points: int = 500,
                   max_markers: int = 200, limits=None) -> str:
    """States and min h of one sequence run; switches labelled by the new primitive, violations marked.
    limits: (state y range, min h y range), e.g. run_limits of all runs, to share the y axes."""
    t = [_num(v) for v in run.get("t", [])]
    n_x = min(len(state_names), max((len(row) for row in run.get("x", [])), default=len(state_names)))
    hidden = len(state_names) - n_x
    state_names = list(state_names)[:n_x]  # a run keeps its first states only (compact.RUN_STATES)
    cols = [[_num(row[k]) if k < len(row) else None for row in run.get("x", [])] for k in range(n_x)]
    min_h = [_num(v) for v in run.get("min_h", [])] + [None] * (len(t) - len(run.get("min_h", [])))
    ts = [v for v in t if v is not None] or [0.0]
    xlim = (min(ts), max(ts) if max(ts) > min(ts) else min(ts) + 1.0)
    events = sorted([(float(c["t"]), f"goal {c['goal']}", "#777") for c in commands] +
                    [(float(s["t"]), f"→ {s['to']}", BLUE) for s in run.get("switches", [])], key=lambda e: e[0])
    pw = width - 90 - 6 * max(map(len, state_names), default=0)
    rows = _rows([(_Panel(48, 0, pw, 1, xlim, (0, 1)).px(te), 8 + 5.8 * len(lab)) for te, lab, _ in events], 6)
    head = 12 + 13 * (max(rows) + 1 if rows else 0)
    ylim, hlim = limits or (_limits([v for c in cols for v in c]), _limits(min_h, True))
    top = _Panel(48, head, pw, 170, xlim, ylim)
    bot = _Panel(48, head + 182, pw, 90, xlim, hlim)
    idx = _decimate(len(t), max_points)
    body = [_band(bot, a, b) for a, b in _intervals(t, [x is not None and v is not None and v < 0
                                                         for x, v in zip(t, min_h)])]
    body += top.axes("", "state") + bot.axes("t (s)", "min h") + [bot.hline(0.0)]
    body += [top.line([t[i] for i in idx], [c[i] for i in idx], PALETTE[k % len(PALETTE)]) for k, c in enumerate(cols)]
    body.append(bot.line([t[i] for i in idx], [min_h[i] for i in idx], "#444"))
    for (te, label, color), r in zip(events, rows):
        dash = "3 3" if color == "#777" else ""
        body += [top.vline(te, color, dash, top=14.0 + 13 * r), bot.vline(te, color, "3 3"),
                 _text(top.px(te) + 2, 12 + 13 * r, label, 10, "start", fill=color)]
    viol = run.get("violations", [])
    for v in [viol[i] for i in _decimate(len(viol), max_markers)]:
        x, y = bot.px(float(v["t"])), bot.py(min(max(float(v["value"]), bot.ylim[0]), bot.ylim[1]))
        tip = f"t = {fmt(v['t'], 4)} s: {v['h']} of {v['primitive']} = {fmt(v['value'])}"
        body.append(_el("path", _tip(tip), d=f"M{_n(x - 3)} {_n(y - 3)}L{_n(x + 3)} {_n(y + 3)}M{_n(x - 3)} "
                        f"{_n(y + 3)}L{_n(x + 3)} {_n(y - 3)}", stroke=VERMILLION, stroke_width=1.5))
    body += _legend(top.x0 + pw + 10, top.y0 + 6, state_names)
    if hidden:
        body.append(_text(top.x0 + pw + 10, top.y0 + 6 + 13 * n_x + 3.5, f"({hidden} more not drawn)", 10, "start",
                          fill="#555"))
    title = f"{run.get('mode', '')}: {'safe' if run.get('safe') else 'unsafe'}, {len(viol)} violation samples" + (
        f"; the first {n_x} of {n_x + hidden} states" if hidden else "")
    return _svg(width, bot.y0 + bot.h + 34, body, title)


def grid_svg(transition: dict, *, max_size: int = 360) -> str:
    """Oracle verdicts over (t_A rows, t_B columns), coloured by outcome; refined cells carry a dot."""
    tA, tB = transition["t_A"], transition["t_B"]

    def key_of(e: dict) -> tuple[str, str | None]:
        return "safe" if e.get("verdict") else e.get("reason", "error"), e.get("violated")

    def bound_of(e: dict) -> str:
        if e.get("status") != "inconclusive" or e.get("margin") is None:
            return ""
        return f"; margin {fmt(e['margin'])} within error bound {fmt(e.get('error_bound'))}"

    cells = transition.get("cells") or [[{"verdict": v, "reason": "entered_E" if v else "left_C"} for v in row]
                                         for row in transition["verdicts"]]
    c = max(4, min(22, max_size // max(len(tA), len(tB), 1)))
    x0, y0, gw, gh = 58, 8, c * len(tB), c * len(tA)
    body = []
    for i, row in enumerate(cells):
        j = 0
        while j < len(row):  # one rectangle per run of equal outcomes
            key, k = key_of(row[j]), j
            while k + 1 < len(row) and key_of(row[k + 1]) == key:
                k += 1
            span = fmt(tB[j]) if k == j else f"{fmt(tB[j])}…{fmt(tB[k])}"
            tip = f"t_A = {fmt(tA[i])}, t_B = {span}: {key[0]}" + (f" ({key[1]})" if key[1] else "") + \
                (bound_of(row[j]) if k == j else "")
            body.append(_el("rect", _tip(tip), x=x0 + c * j, y=y0 + c * i, width=c * (k - j + 1), height=c,
                            fill=CELL_COLORS.get(key[0], "#111111"), shape_rendering="crispEdges"))
            j = k + 1
        body += [_el("circle", cx=x0 + c * (j + .5), cy=y0 + c * (i + .5), r=max(c / 5, 1.5), fill="#fff",
                     stroke="#000", stroke_width=.6) for j, e in enumerate(row) if e.get("refined")]
    body.append(_el("rect", x=x0, y=y0, width=gw, height=gh, fill="none", stroke="#555"))
    ka, kb = math.ceil(13 / c), math.ceil(40 / c)
    body += [_text(x0 - 4, y0 + c * (i + .5) + 3.5, fmt(v), 10, "end") for i, v in enumerate(tA) if i % ka == 0]
    body += [_text(x0 + c * (j + .5), y0 + gh + 12, fmt(v), 10) for j, v in enumerate(tB) if j % kb == 0]
    yc = max(y0 + gh / 2, 28)
    body += [_text(x0 + gw / 2, y0 + gh + 26, "t_B (s)"),
             _text(11, yc, "t_A (s)", transform=f"rotate(-90 11 {_n(yc)})")]
    ly, lx, wmax = y0 + gh + 42, 8.0, 8.0
    limit = max(x0 + gw + 8, 340)  # the legend wraps instead of widening the picture
    for key, label in CELL_LABELS + (("refined", "refined (finer step)"),):
        item = 22 + 5.6 * len(label)
        if lx > 8.0 and lx + item > limit:
            ly, lx = ly + 16, 8.0
        body.append(_el("circle", cx=lx + 5, cy=ly - 4.0, r=3, fill="#fff", stroke="#000", stroke_width=.6)
                    if key == "refined" else _el("rect", x=lx, y=ly - 9.0, width=10, height=10, fill=CELL_COLORS[key]))
        body.append(_text(lx + 14, ly, label, 10, "start"))
        lx += item
        wmax = max(wmax, lx)
    return _svg(max(x0 + gw + 8, wmax), ly + 8, body, f"oracle grid {transition.get('from')} → {transition.get('to')}")


def _reach(shape: str, a: float, b: float, ux: float, uy: float) -> float:
    """Distance from a node's centre to its outline along the unit direction (ux, uy)."""
    ux, uy = abs(ux) + 1e-12, abs(uy) + 1e-12
    if shape == "box":
        return min(a / ux, b / uy)
    return 1.0 / (ux / a + uy / b) if shape == "diamond" else 1.0 / math.hypot(ux / a, uy / b)


def _node(shape: str, x: float, y: float, a: float, b: float, fill: str) -> str:
    st = {"fill": fill, "stroke": "#333", "stroke_width": 1.3}
    if shape == "box":
        return _el("rect", x=x - a, y=y - b, width=2.0 * a, height=2.0 * b, **st)
    if shape == "diamond":
        return _el("polygon", points=f"{_n(x)},{_n(y - b)} {_n(x + a)},{_n(y)} {_n(x)},{_n(y + b)} {_n(x - a)},{_n(y)}",
                   **st)
    return _el("ellipse", cx=x, cy=y, rx=a, ry=b, **st)


def _size(shape: str, name: str) -> tuple[float, float]:
    w = 3.4 * len(name) + 8
    return {"box": (w, 15.0), "diamond": (w + 16, 22.0)}.get(shape, (max(w + 4, 22.0), 20.0))


def window_text(a, b, number=fmt) -> str:
    """One t_A window: '[a, b]', or '{a}' when it is one grid point (safe there, not at its
    neighbours: nothing is claimed between)."""
    return f"{{{number(a)}}}" if a == b else f"[{number(a)}, {number(b)}]"


def windows_text(ws, limit: int = 3) -> str:
    """t_A windows as '[a, b] ∪ {c}' (at most limit of them, then the count of the others)."""
    ws = list(ws or [])
    txt = " ∪ ".join(window_text(a, b) for a, b in ws[:limit])
    return txt + (f" and {len(ws) - limit} more" if len(ws) > limit else "")


def robust_edges(report: dict) -> dict[tuple[str, str], dict]:
    """(from, to) -> the robust section's record of that nominal edge (empty without `robust`)."""
    return {(e["from"], e["to"]): e for e in (report.get("robust") or {}).get("edges", [])}


def edge_views(report: dict) -> list[dict]:
    """Each edge with what the pictures show: label, tooltip, whether the planner may use it, whether it
    survives the project's uncertainty (`robust`: True, False for nominal only, None unchecked) and its
    evidence (`method`: certified edges carry ✓ in their label; the tooltip says which)."""
    trs = {(t["from"], t["to"]): t for t in report.get("transitions", [])}
    rob = robust_edges(report)
    out = []
    for e in report.get("edges", []):
        tr = trs.get((e["from"], e["to"]))
        ws = tr.get("windows", []) if tr and e["class"] == 2 else []
        usable = e.get("usable", True) is not False
        r = rob.get((e["from"], e["to"]))
        robust = None if r is None else bool(r.get("survives"))
        method = tr.get("method") if tr else None
        label = f" {fmt(e.get('duration'))} s " if e.get("duration") is not None else ""
        if method == "certified":
            label = (label.rstrip() + " ✓ ") if label else " ✓ "
        if ws:
            label += f"\nt_A ∈ {windows_text(ws, 1)}"
        if robust is False:
            label += "\nnominal only"
        tip = (f"{e['from']} → {e['to']}: Class {e['class']}, duration {fmt(e.get('duration'))} s, "
               f"peak input {fmt(e.get('peak_input'))}")
        if ws:
            tip += f"; safe only from t_A in {windows_text(ws, 8)} s"
        if method:
            tip += f"; evidence: {method}" + (f", {proved_text(tr)} s" if proved_text(tr) else "")
        if not usable:
            tip += f"; not used by the planner: {e.get('unusable_reason') or 'not executable'}"
        if robust is False:
            tip += (f"; nominal only: unsafe under the project's uncertainty (worst margin "
                    f"{fmt(r.get('worst_margin'))})")
        elif robust and r.get("robust_class") != e["class"]:
            tip += f"; Class {r.get('robust_class')} under uncertainty"
        out.append({"e": e, "label": label, "tip": tip, "usable": usable, "robust": robust, "method": method})
    return out


def graph_dot(report: dict) -> str:
    """DOT text laid out for the report (Graphviz `dot`): shapes by class, dashed Class 2, grey edges
    the planner cannot use, dotted vermillion edges that are nominal only, labels beside the edges."""
    def q(v) -> str:
        return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'

    lines = ["digraph mpg {", '  graph [rankdir=TB, newrank=true, nodesep=0.3, ranksep=0.4, pad=0.15, bgcolor="transparent", '
             'fontname="Helvetica,Arial,sans-serif"];',
             '  node [fontname="Helvetica,Arial,sans-serif", fontsize=12, style=filled, color="#333333", '
             'penwidth=1.2, margin="0.12,0.05"];',
             '  edge [fontname="Helvetica,Arial,sans-serif", fontsize=11, color="#333333", arrowsize=0.7];']
    for p in report.get("primitives", []):
        shape = {"fixed": "box", "periodic": "ellipse", "transient": "diamond"}.get(p["class"], "ellipse")
        lines.append(f"  {q(p['name'])} [shape={shape}, fillcolor={q(NODE_FILL.get(p['class'], '#eeeeee'))}, "
                     f"tooltip={q(p['name'] + ': ' + p['class'])}];")
    for v in edge_views(report):
        e = v["e"]
        if e["from"] == e["to"]:
            continue
        color = UNUSABLE if not v["usable"] else NOMINAL_ONLY if v["robust"] is False else "#333333"
        style = "dashed" if e["class"] == 2 else "solid"  # class by line style, robustness by colour
        attrs = [f"style={style}", f"color={q(color)}", f"fontcolor={q(color)}",
                 f"label={q(v['label'])}", f"tooltip={q(v['tip'])}", f"labeltooltip={q(v['tip'])}"]
        if v["robust"] is False:
            attrs.append("penwidth=1.6")
        lines.append(f"  {q(e['from'])} -> {q(e['to'])} [{', '.join(attrs)}];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def graphviz_svg(report: dict, timeout: float = 10.0) -> str | None:
    """The graph laid out by Graphviz's `dot` (None when dot is missing, fails or takes too long, or
    MPGSPEC_GRAPHVIZ=0)."""
    import os
    import re
    import shutil
    import subprocess

    exe = shutil.which("dot")
    if exe is None or os.environ.get("MPGSPEC_GRAPHVIZ", "1") == "0":
        return None
    try:
        out = subprocess.run([exe, "-Tsvg"], input=graph_dot(report).encode("utf-8"), capture_output=True,
                             timeout=timeout, check=True).stdout.decode("utf-8")
    except (OSError, subprocess.SubprocessError, UnicodeDecodeError):
        return None
    start = out.find("<svg")
    if start < 0:
        return None
    out = out[start:]
    out = re.sub(r"<!--.*?-->", "", out, flags=re.S)
    m = re.match(r'<svg width="([\d.]+)pt" height="([\d.]+)pt"', out)
    if m:  # pt -> px, so the picture has its natural size and shrinks on small screens
        w, h = (float(v) * 4 / 3 for v in m.groups())
        out = f'<svg width="{_n(w)}" height="{_n(h)}"' + out[m.end():]
    out = out.replace("<svg ", '<svg role="img" class="mpg-graph" ', 1)
    return out


def layered_layout(G: nx.DiGraph, order: list[str]) -> dict[str, tuple[float, float]]:
    """Node -> (x, y) in [-1, 1]^2, layer by layer from the top: a node's layer is its distance (in
    edges) from the first primitive of `order` (the paper draws its graphs this way, from Lie down);
    nodes it cannot reach come last, in a layer by their distance from the rest. Within a layer
    nodes are ordered by the mean position of their neighbours in the layers above (barycentres),
    ties in the report's order: crossings stay few without a layout engine."""
    if not len(G):
        return {}
    rank = {n: k for k, n in enumerate(order)}
    dist = nx.single_source_shortest_path_length(G, order[0]) if order and order[0] in G else {}
    rest = [n for n in G if n not in dist]
    if rest:
        far = max(dist.values(), default=-1) + 1
        away = nx.multi_source_dijkstra_path_length(G.to_undirected(), set(dist)) if dist else {}
        dist.update({n: far + max(int(away.get(n, 1)) - 1, 0) for n in rest})
    layers: dict[int, list[str]] = {}
    for n in sorted(G, key=lambda n: rank.get(n, len(rank))):
        layers.setdefault(dist[n], []).append(n)
    depth = sorted(layers)
    x: dict[str, float] = {}
    for d in depth:
        row = layers[d]
        def centre(n: str) -> float:
            near = [x[m] for m in nx.all_neighbors(G, n) if m in x]
            return sum(near) / len(near) if near else rank.get(n, 0) / max(len(rank), 1)
        row.sort(key=lambda n: (centre(n), rank.get(n, 0)))
        for i, n in enumerate(row):
            x[n] = (i + 0.5) / len(row)
    # a crowded layer takes two rows (every other node one row lower), so its nodes do not touch and
    # the edges between them are curves one can follow
    rows: list[list[str]] = []
    for d in depth:
        row = layers[d]
        rows += [row[0::2], row[1::2]] if len(row) > 3 else [row]
    gap = 2.0 / max(len(rows) - 1, 1)
    return {n: (2.0 * x[n] - 1.0, 1.0 - gap * k) for k, row in enumerate(rows) for n in row}


def graph_svg(report: dict, *, width: int = 640, height: int = 470, layout: str = "layered") -> str:
    """The motion primitive graph: box fixed, ellipse periodic, diamond transient; solid Class 1, dashed Class 2,
    grey edges the planner cannot use, vermillion edges that are nominal only; duration labels beside
    the edges (hand-made layout)."""
    prims = report.get("primitives", [])
    node = {p["name"]: (SHAPES.get(p["class"], "ellipse"), *_size(SHAPES.get(p["class"], "ellipse"), p["name"]))
            for p in prims}
    views = [v for v in edge_views(report) if v["e"]["from"] in node and v["e"]["to"] in node
             and v["e"]["from"] != v["e"]["to"]]
    edges = [v["e"] for v in views]
    G = nx.DiGraph()
    G.add_nodes_from(node)
    G.add_edges_from((e["from"], e["to"]) for e in edges)
    kk = layout == "kamada_kawai" and len(G) > 2
    pos = (layered_layout(G, [p["name"] for p in prims]) if layout == "layered" else
           nx.kamada_kawai_layout(G.to_undirected()) if kk else nx.circular_layout(G))
    gh, m = height - 44, 12 + max((s[1] for s in node.values()), default=20)
    P = {k: (width / 2 + float(v[0]) * (width / 2 - m), gh / 2 - float(v[1]) * (gh / 2 - 34)) for k, v in pos.items()}
    body = [f'<defs><marker id="{ARROW_ID}" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
            f'orient="auto"><path d="M0 0L10 5L0 10z" fill="#333"/></marker>'
            f'<marker id="{ARROW_ID}-grey" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
            f'orient="auto"><path d="M0 0L10 5L0 10z" fill="{UNUSABLE}"/></marker>'
            f'<marker id="{ARROW_ID}-nominal" viewBox="0 0 10 10" refX="9" refY="5" markerWidth="7" markerHeight="7" '
            f'orient="auto"><path d="M0 0L10 5L0 10z" fill="{NOMINAL_ONLY}"/></marker></defs>']
    labels = []
    for v in views:
        e = v["e"]
        lost = v["robust"] is False
        color, arrow = ((UNUSABLE, ARROW_ID + "-grey") if not v["usable"] else
                        (NOMINAL_ONLY, ARROW_ID + "-nominal") if lost else ("#333", ARROW_ID))
        (ax, ay), (bx, by) = P[e["from"]], P[e["to"]]
        cx, cy = (ax + bx) / 2 - 0.15 * (by - ay), (ay + by) / 2 + 0.15 * (bx - ax)  # bend: A->B and B->A part
        ends = []
        for (px, py), nm, gap in (((ax, ay), e["from"], 0), ((bx, by), e["to"], 2)):
            d = math.hypot(cx - px, cy - py) or 1.0
            r = _reach(*node[nm], (cx - px) / d, (cy - py) / d) + gap
            ends.append(f"{_n(px + (cx - px) / d * r)} {_n(py + (cy - py) / d * r)}")
        body.append(_el("path", _tip(v["tip"]), data_from=e["from"], data_to=e["to"],
                        d=f"M{ends[0]}Q{_n(cx)} {_n(cy)} {ends[1]}", fill="none",
                        stroke=color, stroke_width=1.6 if lost else 1.2,
                        stroke_dasharray=DASH if e["class"] == 2 else "",  # class by style, robustness by colour
                        marker_end=f"url(#{arrow})"))
        if v["label"]:
            # beside the curve: from its midpoint, outwards along the bend's normal
            mx, my = (ax + 2 * cx + bx) / 4, (ay + 2 * cy + by) / 4
            nx_, ny_ = cx - (ax + bx) / 2, cy - (ay + by) / 2
            d = math.hypot(nx_, ny_) or 1.0
            lab = v["label"].split("\n")[0].strip() + (" (C2)" if e["class"] == 2 else "") + (" ✗" if lost else "")
            lx, ly = mx + nx_ / d * 9, my + ny_ / d * 9 + 3
            anchor = "middle" if abs(nx_ / d) < 0.4 else ("start" if nx_ > 0 else "end")
            labels += [_text(lx, ly, lab, 10, anchor, stroke="#fff", stroke_width=3, stroke_linejoin="round",
                             data_from=e["from"], data_to=e["to"]),
                       _el("text", _tip(v["tip"]) + escape(lab), x=float(lx), y=float(ly), font_size=10,
                           text_anchor=anchor, fill=color, data_from=e["from"], data_to=e["to"])]
    for p in prims:
        (x, y), (shape, a, b) = P[p["name"]], node[p["name"]]
        body.append(_el("g", _node(shape, x, y, a, b, NODE_FILL.get(p["class"], "#eee")) + _text(x, y + 4, p["name"]),
                        data_node=p["name"]))
    ly = height - 18.0
    body += labels
    for x, (cls, shape) in zip((20, 92, 174), SHAPES.items()):
        body += [_node(shape, x, ly, 11, 8, NODE_FILL[cls]), _text(x + 15, ly + 4, cls, 10, "start")]
    keys = [("Class 1", "#333", "", ARROW_ID), ("Class 2 (C2)", "#333", DASH, ARROW_ID)]
    if any(v["robust"] is False for v in views):
        keys.append(("nominal only ✗", NOMINAL_ONLY, "", ARROW_ID + "-nominal"))
    for k, (label, color, dash, arrow) in enumerate(keys):
        x = 250.0 + 120 * k
        body += [_el("line", x1=x, x2=x + 30, y1=ly, y2=ly, stroke=color, stroke_width=1.6 if color == NOMINAL_ONLY else 1.2,
                     stroke_dasharray=dash, marker_end=f"url(#{arrow})"),
                 _text(x + 36, ly + 4, label, 10, "start")]
    return _svg(width, height, body, f"motion primitive graph of {report.get('project', {}).get('name', '')}")
