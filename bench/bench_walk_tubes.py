"""Whether a walk's E holds where its tube is thinnest: seeded starts on and inside E's sphere (half on the sphere,
half inside, put on the contact manifold of the feet held at their phase; a start outside C is left out, as
the floquet verifier leaves it out) at phases in the last 20 ms before
each scheduled touchdown and, for comparison, in the first 100 ms of each swing; each start runs the walk's own discrete
flow (the period map the sizing runs) for three periods. A start fails when its least h falls below the
oracle's tolerance. A count of states, not a timing: E is a safe region of attraction only if none fails.

    python bench/bench_walk_tubes.py [--starts N] [--radii sized 0.006 ...] [--after-entry REPORT] [--no-write]

With --after-entry (a report.json of the project, e.g. reports/a1/report.json), also every safe cell of an
edge into a walk: the walk's flow from the cell's start (x_A*(t_A) switched in at t_B) continued for three
periods past the oracle's entry into E (its t_stop); a cell fails when that continuation leaves C.

Prints a table and replaces (or appends) the section "A1 walks: E before a touchdown" of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import publish_rows  # noqa: E402

HEADING = "## A1 walks: E before a touchdown"
WINDOWS = ((0.16, 0.18), (0.34, 0.36), (0.02, 0.12), (0.20, 0.30))
"""Phase windows (s) of the trot (period 0.36 s; swings 0.02-0.18 and 0.20-0.36 s): the last 20 ms of each
swing, then the first 100 ms of each."""
PERIODS = 3
SEED = 1


def count(project: Path, m: int, radii: list[float | None]) -> list[tuple[str, str]]:
    """Table rows: per walk, radius (None: the sized one) and window, starts in C and those that leave it
    within PERIODS periods."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.certify.hybrid_orbit import HybridFlow, orbit
    from mpgspec.certify.roa import _estimate, _options
    from mpgspec.spec.loader import load_project

    spec = load_project(project)
    prims, tol = compile_project(spec), settings_for(spec).h_tolerance
    rows = []
    for inst in [i for i in spec.primitives if i.name.startswith("Walk(")]:
        name, p = inst.name, prims[inst.name]
        flow, W = HybridFlow(p, 0.001), np.asarray(p.W)
        Xs = orbit(flow, W)[0]
        # the radius `mpgspec verify` sizes (its floquet verifier, as certify/roa.py calls it)
        sized = float(_estimate(inst.spec.roa.method, p, _options(inst, tol)).radius)
        for r in [sized if radius is None else radius for radius in radii]:
            rows += _windows(p, flow, Xs, W, r, m, tol, f"{name}, r = {r:.4g}{' (sized)' if r == sized else ''}")
            print(f"{name} r = {r:.4g}:", "; ".join(v for _k, v in rows[-len(WINDOWS):]), flush=True)
    return rows


def _windows(p, flow, Xs, W, r: float, m: int, tol: float, label: str) -> list[tuple[str, str]]:
    """Rows of one walk and radius: m starts per window (the same seed for every radius)."""
    from verifiers.floquet_hybrid import inverse_root, sphere_starts

    rows = []
    rng = np.random.default_rng(SEED)
    Wi = inverse_root(W)
    for lo, hi in WINDOWS:
        X0, k = sphere_starts(p, flow.dt, Xs, W, Wi, r, m, rng, (int(round(lo / flow.dt)), int(round(hi / flow.dt))))
        t0 = k * flow.dt
        inside = flow.least_h(X0, t0) >= -tol
        X0, t0 = X0[:, inside], t0[inside]
        XT, hmin, _ran = flow.run_until(X0, t0, PERIODS)
        bad = ~(hmin >= -tol) | ~np.isfinite(XT).all(axis=0)  # a blow-up fails too
        how = ""
        if bad.any():
            names = sorted({_first_violated(p, X0[:, j], float(t0[j]), flow.dt, tol) for j in np.flatnonzero(bad)})
            how = f", least h {float(np.nanmin(hmin)):.2g} ({', '.join(names)})"
        rows.append((f"{label}, phases {lo:.2f}-{hi:.2f} s", f"{int(bad.sum())} of {int(inside.sum())} leave C{how}"))
    return rows


def _first_violated(p, x0: np.ndarray, t0: float, dt: float, tol: float) -> str:
    """The safety function a settled start breaks first, stepped as the period map steps it."""
    import casadi as ca

    from mpgspec.certify.hybrid_orbit import _parts
    from mpgspec.oracle.flow import LEFT, rk4_jump

    f, _k, jump, _h, start = _parts(p, np.array(p.setpoint(0.0), float).ravel())  # HybridFlow's settled loop
    x, t = ca.DM(x0), t0
    for _ in range(int(round(PERIODS * float(p.period) / dt)) + 1):
        k1, u, hv = start(x, t)
        hv = np.array(hv, float).ravel()
        if not (hv >= -tol).all():
            return p.h_names[int(np.argmin(np.nan_to_num(hv, nan=-np.inf)))]
        x = rk4_jump(f, None, jump, x, t, dt, LEFT, start=(k1, u))
        t += dt
    return "non-finite"


def after_entry(project: Path, report_path: Path) -> tuple[str, str]:
    """(row label, value): the safe cells into walks whose flow leaves C within PERIODS periods after
    entering E, of all such cells (the oracle judged the flow up to the entry). Steps of dt throughout, as
    the oracle takes them for the A1 (accuracy `low`: no refinement, no shortened steps in a walk)."""
    import json

    import casadi as ca

    from mpgspec.api import compile_project
    from mpgspec.oracle import looplib
    from mpgspec.oracle.flow import LEFT, rk4_jump
    from mpgspec.spec.loader import load_project

    report = json.loads(report_path.read_text())
    prims = compile_project(load_project(project))
    dt = float(report["settings"]["dt"])
    cells, bad = 0, []
    for tr in report["transitions"]:
        pa, pb = prims[tr["from"]], prims[tr["to"]]
        if not tr["to"].startswith("Walk("):
            continue
        lib = looplib.attach(pb)
        loop, jump = lib.get("loop"), lib.get("jump")
        for i, t_a in enumerate(tr["t_A"]):
            for j, t_b in enumerate(tr["t_B"]):
                if tr["verdicts"][i][j] != 1:
                    continue
                cells += 1
                x0 = np.asarray(pa.x_star(t_a), float).ravel()
                x, t, s = ca.DM(x0), float(t_b), 0.0
                entry = int(round(tr["cells"]["t_stop"][i][j] / dt))
                least = np.inf
                for k in range(entry + int(round(PERIODS * float(pb.period) / dt)) + 1):
                    o = loop(x, t, s, x0)
                    if k >= entry:
                        hv = np.array(looplib.windowed(pb, o[1], x, t, s), float)
                        least = min(least, float(np.min(hv)) if np.isfinite(hv).all() else -np.inf)
                    x = rk4_jump(lambda xx, tt, t=t, s=s: loop(xx, tt, s + (tt - t), x0)[0], None, jump, x, t, dt,
                                 LEFT, s=s, start=(o[0], o[3]))
                    t, s = t + dt, s + dt
                if least < 0:
                    bad.append(f"{tr['from']} -> {tr['to']} at t_A {t_a:.2f}, t_B {t_b:.2f}: h {least:.2g}")
    print("\n".join(bad))
    return (f"safe cells into walks, the flow continued {PERIODS} periods past its entry into E",
            f"{len(bad)} of {cells} leave C" + (f" (e.g. {bad[0]})" if bad else ""))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1" / "project.yaml"))
    ap.add_argument("--starts", type=int, default=200, help="starts per walk and window")
    ap.add_argument("--radii", nargs="+", default=["sized", "0.006"],
                    help="radii to check, 'sized' for each walk's sized one (default: sized 0.006)")
    ap.add_argument("--after-entry", metavar="REPORT", help="also continue the safe cells of this report.json")
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    radii = [None if v == "sized" else float(v) for v in a.radii]
    rows = count(Path(a.project), a.starts, radii)
    if a.after_entry:
        rows.append(after_entry(Path(a.project), Path(a.after_entry)))
    publish_rows(HEADING, "bench_walk_tubes.py", 1, t0, rows, not a.no_write)
    return 0 if all(v.startswith("0 of") for k, v in rows if "(sized)" in k or "past its entry" in k) else 1


if __name__ == "__main__":
    sys.exit(main())
