"""The A1 walks: cost of a gait (orbit by Newton shooting) and of the oracle's steps of a walk, as
ratios to the oracle's steps of Lie under the paper's joint PD in the same process; and the oracle's summed local-error bound
along one stride, to set against the walk's tube radius.

    python bench/bench_gait.py
"""
from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import med_ratio, pd_lie, rounds  # noqa: E402
from mpgspec.api import compile_project, settings_for  # noqa: E402
from mpgspec.compile.rigidbody.system import feet_on_ground  # noqa: E402
from mpgspec.compile.system import compile_system  # noqa: E402
from mpgspec.robots.quadruped.gait.orbit import StrideMap, find_orbit  # noqa: E402
from mpgspec.oracle.integrator import build_chunk, initial_state  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402

A1 = Path(__file__).resolve().parents[1] / "specs" / "a1" / "project.yaml"


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        dst = Path(tmp) / "a1"
        shutil.copytree(A1.parent, dst)
        pd_lie(dst)  # the baseline: Lie under the paper's joint PD, a continuous law
        run(load_project(dst / "project.yaml"))


def run(spec) -> None:
    s = settings_for(spec)
    t = time.perf_counter()
    prims = compile_project(spec)
    print(f"compile the six primitives: {time.perf_counter() - t:.1f} s")
    sys_ = compile_system(spec)
    inst = next(i for i in spec.primitives if i.name == "Walk(slow)")
    ctrl = inst.spec.controller
    x = sys_.default_state()
    for j, a in ctrl.pose.items():
        x[sys_.state_names.index(j)] = a
    x = feet_on_ground(sys_, x)
    t = time.perf_counter()
    sm = StrideMap(sys_, ctrl, 0.001)
    print(f"stride map build and JIT (cached after the first run): {time.perf_counter() - t:.1f} s")
    chunks = {n: build_chunk(prims[n], s.dt, 64, True, s.jit_flags) for n in ("Lie", "Walk(slow)")}
    starts = {n: initial_state(prims[n], prims[n].x_star(0.0), 0.0)[:, None] for n in chunks}

    def horizon(n):  # 2.5 s of oracle steps from the setpoint: one rollout, every step judged
        z = starts[n]
        for _ in range(40):
            z = chunks[n].run(z)[0]

    times = rounds({"lie": lambda: horizon("Lie"), "walk": lambda: horizon("Walk(slow)"),
                    "orbit": lambda: find_orbit(sm, x, 0.2)}, 3)
    med = {k: float(np.median(v)) for k, v in times.items()}
    print(f"2.56 s of oracle steps, Lie (baseline): {med['lie'] * 1e3:.0f} ms")
    print(f"2.56 s of oracle steps, Walk(slow): {med['walk'] * 1e3:.0f} ms, {med_ratio(times['walk'], times['lie']):.2f}x Lie")
    print(f"orbit of Walk(slow) by Newton shooting: {med['orbit']:.2f} s, "
          f"{med_ratio(times['orbit'], times['lie']):.1f}x 2.56 s of Lie steps")
    p = prims["Walk(slow)"]
    for dt in (0.001, 0.0005):
        ch = build_chunk(p, dt, 64, True, s.jit_flags)
        z = initial_state(p, p.x_star(0.0), 0.0)
        e = []
        for _ in range(int(round(p.period / dt / 64)) + 1):
            zf, out = ch.run(z[:, None])
            e.append(out[ch.rows.err].ravel())
            z = zf[:, 0]
        e = np.concatenate(e)[: int(round(p.period / dt))]
        print(f"summed local-error bound over one stride at dt = {dt:g}: {e.sum():.3g} "
              f"(largest step {e.max():.3g}, median {np.median(e):.2g})")
    # step doubling: the judged rollout at dt/2 beside one at dt; its error estimate of E's margin
    # is the difference of the two margins (absolute, not summed), from Stand's setpoint into the walk
    ch2 = build_chunk(p, s.dt, 64, True, s.jit_flags, error="doubling")
    ch1 = build_chunk(p, s.dt, 64, True, s.jit_flags)
    x0 = prims["Stand"].x_star(0.0)
    z, e2, e1 = ch2.start(x0[None], [0.0]), [], []
    for _ in range(int(round(3 * p.period / s.dt / 64)) + 1):
        z, out = ch2.run(z)
        e2.append(out[ch2.rows.err][0])
    z = ch1.start(x0[None], [0.0])
    for _ in range(int(round(3 * p.period / s.dt / 64)) + 1):
        z, out = ch1.run(z)
        e1.append(out[ch1.rows.err][0])
    n = int(round(3 * p.period / s.dt))
    e2, e1 = np.concatenate(e2)[:n], np.concatenate(e1)[:n] * np.sqrt(np.max(np.linalg.eigvalsh(np.asarray(p.info["roa_W"]))))
    print(f"E-margin error estimate after three strides from Stand's setpoint, dt = {s.dt:g}: step doubling "
          f"{e2[-1]:.3g} (largest {e2.max():.3g}), summed local {e1.sum():.3g}")
    starts2 = {"Walk(slow)": ch2.start(p.x_star(0.0)[None], [0.0])}

    def horizon2():
        z = starts2["Walk(slow)"]
        for _ in range(40):
            z = ch2.run(z)[0]

    t2 = rounds({"local": lambda: horizon("Walk(slow)"), "doubling": horizon2}, 3)
    print(f"2.56 s of oracle steps, Walk(slow), step doubling vs local: {med_ratio(t2['doubling'], t2['local']):.2f}x")


if __name__ == "__main__":
    main()
