"""The A1 trot's height law under model error: how close each walk's own flow settles to x*(t) at the corners of
the project's uncertainty box, for the project's law and, as the baseline in the same run, the earlier one (the
trot's default height law, kz 100 1/s^2, dz 20 1/s, no limit; its gait tables regenerated in a copy).

    python bench/bench_trot_height.py [--project specs/a1/project.yaml] [--walks Walk(in_place),Walk(fast)] [--no-write]

Each walk's own flow from x*(0), switched in at t = 0, on the perturbed plant at the 8 corners of mass, friction
and torque scale (no push) over the oracle's horizon, as the robust stage runs it: the best RoA margin
r(t) - ||x - x*(t)||_W after the first second (positive: the flow is inside E there; an edge into the walk needs
every scenario to enter E), the least over the corners and the worst corner, and how many runs stay in C.
Mass and torque scale act through their ratio (all eight corners are the nominal plant's or 1.1 / 0.9 or 0.9 /
1.1). Margins, not timings (simulated: rollouts on the compiled robust step).

Prints a table and replaces (or appends) the section "A1 walks: height law under model error" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import itertools
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import publish_rows  # noqa: E402

HEIGHT_KEYS = ("kz", "dz", "height_accel_limit")
"""The walks' height-law keys the earlier copy drops (the trot's defaults: kz 100, dz 20, no limit)."""


def earlier_copy(project: Path, dst: Path) -> Path:
    """A copy of the project whose walks run the trot's default height law, with its gait tables regenerated."""
    shutil.copytree(project.parent, dst)
    walk = dst / "primitives" / "walk.yaml"
    text = walk.read_text()
    for key in HEIGHT_KEYS:
        text = re.sub(rf"\n  {key}: *[^\n]*", "", text)
    walk.write_text(text)
    subprocess.run([sys.executable, "-m", "mpgspec", "gait", str(dst / "gaits.yaml")], check=True,
                   stdout=subprocess.DEVNULL)
    return dst / project.name


def settle(project: Path, label: str, walks: list[str]) -> list[tuple[str, str]]:
    """Rows: per walk, the best RoA margin after 1 s at the box's corners (least; worst corner), runs in C."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.robust.rigid import RigidRobustRollout
    from mpgspec.spec.loader import load_project

    spec = load_project(project)
    prims, settings = compile_project(spec), settings_for(spec)
    unc = spec.project.uncertainty
    names = list(unc.parameters)
    corners = list(itertools.product(*[unc.parameters[n].range for n in names]))
    n = len(corners)
    rows = []
    for name in walks:
        p = prims[name]
        rr = RigidRobustRollout(p, names, "trunk", False, 1, settings, settings.horizon, None, False, 0)
        Y, last = rr.run(np.tile(p.x_star(0.0), (n, 1)), np.zeros(n), np.array(corners, float),
                         np.zeros((n, 0, 1)), tol=settings.h_tolerance, until_entry=False)
        k0 = int(round(1.0 / settings.dt))
        best = np.array([np.nanmax(Y[i, -1, k0:int(last[i]) + 1]) if last[i] >= k0 else np.nan for i in range(n)])
        full = last == rr.N
        k = int(np.nanargmin(best)) if np.isfinite(best).any() else 0
        rows.append((f"{label}: {name}'s own flow at the {n} corners of {', '.join(names)}, best RoA margin after "
                     f"1 s (least; worst corner)",
                     f"{np.nanmin(best):+.4f} ({dict(zip(names, corners[k]))}); {int(full.sum())} of {n} stay in C "
                     f"for {settings.horizon:g} s"))
        print(f"{rows[-1][0]}: {rows[-1][1]}", flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1" / "project.yaml"))
    ap.add_argument("--walks", default="Walk(in_place),Walk(slow),Walk(medium),Walk(fast)")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    project = Path(a.project).resolve()
    walks = a.walks.split(",")
    rows = settle(project, "the project's height law", walks)
    with tempfile.TemporaryDirectory() as tmp:
        rows += settle(earlier_copy(project, Path(tmp) / "a1"), "kz 100, dz 20 (earlier)", walks)
    publish_rows("## A1 walks: height law under model error", "bench_trot_height.py", 1, t0, rows, not a.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
