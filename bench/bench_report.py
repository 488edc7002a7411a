"""What a written report weighs: report.json by top-level key, report.html by section, the time to
read and render it, and (with Chromium) the page's height at 1400 and 390 px and its first paint.

    python bench/bench_report.py [reports/a1 ...] [--no-write]

Reads the folders `mpgspec verify` wrote (default: reports/a1 and reports/pendulum); targets for the
A1 (issue: reports that tell the truth at a glance): report.json <= 1 MB, report.html <= 1.5 MB,
first paint < 0.3 s, page <= 8,000 px at 1400 px with sections folded.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "report"))

import common  # noqa: E402  (bench/common.py)

from mpgspec.report.html import render_html  # noqa: E402

HEADING = "## Report weight"
PAINTS = 5
PAGE = ("({h: document.documentElement.scrollHeight, sw: document.documentElement.scrollWidth, "
        "fcp: (performance.getEntriesByName('first-contentful-paint')[0] || {}).startTime})")


def _mb(n: int) -> str:
    return f"{n / 1e6:.2f} MB"


def weigh(folder: Path) -> list[tuple[str, str]]:
    js, html = folder / "report.json", folder / "report.html"
    raw = js.read_bytes()
    t0 = time.perf_counter()
    report = json.loads(raw)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    render_html(report)
    t_render = time.perf_counter() - t0
    name = report["project"]["name"]
    keys = sorted(((k, len(json.dumps(v, separators=(",", ":")))) for k, v in report.items()), key=lambda kv: -kv[1])
    text = html.read_text(encoding="utf-8")
    marks = [(m.start(), m.group(1)) for m in re.finditer(r'<section id="([^"]+)"', text)] + [(len(text), "")]
    sections = sorted(((n, b - a) for (a, n), (b, _) in zip(marks, marks[1:])), key=lambda kv: -kv[1])
    rows = [(f"{name}: report.json / report.html", f"**{_mb(len(raw))}** / **{_mb(len(text.encode()))}**"),
            (f"{name}: report.json's largest keys", ", ".join(f"{k} {v / 1e3:.0f} kB" for k, v in keys[:6])),
            (f"{name}: report.html's largest sections", ", ".join(f"{k} {v / 1e3:.0f} kB" for k, v in sections[:6])),
            (f"{name}: json.load / render_html", f"{t_load * 1e3:.0f} ms / {t_render * 1e3:.0f} ms")]
    try:
        from cdp_browser import Browser, find_chromium
    except ImportError:
        return rows
    exe = find_chromium()
    if exe is None:
        return rows
    with Browser(exe) as b:  # each width loaded PAINTS times, interleaved: the median first paint
        loads = [[b.open(html.resolve().as_uri(), w, script=PAGE)["value"] for w in (1400, 390)] for _ in range(PAINTS)]
    page = loads[0]
    paints = [sorted(p[k]["fcp"] for p in loads if p[k].get("fcp") is not None) for k in range(2)]
    rows.append((f"{name}: page height at 1400 / 390 px (sections folded as shipped)",
                 f"{page[0]['h']:,} / {page[1]['h']:,} px; first paint (median of {PAINTS} loads) "
                 + " / ".join(f"{f[len(f) // 2]:.0f} ms" if f else "not reported" for f in paints)))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="*", default=["reports/a1", "reports/pendulum"])
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = [r for f in args.folders for r in weigh(Path(f))]
    mach = common.machine(casadi=__import__("casadi").__version__)
    mach["revision"] = common.revision(ROOT)
    common.publish(HEADING, mach, "bench_report.py", 1, time.perf_counter() - t0, common.markdown_table(rows),
                   not args.no_write)


if __name__ == "__main__":
    main()
