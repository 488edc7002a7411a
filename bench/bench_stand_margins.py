"""The rests' margins by design: how far the A1's Stand (or Lie) keeps from C's boundary on E and how close
to x* it settles under model error, for the project's law and, as the baseline in the same run, the earlier
one: Stand's earlier ID-QP (CoM gains 100 / 20 on every axis, a posture task at 50 / 5 pulling at the
setpoint's joints from the switch, contact forces designed for the plant's mu, no least normal force), or
for Lie the paper's joint PD (kp 60, kd 3, gravity compensation, the cubic profile; E of radius 0.023).

    python bench/bench_stand_margins.py [--primitive Stand|Lie] [--project specs/a1/project.yaml] [--no-write]

E inside C: 400 seeded points on E's boundary and 400 inside, on the contact manifold (as the
roa_in_safe_set check draws them), then that check's descent from the three points nearest to leaving C
(not its extra starts along the gradient at x*), and the least friction-cone margin (N, at the plant's mu)
and normal force (N) found. Model error: Lie -> Stand from x*_Lie (Stand -> Lie from x*_Stand) at the 8
corners of the project's uncertainty box (mass, friction and torque scale; no push), the target's own flow
over the oracle's horizon on the perturbed plant; the RoA margin r - ||x - x*||_W at the horizon (positive: inside E), the least over
the corners, and how many runs stay in C. Counts and margins, not timings (empirical: sampled points and
rollouts).

Prints a table and replaces (or appends) the section "A1 Stand: margins under model error" (or "A1 Lie: ...")
of bench/RESULTS.md.
"""
from __future__ import annotations

import argparse
import itertools
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from common import pd_lie, publish_rows  # noqa: E402

EARLIER = {"kp": "[100, 100, 100]", "kd": "[20, 20, 20]", "posture_kp": "50", "posture_kd": "5",
           "posture_profile": "false", "friction": None, "f_min": None, "ki": None, "ki_limit": None}
"""Stand's earlier law: these keys of its controller replaced (None: removed, the default)."""
SOURCE = {"Stand": "Lie", "Lie": "Stand"}
"""The primitive each target is switched in from (its setpoint at t = 0)."""


def earlier_copy(project: Path, dst: Path, target: str) -> Path:
    """A copy of the project whose `target` runs its earlier law (Stand: EARLIER; Lie: the paper's joint PD)."""
    shutil.copytree(project.parent, dst)
    if target == "Lie":
        pd_lie(dst)
        return dst / project.name
    stand = dst / "primitives" / "stand.yaml"
    text = stand.read_text()
    for key, value in EARLIER.items():
        pattern = rf"\n  {key}: *[^\n]*"
        text = re.sub(pattern, "" if value is None else f"\n  {key}: {value}", text)
    stand.write_text(text)
    return dst / project.name


def _recording():
    """roa_manifold._Search that keeps every h it evaluates in the local search (`seen`)."""
    from mpgspec.check import roa_manifold

    class Recording(roa_manifold._Search):
        def hv(self, Z):
            H = super().hv(Z)
            self.__dict__.setdefault("seen", []).append(np.asarray(H))
            return H

    return Recording


def margins(project: Path, label: str, target: str = "Stand") -> list[tuple[str, str]]:
    """Rows: E_target's least friction and normal-force margins, and SOURCE -> target at the box's corners."""
    from mpgspec.api import compile_project, settings_for
    from mpgspec.check import roa_manifold
    from mpgspec.check.assumptions import _contact_projection
    from mpgspec.robust.rigid import RigidRobustRollout
    from mpgspec.spec.loader import load_project

    _Recording = _recording()
    spec = load_project(project)
    prims, settings = compile_project(spec), settings_for(spec)
    stand, lie = prims[target], prims[SOURCE[target]]
    W = np.asarray(stand.W)
    w, V = np.linalg.eigh(W)
    L = V[:, w > 1e-12] / np.sqrt(w[w > 1e-12])
    r, xs = stand.radius * (1 - 1e-9), stand.x_star(0.0)
    search = _Recording(stand, _contact_projection(stand, W), L, r, xs, 0.0,
                        np.maximum(roa_manifold.h_active(stand, xs, 0.0), 1e-9), np.inf, set())
    rng = np.random.default_rng(0)
    d = rng.normal(size=(800, L.shape[1]))
    d *= r * np.r_[np.ones(400), rng.uniform(size=400)][:, None] / np.linalg.norm(d, axis=1, keepdims=True)
    H = np.asarray(search.h_projected(d)[2])
    names = list(stand.h_names)  # Stand's are all active: feet held throughout
    assert len(names) == H.shape[1]
    cands = sorted(zip(search.rel(H), d, H), key=lambda c: c[0])
    search.descend(cands[:3], 8)  # the check's descent, from the three points nearest to leaving C
    rows = []
    for how, Hall in (("800 points", H), ("and a local search", np.vstack([H] + getattr(search, "seen", [])))):
        least = {kind: float(min(Hall[:, i].min() for i, n in enumerate(names) if n.startswith(kind)))
                 for kind in ("friction_cone", "normal_force")}
        rows.append((f"{label}: E_{target} (r = {stand.radius:g}) on the contact manifold, {how}: least friction "
                     "margin (mu 0.6) / normal force", f"{least['friction_cone']:.2f} N / {least['normal_force']:.1f} N"))

    unc = spec.project.uncertainty
    names_th = list(unc.parameters)
    rr = RigidRobustRollout(stand, names_th, "trunk", False, 1, settings, settings.horizon, None, False, 0)
    corners = list(itertools.product(*[unc.parameters[n].range for n in names_th]))
    n = len(corners)
    tol = settings.h_tolerance
    Y, last = rr.run(np.tile(lie.x_star(0.0), (n, 1)), np.zeros(n), np.array(corners, float),
                     np.zeros((n, 0, 1)), tol=tol, until_entry=False)
    full = last == rr.N  # ran to the horizon: stayed in C (a run stops where h < -tol)
    final = np.where(full, Y[np.arange(n), -1, np.minimum(last, rr.N)], np.nan)
    k = int(np.nanargmin(final)) if full.any() else 0
    rows.append((f"{label}: {SOURCE[target]} -> {target} at the {n} corners of {', '.join(names_th)}, RoA margin at "
                 f"{settings.horizon:g} s (least; worst corner)",
                 f"{np.nanmin(final) if full.any() else float('nan'):+.3f} ({dict(zip(names_th, corners[k]))}); "
                 f"{int(full.sum())} of {n} stay in C"))
    print("\n".join(f"{a}: {b}" for a, b in rows), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--primitive", default="Stand", choices=sorted(SOURCE))
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1" / "project.yaml"))
    ap.add_argument("--no-write", action="store_true")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    project = Path(a.project).resolve()
    target = a.primitive
    rows = margins(project, f"{target} (the project's)", target)
    with tempfile.TemporaryDirectory() as tmp:
        rows += margins(earlier_copy(project, Path(tmp) / "a1", target), f"{target} (earlier law)", target)
    script = "bench_stand_margins.py" + ("" if target == "Stand" else f" --primitive {target}")
    publish_rows(f"## A1 {target}: margins under model error", script, 1, t0, rows, not a.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
