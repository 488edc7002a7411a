"""The landing under model error: the A1's Jump -> Land at the corners of the project's uncertainty box, for
the project's Land (a stiff CoM law, `controller: {type: land}`) and, as the baseline in the same run, the
paper's joint PD about a crouch that Land ran before (kp 20, kd 3, the crouch's torques on the feet in
contact, a 26.8 N m bound; its own gait table, written by `mpgspec gait` in a copy).

    python bench/bench_land_law.py [--project specs/a1/project.yaml] [--no-write]

From Jump's x*(T_f) each law lands at the 8 corners of mass, friction and torque scale, without a push and
with the project's push held at -bound on every axis over its duration (in the air and after the
touchdown): the least friction-cone margin (N, at the corner's mu) and the RoA margin r - ||x - x*||_W at the
end of Land's domain (positive: inside E_Land), the least over the corners, and how many runs stay in
C_Land. Then the nominal landing's peak input (N m) and least friction margin at the nominal mu. Counts and
margins, not timings (empirical: rollouts).

Prints a table and replaces (or appends) the section "A1 Land: the landing under model error" of
bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import itertools
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import publish_rows, with_controller  # noqa: E402

PAPER_PD = """controller:
  type: pd
  outputs: [FL_hip_joint, FL_thigh_joint, FL_calf_joint, FR_hip_joint, FR_thigh_joint, FR_calf_joint,
            RL_hip_joint, RL_thigh_joint, RL_calf_joint, RR_hip_joint, RR_thigh_joint, RR_calf_joint]
  kp: [20, 20, 20, 20, 20, 20, 20, 20, 20, 20, 20, 20]
  kd: [3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3]
  target: [0, 0.92, -2.04, 0, 0.92, -2.04, 0, 1.08, -1.96, 0, 1.08, -1.96]
  gravity_compensation: true
  limit: 26.8
"""
"""Land's earlier law, the paper's: a damped joint PD about a crouch."""


def paper_copy(project: Path, dst: Path) -> Path:
    """A copy of the project whose Land runs PAPER_PD, with the gait tables written for it."""
    shutil.copytree(project.parent, dst)
    land = dst / "primitives" / "land.yaml"
    land.write_text(with_controller(land.read_text(), PAPER_PD))
    subprocess.run([sys.executable, "-m", "mpgspec", "gait", str(dst / "gaits.yaml")], check=True,
                   stdout=subprocess.DEVNULL)
    return dst / project.name


def landing(project: Path, label: str) -> list[tuple[str, str]]:
    """Rows: Jump -> Land at the box's corners, unpushed and pushed, and the nominal landing's peak and cone."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.oracle.trace import trace
    from mpgspec.robust.rigid import RigidRobustRollout
    from mpgspec.spec.loader import load_project

    spec = load_project(project)
    prims, settings = compile_project(spec), settings_for(spec)
    land, jump = prims["Land"], prims["Jump"]
    unc = spec.project.uncertainty
    names = list(unc.parameters)
    corners = np.array(list(itertools.product(*[unc.parameters[n].range for n in names])), float)
    n = len(corners)
    span = float(land.domain[1] - land.domain[0])
    dist = unc.disturbance
    bound = np.asarray(dist.force.bound, float)
    segments = int(dist.segments)
    rr = RigidRobustRollout(land, names, dist.force.frame, True, segments, settings, span,
                            float(dist.force.duration), False, 0)
    cone = [i for i, h in enumerate(land.h_names) if h.startswith("friction_cone")]
    x0 = np.tile(jump.x_star(jump.domain[1]), (n, 1))
    rows = []
    for how, sign in (("no push", 0.0), ("push -bound", -1.0)):
        D = np.repeat((sign * bound)[None, :, None], n, axis=0) * np.ones((n, len(bound), segments))
        Y, last = rr.run(x0, np.zeros(n), corners, D, tol=settings.h_tolerance, until_entry=False)
        ends = np.minimum(last, rr.N)
        full = last >= rr.N
        final = np.array([Y[k, -1, ends[k]] if full[k] else np.nan for k in range(n)])
        fc = min(float(np.nanmin(Y[k, cone, :ends[k] + 1])) for k in range(n))
        k = int(np.nanargmin(final)) if full.any() else 0
        rows.append((f"{label}: Jump -> Land at the {n} corners, {how}: RoA margin at {span:g} s (least; worst corner) "
                     "/ least friction margin / runs in C",
                     f"{np.nanmin(final) if full.any() else float('nan'):+.4f} "
                     f"({dict(zip(names, map(float, corners[k])))}) / {fc:.2f} N / {int(full.sum())} of {n}"))
    end = jump.x_star(jump.domain[1])
    tr = trace(land, end, 0.0, span, settings, max_points=100_000)
    U = np.array([[np.nan if v is None else v for v in row] for row in tr["u"]], float)
    cones = min(np.nanmin(np.array([np.nan if v is None else v for v in vals], float))
                for h, vals in tr["h"].items() if h.startswith("friction_cone"))
    rows.append((f"{label}: the nominal landing's peak input / least friction margin (mu 0.6)",
                 f"{np.nanmax(np.abs(U)):.1f} N m / {cones:.2f} N"))
    print("\n".join(f"{a}: {b}" for a, b in rows), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1" / "project.yaml"))
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    project = Path(a.project).resolve()
    rows = landing(project, "Land (the project's)")
    with tempfile.TemporaryDirectory() as tmp:
        rows += landing(paper_copy(project, Path(tmp) / "a1"), "Land (the paper's joint PD)")
    publish_rows("## A1 Land: the landing under model error", "bench_land_law.py", 1, t0, rows, not a.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
