"""The switch cells of one target under the scenarios: run, worst case, adversarial search, records.

For a target B and its nominal in-edges A -> B, each cell (a t_A row at its best t_B) is run from
x_A*(t_A) (and from samples of E_A's boundary, with `start_in_roa`) for every scenario; the worst
scenario of each cell is then pushed by `search` rounds of an adversarial bang-bang disturbance.
B's own flow is checked under the same scenarios (_node_check). graph.py builds the robust graph
from the records made here. Each target is independent of the others: TargetJob carries what one
needs to a worker process (run_target, with the closed loops shared), and a target whose check raised gets the records of
failed_target, its error as the evidence of every cell.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..compile.events import NEVER
from ..graph.transition import Transition
from .rollout import judge, judge_flow
from .scenarios import Scenarios
from .starts import Start, boundary_starts

ROLLOUTS = 4096
"""At most this many rollouts are run (and their samples held) at once."""
SETTLED = NEVER / 2
"""Time since switch-in at the start of a target's own-flow check: long settled, yet below the clock
of an event that has not happened (NEVER), which stays at rest."""


def check_target(prims: dict, B, items: list, unc, settings, sc: Scenarios, rollout) -> tuple[list, dict, int, float]:
    """(edge records, B's own-flow record, rollouts run, seconds building the rollout) for target B
    and its nominal in-edges `items` [(A, transition, t_A rows to check)]; rollout(B, horizon) builds
    B's robust rollout."""
    cells = _cells(prims, items, unc)
    hz = B.horizons(settings.horizon, [c[5] for c in cells])
    tb0 = time.perf_counter()
    rr = rollout(B, float(hz.max()))
    build_s = time.perf_counter() - tb0
    nsteps = np.minimum(np.ceil(hz / settings.dt - 1e-9).astype(int), rr.N)
    tol = settings.h_tolerance
    worst, n_roll = _worst_cases(rr, cells, sc, nsteps, tol)
    n_roll += _search(rr, worst, sc, nsteps, tol, unc.search if unc.disturbance is not None else 0)
    decisive = any(w["all_safe"] for w in worst)  # else no edge into B depends on its own flow
    node = _node_check(B, rr, _node_clocks(cells), sc, settings, tol, decisive)
    n_roll += node["scenarios"]
    per_edge = _cell_records(prims, B, cells, worst, node, sc, unc, settings)
    edges = [_edge_record(a, B.name, tr, per_edge.get(a, []), node, prims, unc) for a, tr, _rows in items]
    return edges, node, n_roll, build_s


@dataclass
class TargetJob:
    """One target's robust check, picklable and small: B's name, its nominal in-edges [(A,
    transition, t_A rows to check)], the uncertainty, the settings, the scenarios and the rollout factory
    (rollout(B, horizon), picklable). The closed loops travel apart, once per worker."""

    target: str
    items: list
    unc: object
    settings: object
    sc: Scenarios
    rollout: object


def run_target(prims: dict, job: TargetJob) -> tuple[list, dict, int, float]:
    """check_target of the job with the project's closed loops (the function an executor maps
    over targets, the closed loops shared)."""
    return check_target(prims, prims[job.target], job.items, job.unc, job.settings, job.sc, job.rollout)


def job_cost(job: TargetJob) -> float:
    """About how many rollouts the job runs (its cells' scenarios and its own flow's): what orders
    a merged map, the costliest first."""
    cells = sum(len(rows) for _a, _tr, rows in job.items)
    return float((cells + 1) * job.sc.S)


def failed_target(prims: dict, b: str, items: list, unc, error: str) -> tuple[list, dict]:
    """(edge records, own-flow record) of a target whose check raised: the error is the evidence of
    each of its cells and of its own flow, none robust-safe (as a rollout that blew up is unsafe)."""
    node = {"node": b, "t_B": [], "scenarios": 0, "stopped": 0, "robust_safe": False, "worst_margin": -math.inf,
            "worst_case": {"error": error}}
    edges = []
    for a, tr, rows in items:
        checked = [{"t_A": float(tr.t_A[i]), "t_B": float(tr.best_t_B[i]), "robust_safe": False,
                    "worst_margin": -math.inf, "worst_case": {"kind": "error", "error": error},
                    "_ij": (i, int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i])))), "starts_kept": 0, "stopped": 0}
                   for i in rows]
        edges.append(_edge_record(a, b, tr, checked, node, prims, unc))
    return edges, node


def _cells(prims: dict, items: list, unc) -> list[tuple]:
    """(A, transition, t_A row i, t_B column j, starts, t_B) of every cell checked."""
    cells = []
    for a, tr, rows in items:
        for i in rows:
            tb = tr.best_t_B[i]
            j = int(np.argmin(np.abs(tr.t_B - tb)))
            t_A = float(tr.t_A[i])
            starts = [Start(prims[a].x_star(t_A))]
            if unc.start_in_roa is not None:
                starts += boundary_starts(prims[a], t_A, unc.start_in_roa.samples, unc.start_in_roa.seed)
            cells.append((a, tr, i, j, starts, float(tb)))
    return cells


def _worst_cases(rr, cells: list, sc: Scenarios, nsteps: np.ndarray, tol: float) -> tuple[list[dict], int]:
    """Per cell its worst scenario over every start (least (safe, margin), the first of equals), and
    the rollouts run; `all_safe` says whether every scenario from every start was safe. A cell is one
    decision: once one of its rollouts is unsafe the others stop undecided, and its scenarios run in
    waves (sc.waves: the box's corners first), a wave only when every rollout of the ones before
    was safe; `stopped` counts the rollouts so left undecided, and the worst case is the worst of
    those decided."""
    worst: list = [None] * len(cells)
    all_safe, stopped = [True] * len(cells), [0] * len(cells)
    n_roll = 0
    waves, D1 = sc.waves(), sc.D1  # the same for every batch
    for chunk in _cell_batches([c[4] for c in cells], max(1, ROLLOUTS // sc.S)):
        for wave in waves:
            rows = [(c, s, k) for c, s in chunk if all_safe[c] for k in wave]
            for c, _s in chunk:  # a cell already lost leaves this wave undecided
                stopped[c] += 0 if all_safe[c] else len(wave)
            if not rows:
                continue
            n_roll += len(rows)
            cs = np.array([c for c, _, _ in rows])
            X0 = np.array([s.x + sc.ERR[k] for _, s, k in rows])
            T0 = np.array([cells[c][5] for c in cs])
            ks = [k for *_, k in rows]
            TH, D = sc.TH[ks], D1[ks]
            Y, last, cut = rr.run_groups(X0, T0, TH, D, nsteps[cs], tol, groups=cs)
            for r, (c, s, k) in enumerate(rows):
                if cut[r]:
                    stopped[c] += 1
                    continue
                safe, margin, entry = judge(Y[r, :-1], Y[r, -1], int(min(nsteps[c], last[r])), tol)
                all_safe[c] = all_safe[c] and safe
                w = worst[c]
                if w is None or (safe, margin) < (w["safe"], w["margin"]):  # only a new worst keeps its samples
                    worst[c] = {"margin": margin, "safe": safe, "entry": entry, "x0": X0[r], "t0": T0[r],
                                "theta": TH[r], "D": D[r], "kind": sc.KIND[k], "err": sc.ERR[k], "start": s,
                                "Y": Y[r].copy()}
    for c, w in enumerate(worst):
        w.update(stopped=stopped[c], all_safe=all_safe[c] and not stopped[c])
    return worst, n_roll


def _cell_batches(starts: list[list], per: int) -> list[list[tuple]]:
    """The (cell, start) pairs in batches of at most `per`: a cell is never split with another (its
    rollouts stop together); one with more than `per` starts is cut into pieces of `per` of its own.
    So which rollouts run together, and stop together, depends on the cell alone."""
    batches, cur = [], []
    for c, ss in enumerate(starts):
        pairs = [(c, s) for s in ss]
        if len(cur) + len(pairs) > per:
            batches += [cur] if cur else []
            cur = []
        if len(pairs) > per:
            batches += [pairs[k:k + per] for k in range(0, len(pairs), per)]
        else:
            cur += pairs
    return batches + ([cur] if cur else [])


def _search(rr, worst: list[dict], sc: Scenarios, nsteps: np.ndarray, tol: float, rounds: int) -> int:
    """`rounds` of the adversarial bang-bang search from each still-safe cell's worst case (by the
    gradient, else a coordinate search); updates `worst` and returns the rollouts run."""
    n_roll = 0
    for _ in range(rounds):
        live = [c for c in range(len(worst)) if worst[c]["all_safe"]]
        if not live:
            break
        if not rr.searchable:  # no gradient through the law (a sampled ID-QP, a rigid body): flip one piece
            cand = [(c, _flipped(worst[c]["D"], sc.bound, a, k)) for c in live
                    for a in range(len(sc.bound)) if sc.bound[a] != 0 for k in range(sc.K)]
        else:
            cand = _gradient_candidates(rr, worst, live, sc.bound)
        if not cand:
            break
        Xc = np.array([worst[c]["x0"] for c, _ in cand])
        Yc, lc = rr.run(Xc, np.array([worst[c]["t0"] for c, _ in cand]),
                        np.array([worst[c]["theta"] for c, _ in cand]).reshape(len(cand), -1),
                        np.array([Dn for _, Dn in cand]), np.array([nsteps[c] for c, _ in cand]), tol)
        n_roll += len(cand)
        moved = False
        for q, (c, Dn) in enumerate(cand):
            ok, m, k_e = judge(Yc[q, :-1], Yc[q, -1], int(min(nsteps[c], lc[q])), tol)
            w = worst[c]
            if (ok, m) < (w["safe"], w["margin"]):
                w.update(margin=m, safe=ok, entry=k_e, D=Dn, Y=Yc[q], kind="adversarial bang-bang disturbance"
                         + ("" if rr.searchable else " (coordinate search)"))
                w["all_safe"] = w["all_safe"] and ok
                moved = True
        if not moved and not rr.searchable:  # the coordinate search sits at a local worst
            break
    return n_roll


def _node_clocks(cells: list) -> list[float]:
    """Every clock the cells switch in at: the own flow is checked from each."""
    return sorted({round(c[5], 9) for c in cells})


def _cell_records(prims: dict, B, cells: list, worst: list[dict], node: dict, sc: Scenarios, unc,
                  settings) -> dict[str, list]:
    """Source -> the record of each of its cells: robust-safe or not, worst margin and worst case."""
    per_edge: dict[str, list] = {}
    tol = settings.h_tolerance
    for c, (a, tr, i, j, starts, tb) in enumerate(cells):
        w = worst[c]
        wc = {"kind": w["kind"], "parameters": dict(zip(sc.names, map(float, w["theta"]))),
              "initial_error": {s: float(w["err"][sc.state_names.index(s)]) for s in unc.initial_state},
              "disturbance": {u: [float(v) for v in w["D"][k]] for k, u in enumerate(sc.dist_names)},
              "binding": _binding(B, w["Y"], w["margin"], w["entry"], tol, settings.dt)}
        if unc.start_in_roa is not None:
            wc["start"] = _start_record(prims[a], float(tr.t_A[i]), w["start"], sc.state_names)
        per_edge.setdefault(a, []).append({"t_A": float(tr.t_A[i]), "t_B": tb,
                                           "robust_safe": bool(w["all_safe"]) and bool(node["robust_safe"]),
                                           "worst_margin": w["margin"], "worst_case": wc, "_ij": (i, j),
                                           "starts_kept": len(starts) - 1, "stopped": w["stopped"]})
    return per_edge


def _edge_record(a: str, b: str, tr: Transition, checked: list[dict], node: dict, prims: dict, unc) -> dict:
    """The robust record of the nominal edge a -> b from its checked cells."""
    margins = [c["worst_margin"] for c in checked]
    worst = min(checked, key=lambda c: c["worst_margin"]) if checked else None
    edge = {"from": a, "to": b, "nominal_class": int(tr.cls), "rows_available": int(tr.available.sum()),
            "target_flow_safe": node["robust_safe"],
            "cells_checked": len(checked), "worst_margin": min(margins) if margins else None,
            "worst_case": None if worst is None else {"t_A": worst["t_A"], "t_B": worst["t_B"],
                                                     **worst["worst_case"]},
            "cells": {"row": [int(c["_ij"][0]) for c in checked],  # t_A rows, at the nominal best t_B
                      "robust_safe": [int(c["robust_safe"]) for c in checked], "worst_margin": margins,
                      "stopped": [int(c["stopped"]) for c in checked]}}
    if unc.start_in_roa is not None:
        kept = [c["starts_kept"] for c in checked]
        edge["cells"]["starts_kept"] = kept
        edge["start_in_roa"] = {"radius": float(prims[a].radius), "drawn": unc.start_in_roa.samples * len(kept),
                                "kept": int(sum(kept))}
    return edge


def _start_record(prim, t_A: float, start: Start, state_names: list[str]) -> dict:
    """Which start of a cell its worst case came from: a sample of E_A's boundary (its index, weighted
    distance, E_A's radius and the offset from x_A*(t_A) by state) or x_A*(t_A) itself (sample None)."""
    dx = start.x - prim.x_star(t_A)
    return {"sample": start.sample, "weighted_distance": float(start.distance), "radius": float(prim.radius),
            "offset": {n: float(v) for n, v in zip(state_names, dx) if v != 0.0}}


def _binding(prim, Y: np.ndarray, margin: float, entry: int | None, tol: float, dt: float) -> dict:
    """What decided a worst case: the safety function with the least value before entry (or over the
    rollout, when it broke one), with that value and its time after the switch; or, when the flow
    stayed safe without entering E_B, the best RoA margin it reached."""
    H = Y[:-1, : (entry + 1 if entry is not None else Y.shape[1])]
    H = H[:, ~np.isnan(H).all(axis=0)] if H.size else H  # samples after a decided rollout are NaN
    if H.size:
        Hf = np.where(np.isfinite(H), H, -np.inf)
        j, k = np.unravel_index(int(np.argmin(Hf)), Hf.shape)
        if entry is not None or Hf[j, k] < -tol:
            return {"h": prim.h_names[j], "value": float(Hf[j, k]), "t": float(k * dt)}
    return {"h": None, "roa_margin": float(margin)}


def _node_check(B, rr, tbs: list[float], sc: Scenarios, settings, tol, decisive: bool = True) -> dict:
    """Definition 1's premise under uncertainty: B's own flow from x_B*(t_B), at the clocks `tbs`
    its robust cells switch in at, stays in C_B for every scenario over the horizon (or the rest of a
    transient's domain), whether or not it settles in E_B. A robust cell checks the flow only up to
    E_B; Theorem 1 also needs B to keep it safe from there. Not `decisive` (no cell into B withstood
    its scenarios, so no edge depends on this check): the first wave only (sc.waves: the box's
    corners), `robust_safe` None when it was safe (the rest, `not_run`, would decide nothing)."""
    run = np.arange(sc.S) if decisive else sc.waves()[0]  # a box of one wave: every scenario
    TH, ERR, D1, S = sc.TH[run], sc.ERR[run], sc.D1[run], len(run)
    hz = B.horizons(settings.horizon, tbs)
    ns = np.repeat(np.minimum(np.ceil(hz / settings.dt - 1e-9).astype(int), rr.N), S)
    X0 = np.concatenate([B.x_star(tb)[None, :] + ERR for tb in tbs])
    T0 = np.repeat(np.asarray(tbs, float), S)
    D = np.tile(D1, (len(tbs), 1, 1))
    # s since switch-in: long ago (a flow settled in B), so events the setpoint's clocks record count;
    # one decision: once a scenario breaks C_B the others stop
    Y, last, cut = rr.run_groups(X0, T0, np.tile(TH, (len(tbs), 1)), D, ns, tol, until_entry=False, s0=SETTLED,
                                 groups=np.zeros(len(X0), int))
    res = {q: judge_flow(Y[q, :-1], int(min(ns[q], last[q])), tol) for q in range(len(X0)) if not cut[q]}
    r = min(res, key=lambda q: (res[q][0], res[q][1]))
    ok, low, k, j = res[r]
    binding = {"h": B.h_names[j], "value": float(low), "t": float(k * settings.dt)} if j is not None else None
    safe = not cut.any() and all(x[0] for x in res.values())
    not_run = (sc.S - S) * len(tbs)
    kind = sc.KIND[int(run[r % S])]
    return {"node": B.name, "t_B": [float(t) for t in tbs], "scenarios": len(X0), "stopped": int(cut.sum()),
            "not_run": not_run, "robust_safe": (None if safe and not_run else bool(safe)), "worst_margin": float(low),
            "worst_case": {"t_B": float(T0[r]), "kind": kind, "parameters": dict(zip(sc.names, map(float, TH[r % S]))),
                           "disturbance": {u: [float(v) for v in D[r][i]] for i, u in enumerate(sc.dist_names)},
                           "binding": binding}}


def _gradient_candidates(rr, worst: list, live: list[int], bound: np.ndarray) -> list:
    """Per live cell two bang-bang disturbances: against the gradient of the binding h sample before
    entry and of the RoA margin at entry (the sign of each piece's derivative, through CasADi)."""
    targets = []
    for c in live:
        w = worst[c]
        Hs = w["Y"][:-1, : w["entry"] + 1]
        jh, kh = np.unravel_index(int(np.argmin(Hs)), Hs.shape) if Hs.size else (0, 0)
        targets += [(c, int(jh), int(kh)), (c, rr.nh, int(w["entry"]))]
    gr = rr.gradients(np.array([worst[c]["x0"] for c, _, _ in targets]),
                      np.array([worst[c]["t0"] for c, _, _ in targets]),
                      np.array([worst[c]["theta"] for c, _, _ in targets]),
                      np.array([worst[c]["D"] for c, _, _ in targets]),
                      [r for _, r, _ in targets], [k for _, _, k in targets])
    return [(c, np.where(gd != 0, -np.sign(gd) * bound[:, None], worst[c]["D"])) for (c, _, _), gd in zip(targets, gr)]


def _flipped(D: np.ndarray, bound: np.ndarray, a: int, k: int) -> np.ndarray:
    """D with piece k of axis a reversed (set to +bound where it was 0): one move of the coordinate
    search for a bang-bang disturbance when no gradient is available."""
    Dn = np.array(D, float)
    Dn[a, k] = -Dn[a, k] if Dn[a, k] != 0 else bound[a]
    return Dn


def cell_rows(tr: Transition, m: int, taken: list | None = None) -> list[int]:
    """Up to m t_A rows of a transition to check, spread evenly over those the executor switches through
    (`taken`: per t_A the t_B it switches in at, or None), else over every verified row: a robust cell is
    a switch the executor may make."""
    avail = np.flatnonzero(tr.available)
    usable = [i for i in avail if taken is not None and taken[i] is not None]
    avail = np.array(usable, int) if usable else avail
    if len(avail) <= m:
        return [int(i) for i in avail]
    return sorted({int(avail[int(round(k))]) for k in np.linspace(0, len(avail) - 1, m)})
