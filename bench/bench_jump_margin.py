"""Jump's joint-limit margin over the A1's uncertainty box: the least q_max margin of the calves (and
the least of every joint-limit function) in Jump's own flow from its x*(0), the stance, at every
corner of mass_scale x torque_scale (friction at its nominal 0.6, no push), on the robust stage's
perturbed plant (mpgspec.robust.rigid.RigidRobustRollout: the oracle's steps, the controllers keep
the URDF's model). A margin in radians, not a timing: the bar of the A1's Jump is 0.1 rad over the
mass range.

    python bench/bench_jump_margin.py [--no-write]

Prints a table and replaces (or appends) the section "A1 Jump: joint-limit margin" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import machine, markdown_table, revision, write_section  # noqa: E402

HEADING = "## A1 Jump: joint-limit margin"
MASS = (0.9, 1.0, 1.1)
TORQUE = (0.9, 1.0, 1.1)


def margins(project: Path) -> list[tuple[float, float, str, float, float]]:
    """(mass_scale, torque_scale, least joint-limit function, its value, least calf q_max margin)."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.robust.rigid import RigidRobustRollout
    from mpgspec.spec.loader import load_project

    spec = load_project(project)
    prims, settings = compile_project(spec), settings_for(spec)
    jump = prims["Jump"]
    span = float(jump.domain[1] - jump.domain[0])
    rr = RigidRobustRollout(jump, ["mass_scale", "friction", "torque_scale"], "trunk", False, 1, settings, span,
                            None, gradient=False)
    x0 = np.asarray(jump.x_star(jump.domain[0]), float).ravel()
    TH = np.array([[m, float(jump.system.friction), k] for m in MASS for k in TORQUE])
    n = len(TH)
    Y, _ = rr.run(np.tile(x0, (n, 1)), np.full(n, jump.domain[0]), TH, np.zeros((n, 0, rr.K)),
                  np.full(n, rr.N), tol=1e9, until_entry=False)
    names = jump.h_names
    limits = [i for i, h in enumerate(names) if h.startswith(("q_min[", "q_max[", "qdot_max["))]
    calves = [i for i, h in enumerate(names) if h.startswith("q_max[") and h.endswith("_calf_joint]")]
    out = []
    for j in range(n):
        lim = Y[j][limits]
        i = np.unravel_index(np.nanargmin(lim), lim.shape)[0]
        out.append((TH[j, 0], TH[j, 2], names[limits[i]], float(np.nanmin(lim)), float(np.nanmin(Y[j][calves]))))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1" / "project.yaml"))
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    import casadi

    t0 = time.perf_counter()
    rows = margins(Path(a.project))
    worst_mass = min(r[4] for r in rows if r[1] == 1.0)
    worst = min(r[4] for r in rows)
    table = [(f"mass {m:g}, torque {k:g}: least calf q_max margin (least joint limit: {h} {v:.4f})", f"{c:.4f} rad")
             for m, k, h, v, c in rows]
    table += [("**least over the mass range, nominal torque (bar: >= 0.1 rad)**", f"**{worst_mass:.4f} rad**"),
              ("least over the mass x torque box", f"{worst:.4f} rad")]
    text = markdown_table(table)
    print(text)
    mach = machine(casadi=casadi.__version__)
    mach["revision"] = revision(ROOT)
    import datetime

    when = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    head = (f"{when}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), Python {mach['python']}, CasADi "
            f"{mach['casadi']}; `python bench/bench_jump_margin.py` ({time.perf_counter() - t0:.0f} s wall). Jump's own "
            "flow from x*(0) on the robust stage's perturbed plant, friction 0.6, no push, dt 1 ms; h of its C_Jump.")
    if not a.no_write:
        write_section(ROOT / "bench" / "RESULTS.md", HEADING, f"{HEADING}\n\n{head}\n\n{text}\n")
    return 0 if worst_mass >= 0.1 else 1


if __name__ == "__main__":
    sys.exit(main())
