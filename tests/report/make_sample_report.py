"""Regenerate tests/report/data/sample_report.json: the pendulum report, shrunk to keep the fixture small.

    python tests/report/make_sample_report.py

Oracle grids are subsampled to every k-th t_A and t_B (verdicts, cells, best_t_B and counts stay
consistent), time series are decimated and floats rounded; the result still validates.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from mpgspec import api
from mpgspec.report.compact import compact_cells, expand_cells
from mpgspec.report.schema import validate_report

ROOT = Path(__file__).resolve().parents[2]
OUT = Path(__file__).with_name("data") / "sample_report.json"
MAX_GRID, MAX_POINTS, MAX_VIOLATIONS = 6, 120, 8


def _every(n: int, m: int) -> list[int]:
    return list(range(0, n, max(1, math.ceil(n / m))))


def _round(x):
    if isinstance(x, float):
        return float(f"{x:.6g}")
    if isinstance(x, list):
        return [_round(v) for v in x]
    if isinstance(x, dict):
        return {k: _round(v) for k, v in x.items()}
    return x


def _grid(tr: dict) -> None:
    ia, ib = _every(len(tr["t_A"]), MAX_GRID), _every(len(tr["t_B"]), MAX_GRID)
    cells = expand_cells(tr)
    tr["t_A"], tr["t_B"] = [tr["t_A"][i] for i in ia], [tr["t_B"][j] for j in ib]
    tr["verdicts"] = [[tr["verdicts"][i][j] for j in ib] for i in ia]
    cells = [[cells[i][j] | {"message": cells[i][j]["message"][:80]} for j in ib] for i in ia]
    tr["cells"] = compact_cells(cells, tr["h_names"])
    tr["best_t_B"] = [tr["best_t_B"][i] for i in ia]
    flat = [e for row in cells for e in row]
    tr["counts"] = {"safe": sum(e["verdict"] for e in flat), "total": len(flat),
                    "inconclusive": sum(e["status"] == "inconclusive" for e in flat),
                    "refined": sum(e["refined"] for e in flat), "errors": sum(e["reason"] == "error" for e in flat),
                    "certified": sum(e["method"] == "certified" for e in flat),
                    "certified_safe": sum(e["verdict"] == 1 and e["method"] == "certified" for e in flat)}


def _series(d: dict, m: int, per_time: tuple[str, ...] = (), per_channel: tuple[str, ...] = (),
            named: tuple[str, ...] = ()) -> None:
    """Keep every k-th sample of lists indexed by time, by channel then time, or by name then time."""
    idx = _every(len(d["t"]), m)

    def pick(v):
        return [v[i] for i in idx]

    for k in per_time:
        if k in d:
            d[k] = pick(d[k])
    for k in per_channel:
        if k in d:
            d[k] = [pick(c) for c in d[k]]
    for k in named:
        d[k] = {n: pick(c) for n, c in d[k].items()}
    d["t"] = pick(d["t"])


def shrink(report: dict) -> dict:
    r = json.loads(json.dumps(report))
    for tr in r["transitions"]:
        _grid(tr)
    for f in r["failures"]:
        if "t" in f["series"]:
            _series(f["series"], MAX_POINTS // 2, ("roa_margin", "h_least"), ("u", "x"), ("h",))
    for run in (r["sequence"] or {}).get("runs", {}).values():
        active = [name for name, k in run["active"] for _ in range(k)]
        run["active"] = active
        _series(run, MAX_POINTS, ("min_h", "active"), ("x",))
        out = []
        for name in run["active"]:
            if out and out[-1][0] == name:
                out[-1][1] += 1
            else:
                out.append([name, 1])
        run["active"] = out
        run["violations"] = run["violations"][:MAX_VIOLATIONS]
    r["project"]["path"] = "specs/pendulum/project.yaml"
    return _round(r)


def main() -> None:
    res = api.run_project(api.discover(ROOT / "specs/pendulum")[0], None)
    small = shrink(res.report)
    validate_report(small)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(small, separators=(",", ":"), allow_nan=False) + "\n", encoding="utf-8")
    print(OUT, OUT.stat().st_size, "bytes")


if __name__ == "__main__":
    main()
