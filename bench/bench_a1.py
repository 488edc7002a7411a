"""Benchmark of the safety oracle (Definition 4) on the Unitree A1 (rigid body, paper Section IV).

    python bench/bench_a1.py            # about 70 s on 2 cores
    python bench/bench_a1.py --quick    # about 1 minute: 3 rounds, one ID-QP call
    options: --repeats R, --no-shipped (skip specs/a1's build and the ID-QP), --no-write

The target (issue): "The compiled A1 oracle (2 s horizon, 1 ms step, four feet in contact, joint
PD): within 1.5x of the compiled right-hand side's own cost times the number of evaluations, and
at least 8x faster than the same rollout with pinocchio called from Python in the same benchmark
run."

Everything runs in one process. A copy of specs/a1 goes to a temporary directory, with two extra
fixed primitives that hold the Stand pose with the Lie primitive's controller (joint PD on all 12
joints, the 1 s cubic motion profile of eq. 7, Kp 60, Kd 3):

  StandPD     plain joint PD (the issue's case)
  StandPD_gc  the same plus gravity compensation (system.static_torque, as lie.yaml uses)

and the project's oracle set to horizon 2.0, dt 0.001, accuracy low (refinements=0: an
inconclusive rollout is not re-run at dt/2). Their E radius is 1e-9 and the oracle runs with
h_tolerance 1e9, so a call never enters E and never leaves C: it rolls the closed loop over the
full 2 s, i.e. 2000 RK4 steps = 8000 right-hand-side evaluations of classical RK4, while still
computing, at every step as usual, every safety function at both ends of the step, their rates
along the flow, the embedded error estimate, the RoA margin and the input. The A1's closed loop
is too large to inline (integrator.INLINE_NODES), so a compiled step evaluates it 8 times: k1..k4
and k5 = f(x_next) at the step's end (the error estimate), plus 3 evaluations for forward
differences along the flow at both ends and h(x_next - e). The start point is Lie's setpoint x_Lie*(0) at t_B = 0 (the
Lie -> Stand transition of Algorithm 1). The verdict with the real safe set (h_tolerance 0) is
reported as well.

Measured, in interleaved rounds (each round runs every measurement once; a row is the median
over rounds, a ratio is the median of the per-round ratios), JIT compilation timed separately:

  (a) the compiled oracle: SafetyOracle(prim, settings)(x0, 0.0);
      and, for information, its compiled chunks alone: the same 32 chunk calls of K = 64 steps
      through a zero-copy FunctionBuffer (the oracle's compiled work without its Python side);
  (b) the compiled closed-loop right-hand side alone: prim.f_cl jit-compiled with the oracle's
      flags (integrator.compile_cached), called 8000 times through Function.buffer() with numpy
      memoryviews bound once; the ratio (a) / (b) is the first target (<= 1.5), as the issue
      counts evaluations (4 per RK4 step); (a) / (8 per step, what the error-aware step makes) is
      shown next to it;
  (c) the same rollout written with pinocchio from Python: pin.crba, pin.nonLinearEffects, foot
      Jacobians (LOCAL_WORLD_ALIGNED) and classical foot accelerations, the same saturated PD
      law (and least-norm gravity compensation), the same Baumgarte-stabilised contact dynamics
      solved by a numpy Schur complement, qdot by the explicit free-flyer formula, classical RK4
      at 1 ms with the base quaternion renormalised after each step (system.project). Its
      trajectory is checked against the compiled one (mpgspec.oracle.trace.trace) and the
      ratio (c) / (a) is the second target (>= 8);
  (d) for information, the plain RK4 chunk the oracle compiled before its verdicts became
      error-aware (bench/plain_rk4.py: the loop at the step start, three f_cl evaluations, outputs
      h, RoA margin, u_raw), jit-compiled the same way and run as the same 32 zero-copy chunk
      calls: (a)'s chunks / (d) is what the error-aware check costs in compiled work.

Then, for information, the shipped project specs/a1/project.yaml: mpgspec.api.build (graph build
with the JIT time of each primitive's chunk, measured with a fresh, empty MPGSPEC_CACHE) and the cost of one oracle call of Stand, whose ID-QP is
solved once per control period (stand.yaml's rate) and held, next to one of the project's Lie (the same
ID-QP with Lie's setpoint); bench/bench_idqp.py measures the ID-QP against the paper's joint-PD Lie.

Prints a markdown table and replaces (or appends) the section "A1 (rigid body)" of
bench/RESULTS.md, keeping everything else in that file. Exit code 0 when both targets are met
for the plain joint PD and the pinocchio trajectory agrees to 1e-6, else 1.
"""
from __future__ import annotations

import argparse
import copy
import datetime as _dt
import gc
import json
import os
import re
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

# a private, cold compile cache, so JIT times are measured
_JIT_DIR = tempfile.mkdtemp(prefix="bench-a1-jit-")
os.environ["MPGSPEC_CACHE"] = _JIT_DIR

import casadi as ca
import common  # noqa: E402  (bench/common.py)
from common import med_ratio, pd_lie, rounds, write_section  # noqa: E402
import pinocchio as pin  # noqa: E402
import yaml  # noqa: E402

from mpgspec.api import build, compile_project, settings_for  # noqa: E402
from mpgspec.oracle.integrator import INLINE_NODES, build_chunk, compile_cached, initial_state  # noqa: E402
from mpgspec.oracle.oracle import SafetyOracle  # noqa: E402
from mpgspec.oracle.trace import trace  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from plain_rk4 import build_plain_chunk  # noqa: E402  (bench/plain_rk4.py)

SPEC_DIR = ROOT / "specs" / "a1"
VARIANTS = (("StandPD", False), ("StandPD_gc", True))
HORIZON, DT = 2.0, 0.001
HEADING = "## A1 (rigid body)"


# ----------------------------------------------------------------------------------------------
# helpers (same conventions as bench_oracle.py)

def log(msg: str) -> None:
    print(msg, flush=True)


def machine() -> dict:
    return common.machine(casadi=ca.__version__, numpy=np.__version__, pinocchio=pin.__version__)


def loadavg() -> str:
    try:
        return " load average " + " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return ""


# ----------------------------------------------------------------------------------------------
# the benchmark project

def make_variant(tmp: Path) -> Path:
    """specs/a1 copied to tmp, plus StandPD / StandPD_gc (Lie's controller, Stand's pose, E of
    radius 1e-9), oracle horizon 2.0, dt 0.001, accuracy low; Stand (ID-QP) and the assertions
    are left out."""
    dst = tmp / "a1"
    shutil.copytree(SPEC_DIR, dst)
    pd_lie(dst)  # Lie's controller: the paper's joint PD
    prim_dir = dst / "primitives"
    lie = yaml.safe_load((prim_dir / "lie.yaml").read_text())
    stand = yaml.safe_load((prim_dir / "stand.yaml").read_text())
    files = ["primitives/lie.yaml"]
    for name, grav in VARIANTS:
        p = copy.deepcopy(lie)
        p["name"] = name
        p["description"] = (f"Benchmark: Stand pose held by Lie's joint PD "
                            f"({'with' if grav else 'without'} gravity compensation); E never entered.")
        p["setpoint"]["named"] = dict(stand["setpoint"]["named"])
        p["controller"]["gravity_compensation"] = grav
        p["roa"]["radius"] = 1e-9
        (prim_dir / f"{name.lower()}.yaml").write_text(yaml.safe_dump(p, sort_keys=False))
        files.append(f"primitives/{name.lower()}.yaml")
    proj = yaml.safe_load((dst / "project.yaml").read_text())
    proj["primitives"] = files
    proj["oracle"].update({"horizon": HORIZON, "dt": DT, "accuracy": "low"})
    proj.pop("assertions", None)
    proj.pop("sequence", None)
    (dst / "project.yaml").write_text(yaml.safe_dump(proj, sort_keys=False))
    return dst / "project.yaml"


def evals_per_step(prim) -> int:
    """Closed-loop evaluations in one compiled step of integrator.build_chunk: k1..k4 and k5 at the
    step's end; a loop too large to inline adds 3 (forward differences along the flow at both ends
    and h(x_next - e)), a small one gets exact directional derivatives inlined instead."""
    f = prim.f_cl
    return 5 + (3 if (not f.is_a("SXFunction") or f.n_nodes() > INLINE_NODES) else 0)


# ----------------------------------------------------------------------------------------------
# compiled pieces called zero-copy

class BufferCall:
    """A Function called through CasADi's FunctionBuffer, inputs and outputs bound once to numpy
    arrays: a call is the compiled code and nothing else."""

    def __init__(self, f: ca.Function, args: list[np.ndarray]):
        self.f = f
        self.buf, self.ev = f.buffer()
        self.args = [np.array(np.broadcast_to(a, f.nnz_in(i)), float) for i, a in enumerate(args)]
        self.res = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(self.args):
            self.buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self.buf.set_res(i, memoryview(r))

    def repeat(self, n: int) -> None:
        ev = self.ev
        for _ in range(n):
            ev()


def jit_rhs(prim, flags) -> ca.Function:
    """prim.f_cl alone, jit-compiled exactly as the oracle compiles its chunks."""
    f = prim.f_cl
    a = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
    name = f"rhs_{re.sub(r'[^A-Za-z0-9]', '_', prim.name)}_{os.getpid()}"
    return compile_cached(ca.Function(name, a, f.call(a), f.name_in(), f.name_out()), flags)


class ChunkLoop:
    """The oracle's own compiled chunk (one column), called zero-copy n times in sequence, each
    call fed the previous end state: the compiled work of one oracle call without its Python."""

    def __init__(self, chunk, z0: np.ndarray):
        self.call = BufferCall(chunk.mapped(1), [z0])
        self.z0 = z0

    def run(self, n: int) -> np.ndarray:
        zin, zf, ev = self.call.args[0], self.call.res[0], self.call.ev
        zin[:] = self.z0
        for _ in range(n):
            ev()
            zin[:] = zf
        return zf


# ----------------------------------------------------------------------------------------------
# (c) the same closed loop with pinocchio from Python

class PinocchioRollout:
    """Joint PD (cubic profile, saturation, optional least-norm gravity compensation) on the A1
    with the feet held by Baumgarte-stabilised contact constraints, integrated by RK4 in Python.

    Mirrors mpgspec.compile.laws.pd.pd_law, system.static_torque, constrained.solve_contact,
    liegroup.qdot and system.project, but every quantity comes from pinocchio and numpy.
    """

    def __init__(self, sysc, x_star: np.ndarray, controller):
        m = sysc.model
        if list(controller.outputs) != list(m.joint_names):
            raise ValueError("the pinocchio rollout expects the PD outputs to be the 12 joint angles in order")
        self.model = model = m.pin_model
        self.data = model.createData()
        self.fids = [model.getFrameId(f) for f in m.contact_frames]
        self.nq, self.nv, self.nu = model.nq, model.nv, m.nu
        self.nb = self.nv - self.nu
        self.nc = self.nq + self.nv  # the continuous state; the system's discrete states (contact flags, clocks) follow
        nf = len(self.fids)
        self.kp, self.kd = np.asarray(controller.kp, float), np.asarray(controller.kd, float)
        self.th = float(controller.profile.duration) if controller.profile is not None else None
        self.gc = bool(controller.gravity_compensation)
        self.alpha, self.beta = float(sysc.baumgarte.alpha), float(sysc.baumgarte.beta)
        self.ground = float(sysc.baumgarte.ground_height)
        self.lo, self.hi = np.asarray(sysc.u_lo, float), np.asarray(sysc.u_hi, float)
        self.pf, self.vf = x_star[self.nq - self.nu:self.nq].copy(), x_star[self.nq + self.nb:self.nq + self.nv].copy()
        self.winv = 1.0 / np.r_[np.ones(self.nu), np.tile([100.0, 100.0, 0.01], nf)]
        self.Bact = np.asarray(m.actuation_matrix, float)
        self.eye = 1e-9 * np.eye(self.nv)
        self.J = np.zeros((3 * nf, self.nv))
        self.drift = np.zeros(3 * nf)
        self.z = np.zeros(nf)
        self.zero_v = np.zeros(self.nv)
        self.tau = np.zeros(self.nv)
        self.LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def switch_in(self, x_sw: np.ndarray) -> None:
        """Coefficients of the cubic profile (eq. 7) from the switch-in state to the setpoint."""
        self.p0 = x_sw[self.nq - self.nu:self.nq].copy()
        self.v0 = x_sw[self.nq + self.nb:self.nc].copy()
        if self.th is not None:
            th, p0, v0, pf, vf = self.th, self.p0, self.v0, self.pf, self.vf
            self.c2 = (3 * (pf - p0) - (2 * v0 + vf) * th) / th**2
            self.c3 = (2 * (p0 - pf) + (v0 + vf) * th) / th**3

    def rhs(self, x: np.ndarray, s: float) -> np.ndarray:
        model, data, nq, nu, nb = self.model, self.data, self.nq, self.nu, self.nb
        q, v = x[:nq], x[nq:self.nc]
        pin.crba(model, data, q)  # upper triangle of D(q) in data.M
        h = pin.nonLinearEffects(model, data, q, v)
        pin.forwardKinematics(model, data, q, v, self.zero_v)  # data.a: accelerations at zero qddot
        pin.computeJointJacobians(model, data)
        pin.updateFramePlacements(model, data)
        J, drift, z, LWA = self.J, self.drift, self.z, self.LWA
        for k, f in enumerate(self.fids):
            J[3 * k:3 * k + 3] = pin.getFrameJacobian(model, data, f, LWA)[:3]
            drift[3 * k:3 * k + 3] = pin.getFrameClassicalAcceleration(model, data, f, LWA).linear
            z[k] = data.oMf[f].translation[2]
        # joint PD on the motion profile, saturated
        if self.th is None or s > self.th:
            yd, yd_dot = self.pf, self.vf
        else:
            sc = s if s > 0.0 else 0.0
            yd = self.p0 + sc * (self.v0 + sc * (self.c2 + sc * self.c3))
            yd_dot = self.v0 + sc * (2 * self.c2 + 3 * sc * self.c3)
        u = -self.kp * (q[nq - nu:] - yd) - self.kd * (v[nb:] - yd_dot)
        if self.gc:  # least-norm [u; lam] with B u + J^T lam = g(q), tangential forces weighted 100x
            g = pin.computeGeneralizedGravity(model, data, q)
            A = np.hstack([self.Bact, J.T])
            AW = A * self.winv
            y = np.linalg.solve(AW @ A.T + self.eye, g)
            u = u + AW[:, :nu].T @ y
        u = np.minimum(np.maximum(u, self.lo), self.hi)
        tau = self.tau
        tau[nb:] = u
        # J a + Jdot v = -2 alpha J v - beta^2 (0, 0, z - z_ground); Schur complement on D^-1
        gamma = -2 * self.alpha * (J @ v)
        gamma[2::3] -= self.beta**2 * (z - self.ground)
        pin.cholesky.decompose(model, data)  # sparse L^T D L of data.M
        Minv = pin.cholesky.computeMinv(model, data)
        MiJt = Minv @ J.T
        a0 = Minv @ (tau - h)
        lam = np.linalg.solve(J @ MiJt, gamma - drift - J @ a0)
        a = a0 + MiJt @ lam
        # qdot of the free flyer: p' = R(quat) v_lin, quat' = 0.5 quat (x) (omega, 0)
        qx, qy, qz, qw = q[3:7]
        R = np.array([[1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
                      [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
                      [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])
        w, qv = v[3:6], q[3:6]
        quat_dot = 0.5 * np.r_[qw * w + np.cross(qv, w), -(qv @ w)]
        return np.concatenate([R @ v[:3], quat_dot, v[6:], a])

    def rollout(self, x0: np.ndarray, dt: float, n: int) -> np.ndarray:
        """Continuous states (q, v) after 0..n RK4 steps (rows)."""
        self.switch_in(np.asarray(x0, float))
        X = np.empty((n + 1, self.nc))
        x = X[0] = np.asarray(x0, float)[:self.nc]
        f, h2 = self.rhs, dt / 2
        for k in range(n):
            s = k * dt
            k1 = f(x, s)
            k2 = f(x + h2 * k1, s + h2)
            k3 = f(x + h2 * k2, s + h2)
            k4 = f(x + dt * k3, s + dt)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            x[3:7] /= np.linalg.norm(x[3:7])
            X[k + 1] = x
        return X


# ----------------------------------------------------------------------------------------------
# the shipped project: graph build and the ID-QP

def shipped_project(n_stand: int, n_lie: int) -> dict:
    """specs/a1 built from an empty compile cache; what the compilers did is read from the compile log
    (MPGSPEC_JIT_LOG): compiler seconds per kind of library (loop, judged, trace, ...)."""
    os.environ["MPGSPEC_CACHE"] = tempfile.mkdtemp(prefix="cold-", dir=_JIT_DIR)  # cold: the compilers really run
    log_path = Path(_JIT_DIR) / "jit_log.jsonl"
    old_log = os.environ.get("MPGSPEC_JIT_LOG")
    os.environ["MPGSPEC_JIT_LOG"] = str(log_path)
    spec = load_project(SPEC_DIR / "project.yaml")
    st = settings_for(spec)
    try:
        t = time.perf_counter()
        prims, g, info, oracle_of = common.run_build(build, spec, st, SafetyOracle)
        total = time.perf_counter() - t
    finally:
        if old_log is None:
            os.environ.pop("MPGSPEC_JIT_LOG", None)
        else:
            os.environ["MPGSPEC_JIT_LOG"] = old_log
    jit: dict[str, float] = {}
    if log_path.is_file():
        for line in log_path.read_text().splitlines():
            rec = json.loads(line)
            if not rec.get("hit"):  # kind: the name up to its first '_', as bench_cold.py groups them
                kind = rec["name"].split("_")[0]
                jit[kind] = jit.get(kind, 0.0) + float(rec["gcc_s"])
    out = {"total": total, "info": info, "jit": jit, "edges": g.G.number_of_edges(), "settings": st,
           "eps": {n: evals_per_step(p) for n, p in prims.items()},
           "info_stand": prims["Stand"].info.get("id_qp", {}).get("control_rate", "?")}
    xl, xs = prims["Lie"].x_star(0.0), prims["Stand"].x_star(0.0)
    for name, x0, n in (("Stand", xl, n_stand), ("Lie", xs, n_lie)):
        ts, ev = [], None
        oracle = oracle_of(name)  # built (chunk compiled) outside the timing
        for _ in range(n):
            t = time.perf_counter()
            ev = oracle(x0, 0.0)
            ts.append(time.perf_counter() - t)
        out[name] = {"t": statistics.median(ts), "ev": ev, "n": n}
    return out


# ----------------------------------------------------------------------------------------------

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 rounds, one ID-QP oracle call")
    ap.add_argument("--repeats", type=int, default=None, help="measurement rounds (default 5, quick 3)")
    ap.add_argument("--no-shipped", action="store_true", help="skip the build of specs/a1 and the ID-QP timing")
    ap.add_argument("--no-write", action="store_true", help="do not touch bench/RESULTS.md")
    args = ap.parse_args(argv)
    R = args.repeats or (3 if args.quick else 5)
    T0 = time.perf_counter()
    mach = machine()
    mach["revision"] = common.revision(ROOT)  # at the start: what is measured
    log(f"machine: {mach['nproc']} CPU ({mach['cpu']}), {mach['platform']}, Python {mach['python']}, "
        f"CasADi {mach['casadi']}, NumPy {mach['numpy']}, pinocchio {mach['pinocchio']};{loadavg()}")

    tmp = Path(tempfile.mkdtemp(prefix="bench-a1-"))
    try:
        return _run(args, R, T0, mach, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        gc.collect()
        shutil.rmtree(_JIT_DIR, ignore_errors=True)  # the private compile caches of this run


def _run(args, R, T0, mach, tmp) -> int:
    path = make_variant(tmp)
    t = time.perf_counter()
    spec = load_project(path)
    prims = compile_project(spec)
    t_compile = time.perf_counter() - t
    base = settings_for(spec)
    st = base.replace(h_tolerance=1e9)  # never leave C: run the full horizon
    x0 = prims["Lie"].x_star(0.0)
    nsteps = int(np.ceil(HORIZON / st.dt - 1e-9))
    n_eval = 4 * nsteps  # classical RK4, as the issue counts
    n_chunks = nsteps // st.chunk + 1  # the oracle stops once steps + K > nsteps
    ctrl = {inst.name: inst.spec.controller for inst in spec.primitives}
    log(f"\nbenchmark project (temporary copy of specs/a1): compiled in {t_compile:.2f} s; oracle dt={st.dt:g}, "
        f"T={HORIZON:g}, refinements={st.refinements}, chunk K={st.chunk}, jit flags {' '.join(st.jit_flags)}; start point "
        f"x_Lie*(0), t_B = 0; {nsteps} RK4 steps = {n_eval} RHS evaluations per rollout; the oracle computes "
        f"{n_chunks} chunks = {n_chunks * st.chunk} steps")

    setup, fns = {}, {}
    for name, _gc in VARIANTS:
        prim = prims[name]
        d = setup[name] = {"nodes": prim.f_cl.n_nodes() if prim.f_cl.is_a("SXFunction") else None,
                           "h_nodes": prim.h.n_nodes() if prim.h.is_a("SXFunction") else None,
                           "eps": evals_per_step(prim)}
        log(f"\n{name}: f_cl {d['nodes']} SX nodes, h {d['h_nodes']} SX nodes ({len(prim.h_names)} safety functions); "
            f"{d['eps']} closed-loop evaluations per compiled step")
        t = time.perf_counter()
        oracle = SafetyOracle(prim, st)
        d["jit_oracle"] = time.perf_counter() - t
        t = time.perf_counter()
        ev = oracle(x0, 0.0)
        d["first"] = time.perf_counter() - t
        d["ev"] = ev
        if ev.steps != nsteps or ev.reason.value != "horizon_reached":
            log(f"  WARNING: the oracle stopped after {ev.steps} steps ({ev.reason.value}), not at the horizon")
        ev_real = SafetyOracle(prim, base)(x0, 0.0)  # same compiled chunk, the real tolerance
        d["ev_real"] = ev_real
        worst = sorted(((v, k) for k, v in ev.min_margins.items() if v is not None))[:2]
        log(f"  oracle: JIT {d['jit_oracle']:.2f} s, first call {d['first'] * 1e3:.1f} ms, {ev.steps} steps "
            f"({ev.reason.value}); smallest margins over the rollout: "
            + ", ".join(f"{k} {v:.3g}" for v, k in worst))
        log(f"  with the real safe set (h_tolerance {base.h_tolerance:g}): verdict {ev_real.verdict} ({ev_real.status}), "
            f"{ev_real.reason.value} at {ev_real.t_stop:.3f} s"
            + (f" ({ev_real.violated})" if ev_real.violated else ""))
        t = time.perf_counter()
        f = jit_rhs(prim, st.jit_flags)
        d["jit_rhs"] = time.perf_counter() - t
        rhs = BufferCall(f, [x0, 0.5, 0.5, x0])
        ref = np.array(prim.f_cl(x0, 0.5, 0.5, x0)).ravel()
        rhs.repeat(1)
        log(f"  compiled RHS: JIT {d['jit_rhs']:.2f} s; |buffer call - f_cl| = {np.abs(rhs.res[0] - ref).max():.1e}")
        chunk = build_chunk(prim, st.dt, st.chunk, st.jit, st.jit_flags)
        loop = ChunkLoop(chunk, initial_state(prim, x0, 0.0))
        loop.run(1)
        t = time.perf_counter()
        plain = build_plain_chunk(prim, st.dt, st.chunk, st.jit, st.jit_flags)
        d["jit_plain"] = time.perf_counter() - t
        ploop = ChunkLoop(plain, initial_state(prim, x0, 0.0))
        d["plain_diff"] = float(np.abs(ploop.run(n_chunks)[:prim.system.nx] - loop.run(n_chunks)[:prim.system.nx]).max())
        log(f"  plain RK4 chunk (before the error-aware check): JIT {d['jit_plain']:.2f} s; |x_plain(T') - x_new(T')|_inf "
            f"after {n_chunks * st.chunk} steps = {d['plain_diff']:.1e}")
        # verification against the compiled trajectory
        t = time.perf_counter()
        tr = trace(prim, x0, 0.0, HORIZON, st, max_points=10 ** 7)
        d["t_trace"] = time.perf_counter() - t
        Xc = np.array(tr["x"], dtype=float).T[:nsteps + 1]
        pr = PinocchioRollout(prim.system, prim.x_star(0.0), ctrl[name])
        pr.switch_in(x0)
        d["rhs_err"] = max(np.abs(pr.rhs(x, s) - np.array(prim.f_cl(x, s, s, x0)).ravel()[:pr.nc]).max()
                           for x, s in ((Xc[0], 0.0), (Xc[nsteps // 4], 0.25 * HORIZON), (Xc[-1], HORIZON)))
        t = time.perf_counter()
        Xp = pr.rollout(x0, st.dt, nsteps)
        d["t_pin_first"] = time.perf_counter() - t
        d["final_diff"] = float(np.abs(Xp[-1] - Xc[-1, :pr.nc]).max())
        d["traj_diff"] = float(np.abs(Xp - Xc[:, :pr.nc]).max())
        d["final"] = Xc[-1]
        log(f"  trace (JIT of the state-recording chunk and one rollout): {d['t_trace']:.2f} s; pinocchio RHS vs "
            f"f_cl: {d['rhs_err']:.1e}; pinocchio rollout {d['t_pin_first']:.2f} s; |x_pin(T) - x_compiled(T)|_inf "
            f"= {d['final_diff']:.1e} (max over the trajectory {d['traj_diff']:.1e}); base height at T "
            f"{Xc[-1][2]:.4f} m")
        fns[f"oracle {name}"] = lambda o=oracle: o(x0, 0.0)
        fns[f"chunks {name}"] = lambda lp=loop: lp.run(n_chunks)
        fns[f"plain {name}"] = lambda lp=ploop: lp.run(n_chunks)
        fns[f"rhs {name}"] = lambda c=rhs: c.repeat(n_eval)
        fns[f"pin {name}"] = lambda p=pr: p.rollout(x0, st.dt, nsteps)

    # Python-side cost of one buffer call, on a trivial compiled function
    a = ca.SX.sym("a")
    triv = BufferCall(compile_cached(ca.Function(f"triv_{os.getpid()}", [a], [2 * a]), st.jit_flags), [1.0])
    fns["trivial"] = lambda: triv.repeat(n_eval)

    log(f"\n{R} interleaved rounds")
    T = rounds(fns, R)
    md = {k: statistics.median(v) for k, v in T.items()}
    mn = {k: min(v) for k, v in T.items()}
    for k in fns:
        log(f"  {k:18s} median {md[k] * 1e3:8.1f} ms  min {mn[k] * 1e3:8.1f} ms")
    res = {}
    for name, _gc in VARIANTS:
        r = res[name] = {
            "oracle": md[f"oracle {name}"], "chunks": md[f"chunks {name}"], "rhs": md[f"rhs {name}"],
            "pin": md[f"pin {name}"], "plain": md[f"plain {name}"],
            "r_rhs": med_ratio(T[f"oracle {name}"], T[f"rhs {name}"]),
            "r_check": med_ratio(T[f"chunks {name}"], T[f"plain {name}"]),
            "r_chunks": med_ratio(T[f"oracle {name}"], T[f"chunks {name}"]),
            "r_chunks_rhs": med_ratio(T[f"chunks {name}"], T[f"rhs {name}"]),
            "r_pin": med_ratio(T[f"pin {name}"], T[f"oracle {name}"]),
        }
        log(f"  {name}: oracle / (RHS x {n_eval}) = {r['r_rhs']:.2f} (its compiled chunks alone: "
            f"{r['r_chunks_rhs']:.2f}; oracle / its chunks {r['r_chunks']:.2f}); oracle / (RHS x "
            f"{setup[name]['eps'] * nsteps}, the new step's evaluations) = {r['r_rhs'] * 4 / setup[name]['eps']:.2f}; "
            f"its chunks / plain RK4 chunks = {r['r_check']:.2f}; "
            f"pinocchio / oracle = {r['r_pin']:.1f}x; "
            f"{r['rhs'] / n_eval * 1e6:.2f} us per compiled RHS, {r['pin'] / n_eval * 1e6:.0f} us per pinocchio RHS")
    triv_ns = md["trivial"] / n_eval * 1e9
    log(f"  a FunctionBuffer call from the Python loop costs {triv_ns:.0f} ns (trivial function), "
        f"{md['trivial'] / min(r['rhs'] for r in res.values()):.0%} of the RHS row at most")

    shipped = None
    if not args.no_shipped:
        n_stand = 1 if args.quick else 3
        log(f"\nshipped specs/a1/project.yaml: mpgspec.api.build, then {n_stand} Stand oracle call(s) (ID-QP) and "
            f"{R} Lie oracle calls")
        shipped = shipped_project(n_stand, R)
        s, info = shipped, shipped["info"]
        log(f"  build {s['total']:.2f} s (compile {info.get('compile_s', 0):.2f} s, traces {info.get('traces_s', 0):.2f} s, "
            f"graph {info['graph_s']:.2f} s with "
            f"{info['oracle_calls']} oracle calls, {s['edges']} edges); compilers by library kind: "
            + ", ".join(f"{k} {v:.2f} s" for k, v in s["jit"].items()))
        for nm in ("Stand", "Lie"):
            e = s[nm]["ev"]
            log(f"  {nm} oracle call: {s[nm]['t'] * 1e3:.1f} ms, {e.steps} steps "
                f"({s[nm]['t'] / max(e.steps, 1) * 1e6:.0f} us/step), verdict {e.verdict} ({e.status}, {e.reason.value})")

    # summary ------------------------------------------------------------------------------------
    A, B = (res[n] for n, _ in VARIANTS)
    dA, dB = (setup[n] for n, _ in VARIANTS)
    ok_rhs, ok_pin = A["r_rhs"] * 4 / dA["eps"] <= 1.5, A["r_pin"] >= 8
    ok_traj = max(dA["final_diff"], dB["final_diff"]) <= 1e-6

    def verdict(e):
        return (f"{e.verdict} ({e.status}), {e.reason.value} at {e.t_stop:.3f} s"
                + (f" ({e.violated})" if e.violated else ""))

    rows = [
        ("f_cl size (SX nodes)", f"{dA['nodes']:,}", f"{dB['nodes']:,}"),
        ("closed-loop evaluations per compiled step, at least (RK4 k1..k4 + end + rates; step doubling makes more)",
         f"{dA['eps']}", f"{dB['eps']}"),
        ("JIT: oracle chunk / RHS alone / trace chunk (+ one rollout) / plain RK4 chunk",
         f"{dA['jit_oracle']:.1f} s / {dA['jit_rhs']:.1f} s / {dA['t_trace']:.1f} s / {dA['jit_plain']:.1f} s",
         f"{dB['jit_oracle']:.1f} s / {dB['jit_rhs']:.1f} s / {dB['t_trace']:.1f} s / {dB['jit_plain']:.1f} s"),
        (f"(a) compiled oracle call, {nsteps} steps (computes {n_chunks * st.chunk})",
         f"{A['oracle'] * 1e3:.1f} ms", f"{B['oracle'] * 1e3:.1f} ms"),
        (f"    its {n_chunks} compiled chunks alone, zero-copy",
         f"{A['chunks'] * 1e3:.1f} ms", f"{B['chunks'] * 1e3:.1f} ms"),
        (f"(b) compiled RHS x {n_eval}, FunctionBuffer",
         f"{A['rhs'] * 1e3:.1f} ms ({A['rhs'] / n_eval * 1e6:.2f} us/eval)",
         f"{B['rhs'] * 1e3:.1f} ms ({B['rhs'] / n_eval * 1e6:.2f} us/eval)"),
        ("(a) / (b), counting classical RK4's 4 evaluations per step", f"{A['r_rhs']:.2f}", f"{B['r_rhs']:.2f}"),
        ("    compiled chunks alone / (b)", f"{A['r_chunks_rhs']:.2f}", f"{B['r_chunks_rhs']:.2f}"),
        (f"**(a) / (RHS x evaluations per compiled step x {nsteps})** (target <= 1.5; an upper bound: the "
         f"evaluations counted at least)",
         f"**{A['r_rhs'] * 4 / dA['eps']:.2f}**", f"**{B['r_rhs'] * 4 / dB['eps']:.2f}**"),
        (f"(d) plain RK4 chunks (before the error-aware check), {n_chunks} zero-copy",
         f"{A['plain'] * 1e3:.1f} ms", f"{B['plain'] * 1e3:.1f} ms"),
        ("**cost of the error-aware check in compiled work** ((a)'s chunks / (d))",
         f"**{A['r_check']:.2f}x**", f"**{B['r_check']:.2f}x**"),
        ("(c) same rollout, pinocchio + numpy from Python",
         f"{A['pin'] * 1e3:.0f} ms ({A['pin'] / n_eval * 1e6:.0f} us/eval)",
         f"{B['pin'] * 1e3:.0f} ms ({B['pin'] / n_eval * 1e6:.0f} us/eval)"),
        ("**(c) / (a)** (target >= 8)", f"**{A['r_pin']:.1f}x**", f"**{B['r_pin']:.1f}x**"),
        ("\\|x_pin(T) - x_compiled(T)\\|_inf (max over trajectory)",
         f"{dA['final_diff']:.1e} ({dA['traj_diff']:.1e})", f"{dB['final_diff']:.1e} ({dB['traj_diff']:.1e})"),
        ("verdict with the real safe set (h_tolerance 0; E radius 1e-9)",
         verdict(dA["ev_real"]), verdict(dB["ev_real"])),
    ]
    w = max(len(r[0]) for r in rows)
    table = [f"| {'measure':{w}s} | {VARIANTS[0][0]} (plain joint PD) | {VARIANTS[1][0]} (joint PD + gravity comp.) |",
             f"|{'-' * (w + 2)}|------|------|"]
    table += [f"| {a:{w}s} | {b} | {c} |" for a, b, c in rows]
    table = "\n".join(table)
    table2 = ""
    if shipped is not None:
        s, info = shipped, shipped["info"]
        st0 = s["settings"]
        es, el = s["Stand"]["ev"], s["Lie"]["ev"]
        ps, pl = s["Stand"]["t"] / max(es.steps, 1), s["Lie"]["t"] / max(el.steps, 1)
        jit_total = sum(s["jit"].values())
        rows2 = [
            (f"graph build, `mpgspec.api.build` ({info['oracle_calls']} oracle calls, dt={st0.dt:g}, "
             f"T={st0.horizon:g}, refinements={st0.refinements})",
             f"{s['total']:.1f} s: compiling the primitives {info.get('compile_s', 0.0):.1f} s, "
             f"Algorithm 1 {info['graph_s']:.1f} s (its chunks' JIT included)"
             + (f", traces of edges and failures {info['traces_s']:.1f} s (their own JIT included)"
                if "traces_s" in info else "")
             + f", the rest {s['total'] - info['graph_s'] - info.get('traces_s', 0.0) - info.get('compile_s', 0.0):.1f} s"),
            ("compilers, cold cache (fresh MPGSPEC_CACHE; CPU seconds from the compile log, by library kind)",
             f"{jit_total:.1f} s: " + ", ".join(f"{k} {v:.1f} s" for k, v in sorted(s["jit"].items(), key=lambda kv: -kv[1]))),
            (f"Stand oracle call, Lie -> Stand (ID-QP at {s['info_stand']}, held over the steps between solves)",
             f"{s['Stand']['t'] * 1e3:,.0f} ms, {es.steps} steps, {ps * 1e6:,.0f} us/step, {verdict(es)}"),
            ("Lie oracle call, Stand -> Lie (the project's Lie: the ID-QP with Lie's setpoint)",
             f"{s['Lie']['t'] * 1e3:.1f} ms, {el.steps} steps, {pl * 1e6:.1f} us/step, {verdict(el)}"),
            ("Stand step / Lie step", f"{ps / pl:.1f}x"),
        ]
        w2 = max(len(r[0]) for r in rows2)
        table2 = "\n".join([f"| {'shipped specs/a1/project.yaml':{w2}s} | value |", f"|{'-' * (w2 + 2)}|-------|"]
                           + [f"| {a:{w2}s} | {b} |" for a, b in rows2])
    when = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    head = (f"A1 quadruped, {when}, {mach['revision']}; {mach['nproc']} CPU ({mach['cpu']}), Python {mach['python']}, CasADi "
            f"{mach['casadi']}, NumPy {mach['numpy']}, pinocchio {mach['pinocchio']};{loadavg()}; "
            f"`python bench/bench_a1.py{' --quick' if args.quick else ''}` (medians of {R} interleaved rounds; "
            f"{time.perf_counter() - T0:.0f} s wall). Start x_Lie*(0), t_B = 0; oracle dt={st.dt:g}, T={HORIZON:g}, "
            f"refinements=0 (low), K={st.chunk}, JIT {' '.join(st.jit_flags)}; E radius 1e-9 and h_tolerance 1e9 so "
            f"every call runs the full {nsteps} steps ({n_eval} RHS evaluations of classical RK4; the error-aware step "
            f"makes {dA['eps']} closed-loop evaluations), still computing h at both ends of each step, its rates, the "
            f"error estimate, the RoA margin and u.")
    section = f"{HEADING}\n\n{head}\n\n{table}\n" + (f"\n{table2}\n" if table2 else "") + \
        "\nSee the docstring of bench/bench_a1.py for the meaning of each row.\n"
    log("\n" + section)
    if not args.no_write:
        out = ROOT / "bench" / "RESULTS.md"
        write_section(out, HEADING, section)
        log(f"wrote the '{HEADING[3:]}' section of {out.relative_to(ROOT)}")
    log(f"targets ({VARIANTS[0][0]}, plain joint PD): oracle within 1.5x of the RHS cost x the evaluations its step "
        f"makes {'met' if ok_rhs else 'MISSED'} ({A['r_rhs'] * 4 / dA['eps']:.2f}); >= 8x faster than pinocchio from Python "
        f"{'met' if ok_pin else 'MISSED'} ({A['r_pin']:.1f}x); same trajectory to 1e-6 "
        f"{'met' if ok_traj else 'MISSED'}")
    return 0 if (ok_rhs and ok_pin and ok_traj) else 1


if __name__ == "__main__":
    sys.exit(main())
