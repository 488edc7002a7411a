"""Replay the sequence's runs in MuJoCo and compare them with mpgspec's own rollouts."""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...compile.primitive import CompiledPrimitive
from ...oracle.executors import InProcess
from ...oracle.joint import Map, run
from ...oracle.tasks import Failed
from ..sequence import SequenceRun, playback_samples
from .executor import ExecutorPlan, StateExecutor
from .mjcf import MujocoRobot, build_robot
from .replay import Replay, replay
from .settings import CrossCheckSettings

SERIES_POINTS = 200
"""Samples kept of each compared series (for the report's plot)."""
RECORD = 3
"""Layout of the memoised comparison (part of its key): 2 keeps the playback samples; 3 a variant is
the executor's run on the simulator's state, with its least margins."""
WORST = 10
"""Kinds of safety functions listed per run (the least margin of each, least first)."""


@dataclass
class CrossCheckResult:
    """Every replayed run, compared with mpgspec's; `agree` is True when every verdict matches."""

    simulator: str
    settings: CrossCheckSettings
    model: dict
    runs: dict[str, dict] = field(default_factory=dict)
    variants: list[dict] = field(default_factory=list)
    """The graph executor run on the simulator's state under each of the project's variants (variants_stage)."""

    @property
    def agree(self) -> bool:
        return all(r["agree"] for r in self.runs.values()) and all(v["agree"] for v in self.variants)

    def to_dict(self) -> dict:
        """What the report stores: everything but the runs' playback samples (playback())."""
        runs = {m: _without_playback(r) for m, r in self.runs.items()}
        return {"simulator": self.simulator, "settings": self.settings.to_dict(), "model": self.model,
                "agree": self.agree, "runs": runs, **({"variants": self.variants} if self.variants else {})}

    def playback(self) -> dict[str, dict]:
        """name -> {t, x} of each replayed run's states at the 3D playback's frame rate ('graph',
        'naive', and 'graph executor' for the executor on the simulator's state)."""
        out = {}
        for m, r in self.runs.items():
            if isinstance(r.get("playback"), dict):
                out[m] = r["playback"]
            if isinstance((r.get("executor") or {}).get("playback"), dict):
                out[f"{m} executor"] = r["executor"]["playback"]
        return out


def _without_playback(run: dict) -> dict:
    out = {k: v for k, v in run.items() if k != "playback"}
    if isinstance(out.get("executor"), dict):
        out["executor"] = {k: v for k, v in out["executor"].items() if k != "playback"}
    return out


def _playback(rep: Replay, nq: int) -> dict:
    """The replay's configurations at the playback's frame rate (positions only: what is drawn)."""
    k = playback_samples(rep.t)
    return {"t": [round(float(v), 4) for v in rep.t[k]],
            "x": [[round(float(v), 5) for v in row] for row in rep.x[k, :nq]],
            "active": [rep.active[i] for i in k] if len(rep.active) == len(rep.t) else []}


def crosscheck_runs(prims: dict[str, CompiledPrimitive], runs: dict[str, SequenceRun], duration: float,
                    settings: CrossCheckSettings, h_tolerance: float = 0.0, robot: MujocoRobot | None = None,
                    memo=None, executor=None, plan: ExecutorPlan | None = None) -> CrossCheckResult:
    """Replay each run named in settings.runs (that exists) for `duration` s and compare it.

    plan (optional): the graph executor's lookup table and verified switch times; the graph run is
    then also run by the executor on the simulator's own state (its `executor` entry).

    memo (mpgspec.oracle.cache.Memo, optional) keeps each comparison by the content hash of what
    decides it: the run, the primitives' closed loops, the settings and the simulator's version.
    executor (optional): the runs not in the memo are replayed side by side through its map (each
    run alone in its process, so the comparison is the same wherever it runs)."""
    stage = runs_stage(prims, runs, duration, settings, h_tolerance, robot, memo, plan,
                       pooled=2 if executor is not None else None)
    return run(stage, executor or InProcess())


def runs_stage(prims: dict[str, CompiledPrimitive], runs: dict[str, SequenceRun], duration: float,
               settings: CrossCheckSettings, h_tolerance: float = 0.0, robot: MujocoRobot | None = None,
               memo=None, plan: ExecutorPlan | None = None, pooled: int | None = 1):
    """crosscheck_runs as a stage (mpgspec.oracle.joint): the runs not in the memo are one map when
    there are at least `pooled` of them (None: replayed in this process), the result returned."""
    system = next(iter(prims.values())).system
    robot = robot or build_robot(system, settings)
    res = CrossCheckResult(settings.simulator, settings, dict(robot.info))
    modes = [mode for mode in settings.runs if mode in runs]
    keys = {m: _memo_key(memo, prims, runs[m], duration, settings, h_tolerance, robot,
                         plan if m == "graph" else None) for m in modes} if memo is not None else {}
    known = {m: memo.get(keys[m]) for m in keys}
    todo = [m for m in modes if known.get(m) is None]
    if pooled is not None and len(todo) >= pooled:  # each worker builds the same MuJoCo model from the system
        shared = (None, prims, {m: runs[m] for m in todo}, duration, settings, h_tolerance, plan)
        done = yield Map(_replayed, todo, f"cross-check ({settings.simulator})", shared,
                         cost=[_cost(runs[m], duration, plan if m == "graph" else None) for m in todo])
    else:
        done = [_replayed((robot, prims, runs, duration, settings, h_tolerance, plan), m) for m in todo]
    for m, out in zip(todo, done):
        if isinstance(out, Failed):  # as a replay raising here would
            raise RuntimeError(f"the {settings.simulator} replay of the {m} run failed: {out.error}")
        known[m] = out
        if m in keys:
            memo.put(keys[m], out)
    res.runs = {m: known[m] for m in modes}
    return res


def _cost(run: SequenceRun, duration: float, plan: ExecutorPlan | None = None) -> float:
    """Seconds of simulated time a replay covers (twice with the executor on the simulator's state):
    what orders a merged map."""
    return _until(run, duration) + (duration if plan is not None else 0.0)


def variants_stage(prims: dict[str, CompiledPrimitive], run: SequenceRun, duration: float,
                   variants: list[tuple[str, CrossCheckSettings, dict]], plan: ExecutorPlan,
                   h_tolerance: float = 0.0, memo=None):
    """The graph executor run on the simulator's own state under each variant (name, settings, what it
    replaces), as a stage (mpgspec.oracle.joint): what a robot running the plan would do on that model.
    Per variant: its verdict beside mpgspec's graph run, its first violation, how many control updates
    violate, the least margins, and when it reached each goal of the sequence against mpgspec's run
    (a variant agrees when it is safe and reaches every goal). Each is kept in the memo as a
    cross-checked run is; the ones not in it are one map (each in its own process)."""
    system = next(iter(prims.values())).system
    run_hash = _run_hash(run, plan) if memo is not None and variants else None
    keys = [_memo_key(memo, prims, run, duration, st, h_tolerance, build_robot(system, st), plan, "crosscheck variant",
                      run_hash) if memo is not None else None for _n, st, _c in variants]
    done = [memo.get(k) if k is not None else None for k in keys]
    todo = [i for i, r in enumerate(done) if r is None]
    items = [variants[i][1] for i in todo]
    shared = (prims, run, duration, h_tolerance, plan)
    label = f"cross-check variants ({variants[0][1].simulator})" if variants else "cross-check variants"
    got = yield Map(_variant, items, label, shared, cost=[duration] * len(items))
    for i, r in zip(todo, got):
        if isinstance(r, Failed):
            raise RuntimeError(f"the executor run with {variants[i][0]} failed: {r.error}")
        done[i] = r
        if keys[i] is not None:
            memo.put(keys[i], r)
    theirs = _verdict_of(run)
    out = []
    for (name, st, changed), r in zip(variants, done):
        verdict = {k: r.get(k) for k in ("safe", "first_violation", "violation_samples", "failed")}
        out.append({"name": name, "replaces": changed, "agree": bool(r["safe"] and r["reached_every_goal"]),
                    st.simulator: verdict, "mpgspec": theirs, "worst": (r.get("worst") or [])[:5],
                    "goals": r.get("goals") or [], "reached_every_goal": bool(r["reached_every_goal"]),
                    "largest_lag_s": r.get("largest_lag_s"), "waiting": r.get("waiting")})
    return out


def _verdict_of(run: SequenceRun) -> dict:
    """mpgspec's verdict of a sequence run as the comparisons show it beside the simulator's."""
    return {"safe": run.safe, "first_violation": run.violations[0] if run.violations else None,
            "violation_samples": len({v["t"] for v in run.violations}), "failed": run.failed}


def _variant(shared: tuple, st: CrossCheckSettings) -> dict:
    """The graph executor run on the simulator's state under one variant's settings; shared = (prims,
    run, duration, h_tolerance, plan)."""
    prims, run, duration, h_tolerance, plan = shared
    robot = build_robot(next(iter(prims.values())).system, st)
    return _without_playback(executed(robot, prims, plan, run, duration, st, h_tolerance))


def _replayed(shared: tuple, mode: str) -> dict:
    """One run replayed and compared: shared = (robot or None to build it, prims, runs, duration,
    settings, h_tolerance, plan or None); with a plan the graph run is also executed on the
    simulator's state."""
    robot, prims, runs, duration, settings, h_tolerance, plan = shared
    robot = robot or build_robot(next(iter(prims.values())).system, settings)
    rep = replay(robot, prims, runs[mode].switches, _until(runs[mode], duration), settings, h_tolerance)
    out = compare(prims, rep, runs[mode], settings.control_rate)
    if plan is not None and mode == "graph":
        out["executor"] = executed(robot, prims, plan, runs[mode], duration, settings, h_tolerance)
    return out


def executed(robot: MujocoRobot, prims: dict[str, CompiledPrimitive], plan: ExecutorPlan, run: SequenceRun,
             duration: float, settings: CrossCheckSettings, h_tolerance: float) -> dict:
    """The graph executor run on the simulator's state for `duration` s: its verdict, switches and
    when it arrived in each goal, beside mpgspec's run (whose switch times the replay reuses)."""
    ex = StateExecutor(plan, prims, settings.control_rate)
    rep = replay(robot, prims, run.switches[:1], duration, settings, h_tolerance, decide=ex.decide)
    goals = ex.goals(run.switches)
    lags = [g["arrived"] - g["arrived_mpgspec"] for g in goals
            if g["arrived"] is not None and g["arrived_mpgspec"] is not None]
    return {"safe": rep.safe and not ex.unverified, "first_violation": rep.first_violation,
            "violation_samples": rep.violation_samples, "failed": rep.failed or ex.unverified,
            "switches": rep.switches, "goals": goals,
            "reached_every_goal": all(g["arrived"] is not None for g in goals),
            "largest_lag_s": max((abs(v) for v in lags), default=None),
            "waiting": {"primitive": ex.cur, "best_roa_margin": ex.best.get(ex.cur)} if ex.goal != ex.cur else None,
            "contact": rep.contact,
            "law_failures": dict(rep.law_failures), "wall_s": rep.wall_s,
            "worst": [{"primitive": p, "h": h, "mujoco": v, "t": tt} for p, h, v, tt in least_margins(prims, rep)],
            "playback": _playback(rep, next(iter(prims.values())).system.model.nq)}


def _until(run: SequenceRun, duration: float) -> float:
    """How long to replay a run: the sequence's duration, or up to where mpgspec's run stopped
    (a numerical failure): after it there is nothing to compare, and a robot that has fallen
    only makes the simulator's law fail at every update."""
    if run.failed and run.t:
        return min(duration, float(run.t[-1]))
    return duration


def _memo_key(memo, prims, run: SequenceRun, duration, settings, h_tolerance, robot, plan=None,
              kind: str = "crosscheck", run_hash: str | None = None) -> str:
    """The memo key of one comparison; run_hash: _run_hash(run, plan) when the caller has it (a run of
    many seconds takes a while to serialise, and every variant of it has the same)."""
    used = sorted({s["to"] for s in run.switches} | (set(plan.table) if plan is not None else set()))
    return memo.key(kind, RECORD, run_hash or _run_hash(run, plan), [prims[n].digest() for n in used],
                    duration, sorted(settings.to_dict().items()), h_tolerance, sorted(robot.info.items()))


def _run_hash(run: SequenceRun, plan=None) -> str:
    text = json.dumps([run.to_dict(), plan.key() if plan is not None else None], sort_keys=True, default=float)
    return hashlib.sha256(text.encode()).hexdigest()


def _com_function(system) -> ca.Function:
    env = system.extra_env
    return ca.Function("com", [system.x], [ca.vertcat(*[env[f"com_{a}"] for a in "xyz"])])


def _decimate(n: int, most: int = SERIES_POINTS) -> np.ndarray:
    return np.unique(np.linspace(0, n - 1, min(n, most)).round().astype(int)) if n else np.zeros(0, int)


def least_margins(prims: dict[str, CompiledPrimitive], rep: Replay) -> list[tuple]:
    """(primitive, h, least value, when) of each kind of h (q_min, foot_still, ...) in a replay, least
    first, at most WORST of them."""
    families: dict[str, tuple] = {}
    for p, (least, when) in rep.worst.items():
        for h, v, tt in zip(prims[p].h_names, least, when):
            fam = h.split("[", 1)[0]
            if np.isfinite(v) or v < 0:
                if fam not in families or v < families[fam][2]:
                    families[fam] = (p, h, float(v), float(tt))
    return sorted(families.values(), key=lambda w: w[2])[:WORST]


def compare(prims: dict[str, CompiledPrimitive], rep: Replay, run: SequenceRun, rate: float) -> dict:
    """Verdicts, first violations, the largest CoM and joint divergence at mpgspec's samples (each
    matched with the nearest control update), the least margins in MuJoCo and the contacts."""
    system = next(iter(prims.values())).system
    t = np.asarray(run.t, float)
    X = np.asarray(run.x, float).reshape(len(t), -1)
    k = np.clip(np.round(t * rate).astype(int), 0, len(rep.t) - 1)
    ok = np.isfinite(rep.x[k]).all(axis=1) & np.isfinite(X).all(axis=1) if len(t) else np.zeros(0, bool)
    t, X, k = t[ok], X[ok], k[ok]
    div = {"samples": int(len(t)), "com": None, "joint": None, "until": None, "com_until": None, "joint_until": None}
    com = np.asarray(_com_function(system).map(len(t))(X.T), float).T if len(t) else np.zeros((0, 3))
    if len(t):
        dc = np.linalg.norm(com - rep.com[k], axis=1)
        i = int(np.argmax(dc))
        div["com"] = {"max": float(dc[i]), "t": float(t[i]), "mpgspec": com[i].tolist(), "mujoco": rep.com[k[i]].tolist()}
        bq, nq = (7 if system.model.floating_base else 0), system.model.nq
        dq = np.abs(X[:, bq:nq] - rep.x[k, bq:nq])
        i, j = np.unravel_index(int(np.argmax(dq)), dq.shape)
        div["joint"] = {"max": float(dq[i, j]), "t": float(t[i]), "joint": system.state_names[bq + j]}
        firsts = [v["t"] for v in (rep.first_violation, run.violations[0] if run.violations else None) if v]
        if firsts:  # after a violation the two may part for good: the divergence on the way there
            before = t <= min(firsts)
            div["until"] = float(min(firsts))
            div["com_until"] = float(dc[before].max()) if before.any() else None
            div["joint_until"] = float(dq[before].max()) if before.any() else None
    mpg_bad = {(v["primitive"], v["h"]) for v in run.violations}
    worst = least_margins(prims, rep)
    mine = {"safe": rep.safe, "first_violation": rep.first_violation, "violation_samples": rep.violation_samples,
            "failed": rep.failed}
    theirs = _verdict_of(run)
    d = _decimate(len(t))
    least = np.asarray(run.min_h if len(run.min_h) == len(ok) else [None] * len(ok), dtype=float)[ok]
    return {
        "mode": run.mode, "agree": rep.safe == run.safe, "mujoco": mine, "mpgspec": theirs,
        "switches": rep.switches,
        "divergence": div,
        "worst": [{"primitive": p, "h": h, "mujoco": v, "t": tt, "violated_in_mpgspec": (p, h) in mpg_bad}
                  for p, h, v, tt in worst],
        "contact": rep.contact, "start_offset": rep.start_offset, "wall_s": rep.wall_s,
        "law_failures": dict(rep.law_failures),
        "series": {"t": t[d].tolist(), "com_z": {"mujoco": rep.com[k[d], 2].tolist(), "mpgspec": com[d, 2].tolist()},
                   "least_h": {"mujoco": rep.least_h[k[d]].tolist(), "mpgspec": least[d].tolist()}},
        "playback": _playback(rep, system.model.nq),
    }
