"""Benchmark of the Definition 1 check roa_in_safe_set on the contact manifold: the single-point loop
it replaced against the batched evaluation, in one process.

    python bench/bench_assumptions.py                 # Lie, Stand and Walk(slow) of the A1, 3 rounds
    python bench/bench_assumptions.py --quick         # Lie only, 1 round
    options: --primitives NAME,NAME  --repeats R  --project specs/anymal  --points N

Measured, in interleaved rounds (bench/common.py; a ratio is the median of per-round ratios):

  projection   N points of E (radii up to 2 r_E, so some need many Gauss-Newton steps) projected
               onto the primitive's contact manifold: one project_to_contacts call per point as the
               check made them (a private copy of that code, below) against project_to_contacts_many;
  roa check    roa_in_safe_set(p, 1e-9): the check as it was (a private copy of its single-point
               loop: every sample projected twice, h and each forward-difference Jacobian one point at
               a time) against the check today.

Both pairs must agree bit for bit; the script says so (exit code 1 otherwise). Compiling the project
is not measured (the compile cache, MPGSPEC_CACHE, serves it after the first run).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from common import machine, med_ratio, rounds  # noqa: E402  (bench/common.py)

from mpgspec.api import compile_project  # noqa: E402
from mpgspec.check import assumptions as A  # noqa: E402
from mpgspec.check.evaluate import S_SETTLED, clock, numeric_fn  # noqa: E402
from mpgspec.compile.numeric import numeric  # noqa: E402
from mpgspec.compile.primitive import INACTIVE  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402


def _single(sys_) -> dict:
    """The Functions one Gauss-Newton step of the single-point projection evaluated, on numpy arrays."""
    if not hasattr(sys_, "_bench_single"):
        sys_._bench_single = {"kinematics": numeric(sys_._manifold_kinematics), "normalize": numeric(sys_.dyn.normalize),
                              "integrate": numeric(sys_.dyn.integrate)}
    return sys_._bench_single


def _inverse_metric(block):
    return np.linalg.inv(block + 1e-3 * max(1e-12, float(np.abs(block).max())) * np.eye(block.shape[0]))


def project_one(sys_, x, contacts, W, tol=1e-12, max_iter=50):
    """project_to_contacts as it was: one point, numpy linear algebra per Gauss-Newton step."""
    N, m = _single(sys_), sys_.model
    nq, nv, nc = m.nq, m.nv, len(m.contact_frames)

    def kin(q):
        out = N["kinematics"](q)[0]
        return out[:nc], out[nc:nc + 3 * nc * nv].reshape((nv, 3 * nc)).T, out[nc + 3 * nc * nv:].reshape((nv, nq)).T

    x = np.array(x, float).ravel()
    rows = [m.contact_frames.index(f) for f in contacts]
    q, Wq = N["normalize"](x[:nq])[0], W[:nq, :nq]
    for _ in range(max_iter):
        z, J, G = kin(q)
        r = z[rows]
        if not rows or np.abs(r).max() <= tol:
            break
        Ah = J[[3 * i + 2 for i in rows]]
        Minv = _inverse_metric(G.T @ Wq @ G)
        dv = -Minv @ Ah.T @ np.linalg.lstsq(Ah @ Minv @ Ah.T, r, rcond=None)[0]
        q = N["integrate"](q, dv, 1.0)[0]
    v = x[nq:nq + nv]
    if rows:
        J = kin(q)[1][[3 * i + k for i in rows for k in range(3)]]
        Minv = _inverse_metric(W[nq:nq + nv, nq:nq + nv])
        v = v - Minv @ J.T @ np.linalg.lstsq(J @ Minv @ J.T, J @ v, rcond=None)[0]
    out = np.concatenate([q, v, x[nq + nv:]])
    if sys_.events:
        for f in m.contact_frames:
            out[sys_.state_names.index(f"contact_{f}")] = float(f in contacts)
    return out


def _h(p, x, t):
    v = numeric_fn(p, "h")(x, t, S_SETTLED, x)[0]
    return v[np.abs(v) < INACTIVE / 2]


def _search(p, xs, t, L, r, W, feet, scale, state, samples, rng, starts=3, steps=8):
    """One clock time of the single-point check: samples, then the local search from `starts`."""
    k = L.shape[1]

    def project(x):
        return project_one(p.system, x, feet, W)

    def hv(z):
        h = _h(p, project(xs + L @ z), t)
        state["worst"] = min(state["worst"], float(h.min()))
        return h

    def rel(z):
        return float((hv(z) / scale).min())

    def jac(z):
        e = max(1e-7, 1e-4 * r)
        h0 = hv(z)
        return h0, np.stack([(hv(z + e * c) - h0) / e for c in np.eye(k)], axis=1)

    def to_boundary(g):
        n = np.linalg.norm(g)
        return -r * g / n if n > 0 else None

    def wnorm(dx):
        return float(np.sqrt(max(dx @ W @ dx, 0.0)))

    d = rng.normal(size=(2 * samples, k))
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    d *= r * np.r_[np.ones(samples), rng.uniform(size=samples)][:, None]
    cands = []
    for z in d:
        x0 = xs + L @ z
        x = project(x0)
        state["dist"].append(wnorm(x - x0))
        state["spread"].append(wnorm(x - xs))
        state["raw"] = min(state["raw"], float(_h(p, x0, t).min()))
        cands.append((rel(z), z))
    if r > 0:
        for g in jac(np.zeros(k))[1]:
            z = to_boundary(g)
            if z is not None:
                cands.append((rel(z), z))
    cands.sort(key=lambda c: c[0])
    for m, z in cands[:starts]:
        for _ in range(steps):
            h0, G = jac(z)
            z_new = to_boundary(G[int(np.argmin(h0 / scale))])
            if z_new is None:
                break
            m_new = rel(z_new)
            if m_new >= m - 1e-12:
                break
            z, m = z_new, m_new


def roa_single(p, tol=1e-9, samples=400, seed=0):
    """roa_in_safe_set on the contact manifold as it was, point by point."""
    rng = np.random.default_rng(seed)
    W = np.asarray(p.W)
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])
    r = p.radius * (1 - 1e-9)
    project = A._contact_projection(p, W)
    state = {"worst": np.inf, "raw": np.inf, "dist": [], "spread": []}
    feet = set()
    for t in clock(p, 8):
        xs = p.x_star(t)
        scale = np.maximum(_h(p, xs, t), 1e-9)
        if not scale.size:
            continue
        mode = project(xs, xs, t)[1]
        feet.update(mode)
        _search(p, xs, t, L, r, W, mode, scale, state, samples, rng)
    return A._manifold_check(p, tol, samples, r, state["worst"], state["raw"], state["dist"], state["spread"], feet)


def _points(p, n, seed=0):
    W = np.asarray(p.W, float)
    w, V = np.linalg.eigh(W)
    keep = w > 1e-12
    L = V[:, keep] / np.sqrt(w[keep])
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, L.shape[1]))
    d *= 2 * max(p.radius, 0.05) * rng.uniform(size=(n, 1)) / np.linalg.norm(d, axis=1, keepdims=True)
    return W, p.x_star(0.0) + d @ L.T


def bench_primitive(p, repeats: int, n: int) -> tuple[list[str], bool]:
    sys_ = p.system
    W, X = _points(p, n)
    feet = A._contact_projection(p, W)(X[0], p.x_star(0.0), 0.0)[1]
    res = {}
    proj = rounds({"one": lambda: res.__setitem__("one", np.array([project_one(sys_, x, feet, W) for x in X])),
                   "many": lambda: res.__setitem__("many", sys_.project_to_contacts_many(X, feet, W))}, repeats)
    same_proj = np.array_equal(res["one"], res["many"], equal_nan=True)
    chk = rounds({"one": lambda: res.__setitem__("c_one", roa_single(p)),
                  "many": lambda: res.__setitem__("c_many", A.roa_in_safe_set(p, 1e-9))}, repeats)
    same_chk = res["c_one"].to_dict() == res["c_many"].to_dict()
    med = {k: float(np.median(v)) for k, v in chk.items()}
    lines = [f"{p.name:14s} projection {n} points: {np.median(proj['one']):.3f} s -> {np.median(proj['many']):.3f} s, "
             f"x{med_ratio(proj['one'], proj['many']):.1f} ({'identical' if same_proj else 'DIFFERENT'})",
             f"{'':14s} roa_in_safe_set: {med['one']:.2f} s -> {med['many']:.2f} s, x{med_ratio(chk['one'], chk['many']):.1f}"
             f" ({'identical' if same_chk else 'DIFFERENT'}; {res['c_many'].status}, min_h "
             f"{res['c_many'].numbers['min_h']})"]
    return lines, same_proj and same_chk


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--project", default=str(ROOT / "specs" / "a1"))
    ap.add_argument("--primitives", default="Lie,Stand,Walk(slow)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--points", type=int, default=400)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    names, repeats = (["Lie"], 1) if a.quick else (a.primitives.split(","), a.repeats)
    t0 = time.perf_counter()
    prims = compile_project(load_project(Path(a.project) / "project.yaml"))
    print(f"compiled {Path(a.project).name} in {time.perf_counter() - t0:.1f} s; {machine()}", flush=True)
    ok = True
    for name in names:
        lines, same = bench_primitive(prims[name], repeats, a.points)
        ok &= same
        print("\n".join(lines), flush=True)
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    print(f"medians of {repeats} interleaved rounds; load average {load}; {time.perf_counter() - t0:.0f} s wall")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
