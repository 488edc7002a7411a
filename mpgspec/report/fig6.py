"""Fig. 6 of the paper from a goal sequence's runs: CoM height and trunk roll / pitch / yaw over time,
every run on shared axes above the primitive timeline (a row of blocks per run, switches marked),
and gait tiles: side-view stick figures of the robot at the switches, all at one scale.

Runs are in the readable form of compact.run_rows; `body` and `poses` come from the execute stage.
"""
from __future__ import annotations

import math
from statistics import median

from .svg import (BLUE, GREEN, ORANGE, PALETTE, PURPLE, SKY, VERMILLION, YELLOW, _el, _intervals, _n, _num, _Panel,
                  _svg, _text, _ticks, _tip, fmt)

RUN_COLORS = {"graph": BLUE, "naive": VERMILLION}
BLOCK_COLORS = (SKY, ORANGE, GREEN, YELLOW, PURPLE, "#999999")
"""Primitive blocks in the order of the report's primitives; from the seventh on the colours repeat hatched."""
BODY = (("com_z", "CoM z (m)", 1.0, 110), ("roll", "roll (°)", 180 / math.pi, 64),
        ("pitch", "pitch (°)", 180 / math.pi, 64), ("yaw", "yaw (°)", 180 / math.pi, 64))
"""Panels: series key, axis label, scale from the stored unit, height in px."""
NEAR, FAR = "#222222", "#a8a8a8"
TILE_W, TILE_HEAD = 124, 28
RUNAWAY = 3.0


def run_color(mode: str, k: int) -> str:
    return RUN_COLORS.get(mode, PALETTE[(k + 2) % len(PALETTE)])


def _block_fill(k: int) -> str:
    return BLOCK_COLORS[k % len(BLOCK_COLORS)] if k < len(BLOCK_COLORS) else f"url(#fig6-hatch-{k % len(BLOCK_COLORS)})"


def _hatches() -> str:
    pats = "".join(
        f'<pattern id="fig6-hatch-{k}" patternUnits="userSpaceOnUse" width="6" height="6" '
        f'patternTransform="rotate(45)"><rect width="6" height="6" fill="{c}"/>'
        f'<rect width="2.5" height="6" fill="#fff" fill-opacity="0.75"/></pattern>' for k, c in enumerate(BLOCK_COLORS))
    return f"<defs>{pats}</defs>"


def _span(values, zero: bool) -> tuple[float, float]:
    """A y range over the values that a run running away does not stretch beyond a few spreads of
    the others (lines are clipped to the panel); padded, with 0 when `zero`."""
    vals = sorted(v for v in values if v is not None)
    if not vals:
        return (-1.0, 1.0) if zero else (0.0, 1.0)
    q1, q99 = vals[int(0.01 * (len(vals) - 1))], vals[int(0.99 * (len(vals) - 1))]
    s = max(q99 - q1, 1e-9)
    lo, hi = max(vals[0], q1 - 2 * s), min(vals[-1], q99 + 2 * s)
    lo, hi = (min(lo, 0.0), max(hi, 0.0)) if zero else (lo, hi)
    pad = 0.06 * (hi - lo) if hi - lo > 1e-6 else max(1.0 if zero else 0.05, abs(lo) * 0.1)
    return lo - pad, hi + pad


def _axes(p: _Panel, label: str, n: int, xlabel: bool) -> list[str]:
    out = [_el("rect", x=p.x0, y=p.y0, width=p.w, height=p.h, fill="none", stroke="#888")]
    for v in _ticks(*p.ylim, n=n):
        out += [p.hline(v, "#eee", ""), _text(p.x0 - 4, p.py(v) + 3.5, fmt(v), 10, "end")]
    if xlabel:
        out += [_text(p.px(v), p.y0 + p.h + 13, fmt(v), 10) for v in _ticks(*p.xlim, n=8)]
        out.append(_text(p.x0 + p.w / 2, p.y0 + p.h + 27, "t (s)"))
    yc = p.y0 + p.h / 2
    return out + [_text(13, yc, label, 10, transform=f"rotate(-90 13 {_n(yc)})")]


def _end(run: dict, duration: float) -> float:
    """Where a run's timeline ends: its duration, or its last sample when it stopped early."""
    t = [v for v in map(_num, run.get("t") or []) if v is not None]
    if not t:
        return 0.0
    gap = 2 * (t[-1] - t[-2]) if len(t) > 1 else 0.0
    return duration if t[-1] >= duration - max(gap, 0.01) else t[-1]


def _blocks(spans, y: float, p: _Panel, index: dict, who: str) -> list[str]:
    """One coloured block per (start, end, primitive), labelled where the name fits."""
    out = []
    for a, b, name in spans:
        x, w = p.px(a), max(p.px(b) - p.px(a), 0.8)
        k = index.get(name, len(index))
        out.append(_el("rect", _tip(f"{who}: {name} from {fmt(a, 4)} s to {fmt(b, 4)} s"), x=x, y=y, width=w,
                       height=16.0, fill=_block_fill(k), stroke="#fff", stroke_width=0.6))
        if w >= 6.0 * len(name) + 6:
            out.append(_text(x + w / 2, y + 11.5, name, 10, fill="#000"))
    return out


def _key(runs: dict, colors: dict, x: float) -> list[str]:
    """One line per run, the switch mark and the outside-C bar, in a row above the panels."""
    out = []
    for m, r in runs.items():
        lab = f"{m} ({'safe' if r.get('safe') else 'unsafe'})"
        out += [_el("line", x1=x, x2=x + 18, y1=11.0, y2=11.0, stroke=colors[m], stroke_width=2.2),
                _text(x + 22, 14.5, lab, 10, "start")]
        x += 34 + 5.8 * len(lab)
    out += [_el("line", x1=x, x2=x, y1=4.0, y2=17.0, stroke="#555", stroke_dasharray="3 2"),
            _text(x + 5, 14.5, "switch (run's colour)", 10, "start")]
    x += 130
    return out + [_el("rect", x=x, y=9.0, width=18.0, height=4.0, fill=VERMILLION),
                  _text(x + 22, 14.5, "outside C", 10, "start")]


def _panels(runs: dict, colors: dict, x0: float, pw: float, xlim, y: float) -> tuple[list[str], list[_Panel]]:
    """The BODY panels stacked from y, one line per run in each, clipped to its panel."""
    out, panels = [], []
    for n, (key, label, scale, h) in enumerate(BODY):
        series = {m: [None if _num(v) is None else _num(v) * scale for v in (r.get("body") or {}).get(key) or []]
                  for m, r in runs.items()}
        p = _Panel(x0, y, pw, h, xlim, _span([v for vs in series.values() for v in vs], key != "com_z"))
        out += _axes(p, label, 4 if h > 80 else 3, n == len(BODY) - 1)
        if key != "com_z":
            out.append(p.hline(0.0, "#bbb", "2 2"))
        clip = f"fig6-clip-{n}"
        out.append(f'<clipPath id="{clip}"><rect x="{_n(p.x0)}" y="{_n(p.y0)}" width="{_n(p.w)}" '
                   f'height="{_n(p.h)}"/></clipPath>')
        lines = [p.line([_num(v) for v in runs[m].get("t") or []], vs, colors[m]) for m, vs in series.items()]
        out.append(_el("g", "".join(lines), clip_path=f"url(#{clip})", data_series=key))
        panels.append(p)
        y += h + 8
    top, bottom = panels[0].y0, panels[-1].y0 + panels[-1].h
    for m, r in runs.items():
        for s in r.get("switches") or []:
            t = _num(s.get("t"))
            if s.get("reason") == "start" or t is None or not xlim[0] <= t <= xlim[1]:
                continue
            x = panels[0].px(t)
            out.append(_el("line", _tip(f"{m}: {s.get('from', '')} → {s['to']} at {fmt(t, 4)} s"), x1=x, x2=x,
                           y1=top, y2=bottom, stroke=colors[m], stroke_opacity=0.55, stroke_dasharray="3 2",
                           data_switch=m))
    return out, panels


def _unsafe(run: dict, mode: str, tl: _Panel, y: float) -> list[str]:
    """Vermillion bars under a run's row where its least active h was negative."""
    t = [_num(v) for v in run.get("t") or []]
    low = [_num(v) for v in run.get("min_h") or []]
    bad = [x is not None and i < len(low) and low[i] is not None and low[i] < 0 for i, x in enumerate(t)]
    v0 = (run.get("violations") or [None])[0]
    first = f"; first: {v0['h']} of {v0['primitive']} at {fmt(v0['t'], 4)} s" if v0 else ""
    return [_el("rect", _tip(f"{mode} outside C from {fmt(a, 4)} s to {fmt(b, 4)} s{first}"), x=tl.px(a), y=y,
                width=max(tl.px(b) - tl.px(a), 1.5), height=4.0, fill=VERMILLION, data_unsafe=mode)
            for a, b in _intervals(t, bad)]


def body_svg(runs: dict, commands, primitives, duration: float, *, width: int = 960) -> str | None:
    """CoM height and trunk roll / pitch / yaw of every run on shared axes, the goal commands and each
    run's active primitive as rows of blocks below, switch times marked across the panels and the
    times outside C as a vermillion bar under a run's row. None when no run has `body` series."""
    runs = {m: r for m, r in runs.items() if (r.get("body") or {}).get("com_z")}
    if not runs:
        return None
    index = {name: k for k, name in enumerate(primitives)}
    x0, right = 66.0, 14.0
    xlim = (0.0, float(duration) if duration and duration > 0 else 1.0)
    colors = {m: run_color(m, k) for k, m in enumerate(runs)}
    body, panels = _panels(runs, colors, x0, width - x0 - right, xlim, 26.0)
    body = [_hatches(), *_key(runs, colors, x0), *body]
    y = panels[-1].y0 + panels[-1].h + 40
    tl = _Panel(x0, y, width - x0 - right, 1.0, xlim, (0.0, 1.0))
    cmds = sorted(commands or [], key=lambda c: float(c["t"]))
    rows = [("goals", [(float(c["t"]), float(cmds[k + 1]["t"]) if k + 1 < len(cmds) else xlim[1], c["goal"])
                       for k, c in enumerate(cmds)], None)]
    for m, r in runs.items():
        sw = [s for s in r.get("switches") or [] if _num(s.get("t")) is not None]
        end = _end(r, xlim[1])
        rows.append((m, [(float(s["t"]), float(sw[k + 1]["t"]) if k + 1 < len(sw) else end, s["to"])
                         for k, s in enumerate(sw)], r))
    for m, spans, r in rows:
        body.append(_text(x0 - 4, y + 11.5, m, 10, "end", fill=colors.get(m, "#000")))
        body += _blocks(spans, y, tl, index, m)
        if r is not None:
            body += _unsafe(r, m, tl, y + 17.0)
            if spans and spans[-1][1] < xlim[1] - 1e-9:
                body.append(_text(tl.px(spans[-1][1]) + 3, y + 11.5, "stopped", 10, "start", fill=VERMILLION))
        y += 24
    y += 6
    lx = x0
    for name in primitives:  # colour key of the blocks, wrapping
        item = 22 + 6.0 * len(name)
        if lx > x0 and lx + item > width - right:
            lx, y = x0, y + 16
        body += [_el("rect", x=lx, y=y, width=12.0, height=12.0, fill=_block_fill(index[name]), stroke="#888",
                     stroke_width=0.5), _text(lx + 16, y + 10, name, 10, "start")]
        lx += item
    return _svg(width, y + 20, body, "CoM height and trunk orientation per run, with the primitive timeline")


def _xz(pt) -> tuple[float, float] | None:
    x, z = _num(pt[0]), _num(pt[2])
    return None if x is None or z is None else (x, z)


def _extent(pose: dict) -> tuple[float, float, float, float] | None:
    """Centre x of the trunk, largest |x - centre|, lowest and highest z of a pose."""
    trunk = [q for q in map(_xz, pose.get("trunk") or []) if q]
    pts = trunk + [q for leg in pose.get("legs") or [] for q in map(_xz, leg) if q]
    if not trunk:
        return None
    cx = sum(q[0] for q in trunk) / len(trunk)
    return cx, max(abs(q[0] - cx) for q in pts), min(q[1] for q in pts), max(q[1] for q in pts)


def tile_scale(runs: dict) -> tuple[float, float, float] | None:
    """(half-width, lowest z, highest z) in metres that every tile shows: the largest extent of the
    poses apart from those beyond RUNAWAY times the median one (drawn clipped)."""
    ext = [e for r in runs.values() for p in r.get("poses") or [] if (e := _extent(p))]
    if not ext:
        return None
    size = median(max(e[1], e[3]) for e in ext)
    ext = [e for e in ext if max(e[1], e[3]) <= RUNAWAY * size] or ext
    half, top = max(e[1] for e in ext), max(e[3] for e in ext)
    top = max(top, 0.2 * half)
    return 1.08 * half, -0.1 * max(top, half), 1.06 * top


def _label(pose: dict, leaves: bool) -> tuple[str, str]:
    t = f"{pose['t']:.2f} s"
    name, ev = str(pose.get("primitive", "")), pose.get("event")
    line1 = f"{t} ✗ leaves C" if leaves else f"{t} · {ev}"
    return line1, f"→ {name}" if ev == "switch" else name


def tile_svg(pose: dict, scale: tuple[float, float, float], color: str, mode: str = "", uid: str = "0",
             leaves: bool | None = None) -> str:
    """Side view (x right, z up) of one pose centred on its trunk: ground at z = 0 with a tick every
    0.1 m of world x, far legs grey, trunk, near legs dark (near: the legs on the -y side). A pose
    where the run leaves C (by default its first violation) is framed vermillion; uid makes the clip
    path's id unique in the page."""
    half, zlo, zhi = scale
    s = (TILE_W - 8) / (2 * half)
    h = TILE_HEAD + (zhi - zlo) * s + 4
    e = _extent(pose)
    cx = e[0] if e else 0.0

    def px(q):
        return 4 + (q[0] - cx + half) * s, TILE_HEAD + (zhi - q[1]) * s

    bad = pose.get("event") == "first_violation" if leaves is None else leaves
    line1, line2 = _label(pose, bad)
    body = [_el("rect", x=0.5, y=0.5, width=TILE_W - 1.0, height=h - 1, fill="#fff", rx=3,
                stroke=VERMILLION if bad else "#cfcfcf", stroke_width=2 if bad else 1),
            _text(TILE_W / 2, 12, line1, 10, fill=VERMILLION if bad else "#333"),
            _text(TILE_W / 2, 24, line2 if len(line2) <= 19 else line2[:18] + "…", 10, font_weight="bold",
                  fill=VERMILLION if bad else "#000")]
    gy = TILE_HEAD + zhi * s
    inner = [_el("line", x1=2.0, x2=TILE_W - 2.0, y1=gy, y2=gy, stroke="#6b6b6b", stroke_width=1.2)]
    k0 = math.ceil((cx - half) / 0.1)
    for k in range(k0, k0 + int(2 * half / 0.1) + 2):
        x = px((k * 0.1, 0.0))[0]
        if 2 <= x <= TILE_W - 2:
            inner.append(_el("line", x1=x, x2=x - 4, y1=gy, y2=gy + 4, stroke="#9a9a9a"))
    trunk = [q for q in map(_xz, pose.get("trunk") or []) if q]
    ty = [_num(q[1]) for q in pose.get("trunk") or [] if _num(q[1]) is not None]
    cy = sum(ty) / len(ty) if ty else 0.0
    legs = []
    for leg in pose.get("legs") or []:
        ys = [_num(q[1]) for q in leg if _num(q[1]) is not None]
        pts = [px(q) for q in map(_xz, leg) if q]
        if pts:
            legs.append((bool(ys) and sum(ys) / len(ys) < cy, pts))

    def draw(pts, color_, width):
        d = "".join(f"{'L' if i else 'M'}{_n(x)} {_n(y)}" for i, (x, y) in enumerate(pts))
        out = [_el("path", d=d, fill="none", stroke=color_, stroke_width=width, stroke_linejoin="round",
                   stroke_linecap="round")]
        out += [_el("circle", cx=x, cy=y, r=1.6, fill=color_) for x, y in pts[1:-1]]
        return out + [_el("circle", cx=pts[-1][0], cy=pts[-1][1], r=2.4, fill=color_)]

    for near, pts in legs:
        if not near:
            inner += draw(pts, FAR, 2.0)
    if trunk:
        inner.append(_el("polygon", points=" ".join(f"{_n(x)},{_n(y)}" for x, y in map(px, trunk)), fill=color,
                         fill_opacity=0.35, stroke=color, stroke_width=1.5, stroke_linejoin="round"))
    for near, pts in legs:
        if near:
            inner += draw(pts, NEAR, 2.2)
    com = _xz(pose.get("com") or (None, None, None))
    if com:
        x, y = px(com)
        inner.append(_el("circle", cx=x, cy=y, r=2.6, fill="#fff", stroke="#000", stroke_width=1))
    clip = f"tile-clip-{uid}"
    body += [f'<clipPath id="{clip}"><rect x="1" y="{_n(TILE_HEAD - 2)}" width="{TILE_W - 2}" '
             f'height="{_n(h - TILE_HEAD)}"/></clipPath>', _el("g", "".join(inner), clip_path=f"url(#{clip})")]
    tip = f"{mode}: {line1}, {pose.get('primitive', '')}"
    return _svg(TILE_W, h, body, tip).replace("<svg ", '<svg class="tile" ', 1)


def gait_tiles(runs: dict) -> list[dict]:
    """Per run with poses: its mode, colour and one tile per pose, all at one scale (a first
    violation at the time of a switch is shown on that switch's tile)."""
    scale = tile_scale(runs)
    if scale is None:
        return []
    out = []
    for k, (m, r) in enumerate(runs.items()):
        shown: list[list] = []  # [pose, leaves C]; a first violation at a switch marks that switch's tile
        for p in r.get("poses") or []:
            if not _extent(p):
                continue
            if p.get("event") == "first_violation" and shown and abs(shown[-1][0]["t"] - p["t"]) < 1e-9:
                shown[-1][1] = True
            else:
                shown.append([p, p.get("event") == "first_violation"])
        if shown:
            out.append({"mode": m, "color": run_color(m, k), "safe": bool(r.get("safe")),
                        "tiles": [tile_svg(p, scale, run_color(m, k), m, f"{k}-{j}", bad)
                                  for j, (p, bad) in enumerate(shown)]})
    return out
