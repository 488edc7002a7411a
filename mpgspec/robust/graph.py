"""The robust graph: each nominal edge's switch cells re-run under the project's uncertainty.

For every nominal transition A -> B (among `nodes`, when given), up to `cells` t_A rows that have
a verified t_B are taken (the t_B the plan would switch in at). Each such cell is run for a set of
scenarios: the corners of the box of uncertain parameters and start errors (at most `corners` of
them, seeded), its centre, `samples` seeded random points, each with the disturbance at 0, +bound
and -bound; then `search` rounds of an adversarial bang-bang disturbance from the worst scenario
(the sign of the gradient, through CasADi, of the binding h sample before entry and of the RoA
margin at entry; where the law gives no gradient, a rigid body or a sampled ID-QP, a coordinate
search that reverses one piece of one axis per candidate and keeps the worst).
With `start_in_roa`, every scenario also starts from seeded samples of the boundary of the source's
region of attraction E_A (starts.py), and the search continues from the worst start.
A cell is robust-safe when every scenario from every start is safe; the robust transition keeps
only those cells and is classified like the nominal one. This is falsification: a robust edge withstood every
scenario tried, it is not proven to withstand the whole set.
"""
from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from ..check.assertions import AssertionResult, evaluate_assertions
from ..compile.events import NEVER
from ..graph.transition import MotionPrimitiveGraph, Transition, TransitionClass
from ..plan.planner import lookup_table
from .rigid import RigidRobustRollout
from .rollout import RobustRollout, judge, judge_flow, plant
from .starts import Start, boundary_starts
from .sequence import sequence_under_uncertainty

LABEL = "empirical"
RECORD = 8
"""Layout of the memoised robust record (part of its key)."""
ROLLOUTS = 4096
"""At most this many rollouts are run (and their samples held) at once."""
NODE_STARTS = 2
"""A target's own flow is checked from x_B*(t_B) at this many of its cells' switch-in clocks (the
first and the last)."""
SETTLED = NEVER / 2
"""Time since switch-in at the start of a target's own-flow check: long settled, yet below the clock
of an event that has not happened (NEVER), which stays at rest."""
SAMPLED = "empirical (sampled)"
NOTE = ("falsification, not proof: a robust edge withstood every scenario tried (parameter-box corners, seeded "
        "samples and an adversarial disturbance search); no certificate backs it")


@dataclass
class RobustResult:
    """The robust graph, what each nominal edge withstood, and the robust assertions."""

    graph: MotionPrimitiveGraph
    edges: list[dict]
    assertions: list[AssertionResult]
    scenarios: dict
    timing: dict = field(default_factory=dict)
    sequence: dict | None = None  # safe fraction of the goal sequence per mode under sampled uncertainty
    nodes: list[dict] = field(default_factory=list)  # each target's own flow under the scenarios

    def to_dict(self) -> dict:
        survive = [e for e in self.edges if e["survives"]]
        return {"level": LABEL, "note": NOTE, "scenarios": self.scenarios,
                "summary": {"nominal_edges": len(self.edges), "robust_edges": len(survive),
                            "nominal_only": [f"{e['from']} -> {e['to']}" for e in self.edges if not e["survives"]]},
                "edges": self.edges, "nodes": self.nodes, "assertions": [a.to_dict() for a in self.assertions],
                "sequence": self.sequence,
                "timing": self.timing}


def _scenarios(unc, sys, rng: np.random.Generator, nominal: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                           list[str]]:
    """(theta (S, P), start error (S, nx), disturbance sign (S,), kind) of every scenario of a cell."""
    names = list(unc.parameters)
    lo = [unc.parameters[n].range[0] for n in names]
    hi = [unc.parameters[n].range[1] for n in names]
    nom = [nominal[n] for n in names]
    states = [sys.state_names.index(s) for s in unc.initial_state]
    eb = [float(unc.initial_state[s]) for s in unc.initial_state]
    lo, hi = np.array(lo + [-b for b in eb], float), np.array(hi + eb, float)
    centre = np.array(nom + [0.0] * len(eb), float)
    dim = len(lo)
    pts, kinds = [centre], ["nominal"]
    if dim:
        if 2 ** dim <= unc.corners:
            corners = np.array(list(itertools.product((0, 1), repeat=dim)), float)
        else:
            corners = rng.integers(0, 2, (unc.corners, dim)).astype(float)
        pts += list(lo + corners * (hi - lo))
        kinds += ["corner"] * len(corners)
        pts += list(lo + rng.random((unc.samples, dim)) * (hi - lo))
        kinds += ["sample"] * unc.samples
    pts = np.array(pts, float).reshape(-1, dim)
    signs = [0.0, 1.0, -1.0] if unc.disturbance is not None else [0.0]
    th, err, sg, kd = [], [], [], []
    for sgn in signs:
        for p, k in zip(pts, kinds):
            th.append(p[: len(names)])
            e = np.zeros(sys.nx)
            e[states] = p[len(names):]
            err.append(e)
            sg.append(sgn)
            kd.append(k if sgn == 0 else f"{k}, constant disturbance {'+' if sgn > 0 else '-'}bound")
    return np.array(th).reshape(-1, len(names)), np.array(err), np.array(sg), kd


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


def _node_check(B, rr, tbs: list[float], TH, ERR, D1, KIND, settings, tol, names, dist_names) -> dict:
    """Definition 1's premise under uncertainty: B's own flow from x_B*(t_B), at the clocks `tbs`
    its robust cells switch in at, stays in C_B for every scenario over the horizon (or the rest of a
    transient's domain), whether or not it settles in E_B. A robust cell checks the flow only up to
    E_B; Theorem 1 also needs B to keep it safe from there."""
    S = len(TH)
    hz = B.horizons(settings.horizon, tbs)
    ns = np.repeat(np.minimum(np.ceil(hz / settings.dt - 1e-9).astype(int), rr.N), S)
    X0 = np.concatenate([B.x_star(tb)[None, :] + ERR for tb in tbs])
    T0 = np.repeat(np.asarray(tbs, float), S)
    D = np.tile(D1, (len(tbs), 1, 1))
    # s since switch-in: long ago (a flow settled in B), so events the setpoint's clocks record count
    Y, last = rr.run(X0, T0, np.tile(TH, (len(tbs), 1)), D, ns, tol, until_entry=False, s0=SETTLED)
    res = [judge_flow(Y[r, :-1], int(min(ns[r], last[r])), tol) for r in range(len(X0))]
    r = min(range(len(X0)), key=lambda q: (res[q][0], res[q][1]))
    ok, low, k, j = res[r]
    binding = {"h": B.h_names[j], "value": float(low), "t": float(k * settings.dt)} if j is not None else None
    return {"node": B.name, "t_B": [float(t) for t in tbs], "scenarios": len(X0),
            "robust_safe": bool(all(x[0] for x in res)), "worst_margin": float(low),
            "worst_case": {"t_B": float(T0[r]), "kind": KIND[r % S], "parameters": dict(zip(names, map(float, TH[r % S]))),
                           "disturbance": {u: [float(v) for v in D[r][i]] for i, u in enumerate(dist_names)},
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


def _rows(tr: Transition, m: int) -> list[int]:
    avail = np.flatnonzero(tr.available)
    if len(avail) <= m:
        return [int(i) for i in avail]
    return sorted({int(avail[int(round(k))]) for k in np.linspace(0, len(avail) - 1, m)})


def robust_stage(cp, vg, progress=None, memo=None) -> RobustResult | None:
    """Build the robust graph of a compiled project and its nominal graph; None without `uncertainty`.

    memo (optional, mpgspec.oracle.cache.Memo) keeps the cell verdicts and sequence statistics by the
    content hash of the closed loops, the system, the uncertainty, the sequence and the settings.
    """
    spec, prims, settings, g = cp.spec, cp.prims, cp.settings, vg.graph
    unc = spec.project.uncertainty
    if unc is None:
        return None
    t0 = time.perf_counter()
    seq_spec = spec.project.sequence
    key = memo.key("robust", RECORD, *(p.digest() for p in prims.values()), spec.system.model_dump_json(),
                   unc.model_dump_json(), seq_spec.model_dump_json() if seq_spec else None,
                   sorted(dataclasses.asdict(settings).items())) if memo is not None else None
    known = memo.get(key) if memo is not None else None
    if known is not None:
        edges = known["edges"]
        rg = _robust_graph(g, edges, unc.nodes)
        return RobustResult(rg, edges, _assertions(unc, rg), known["scenarios"],
                            {"robust_s": time.perf_counter() - t0, "robust_cache_hit": 1.0}, known["sequence"],
                            known["nodes"])
    sys = next(iter(prims.values())).system
    names = list(unc.parameters)
    dist = unc.disturbance
    force = dist.force if dist is not None else None
    if sys.is_rigid_body:
        nominal_values = {"mass_scale": 1.0, "friction": float(sys.friction)}
        frame = force.frame if force is not None else sys.base_frames()[0]
        dist_names = [f"force_{a}" for a in "xyz"] if force is not None else []
        bound = np.asarray(force.bound, float) if force is not None else np.zeros(0)

        def rollout(B, horizon):
            return RigidRobustRollout(B, names, frame, force is not None, K, settings, horizon,
                                      force.duration if force is not None else None)
    else:
        nominal_values = dict(sys.parameters)
        P = plant(spec, names)
        dist_idx = [sys.input_names.index(u) for u in dist.inputs] if dist is not None else []
        dist_names = list(dist.inputs) if dist is not None else []
        bound = (np.broadcast_to(np.asarray(dist.bound, float), (len(dist_idx),)).copy() if dist is not None
                 else np.zeros(0))

        def rollout(B, horizon):
            return RobustRollout(B, P, dist_idx, K, settings, horizon)
    K = dist.segments if dist is not None else 1
    roa_starts = unc.start_in_roa
    rng = np.random.default_rng(unc.seed)
    TH, ERR, SG, KIND = _scenarios(unc, sys, rng, nominal_values)
    S = len(TH)
    tol = settings.h_tolerance
    among = set(unc.nodes) if unc.nodes is not None else set(prims)
    nominal = {(a, b): tr for (a, b), tr in g.transitions.items()
               if tr.cls is not TransitionClass.NONE and a in among and b in among}
    edges, nodes, n_roll, build_s = [], [], 0, 0.0
    by_target: dict[str, list] = {}
    for (a, b), tr in nominal.items():
        by_target.setdefault(b, []).append((a, tr))
    for bi, (b, items) in enumerate(by_target.items()):
        if progress:
            progress(spec.name, "robust graph", bi, len(by_target))
        B = prims[b]
        cells = []
        for a, tr in items:
            for i in _rows(tr, unc.cells):
                tb = tr.best_t_B[i]
                j = int(np.argmin(np.abs(tr.t_B - tb)))
                t_A = float(tr.t_A[i])
                starts = [Start(prims[a].x_star(t_A))]
                if roa_starts is not None:
                    starts += boundary_starts(prims[a], t_A, roa_starts.samples, roa_starts.seed)
                cells.append((a, tr, i, j, starts, float(tb)))
        hz = B.horizons(settings.horizon, [c[5] for c in cells])
        tb0 = time.perf_counter()
        rr = rollout(B, float(hz.max()))
        build_s += time.perf_counter() - tb0
        nsteps = np.minimum(np.ceil(hz / settings.dt - 1e-9).astype(int), rr.N)
        C = len(cells)
        D1 = (SG[:, None, None] * bound[None, :, None]) * np.ones((1, len(bound), K))
        worst = [None] * C  # per cell: its worst scenario so far, over every start
        pairs = [(c, s) for c in range(C) for s in cells[c][4]]
        per = max(1, ROLLOUTS // S)
        for q0 in range(0, len(pairs), per):
            chunk = pairs[q0:q0 + per]
            cs = np.repeat([c for c, _ in chunk], S)
            X0 = np.concatenate([s.x[None, :] + ERR for _, s in chunk])
            T0 = np.array([cells[c][5] for c in cs])
            THb, D = np.tile(TH, (len(chunk), 1)), np.tile(D1, (len(chunk), 1, 1))
            Y, last = rr.run(X0, T0, THb, D, nsteps[cs], tol)
            n_roll += len(X0)
            for q, (c, s) in enumerate(chunk):
                rs = range(q * S, (q + 1) * S)
                res = {r: judge(Y[r, :-1], Y[r, -1], int(min(nsteps[c], last[r])), tol) for r in rs}
                r = min(rs, key=lambda r: (res[r][0], res[r][1]))
                ok = all(res[p][0] for p in rs)
                w = worst[c]
                if w is None or (res[r][0], res[r][1]) < (w["safe"], w["margin"]):
                    worst[c] = {"margin": res[r][1], "safe": res[r][0], "entry": res[r][2], "x0": X0[r],
                                "t0": T0[r], "theta": THb[r], "D": D[r], "kind": KIND[r % S], "err": ERR[r % S],
                                "start": s, "all_safe": ok and (w is None or w["all_safe"]), "Y": Y[r].copy()}
                else:
                    w["all_safe"] = w["all_safe"] and ok
        for _ in range(unc.search if dist is not None else 0):
            live = [c for c in range(C) if worst[c]["all_safe"]]
            if not live:
                break
            if rr.grad is None:  # no gradient through the law (a sampled ID-QP, a rigid body): flip one piece
                cand = [(c, _flipped(worst[c]["D"], bound, a, k)) for c in live
                        for a in range(len(bound)) if bound[a] != 0 for k in range(K)]
            else:
                cand = _gradient_candidates(rr, worst, live, bound)
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
                             + ("" if rr.grad is not None else " (coordinate search)"))
                    w["all_safe"] = w["all_safe"] and ok
                    moved = True
            if not moved and rr.grad is None:  # the coordinate search sits at a local worst
                break
        tbs = sorted({round(c[5], 9) for c in cells})
        tbs = [tbs[int(round(k))] for k in np.linspace(0, len(tbs) - 1, min(NODE_STARTS, len(tbs)))]
        node = _node_check(B, rr, sorted(set(tbs)), TH, ERR, D1, KIND, settings, tol, names, dist_names)
        n_roll += node["scenarios"]
        nodes.append(node)
        per_edge: dict[str, list] = {}
        for c, (a, tr, i, j, starts, tb) in enumerate(cells):
            w = worst[c]
            wc = {"kind": w["kind"], "parameters": dict(zip(names, map(float, w["theta"]))),
                  "initial_error": {s: float(w["err"][sys.state_names.index(s)]) for s in unc.initial_state},
                  "disturbance": {u: [float(v) for v in w["D"][k]] for k, u in enumerate(dist_names)},
                  "binding": _binding(B, w["Y"], w["margin"], w["entry"], tol, settings.dt)}
            if roa_starts is not None:
                wc["start"] = _start_record(prims[a], float(tr.t_A[i]), w["start"], sys.state_names)
            per_edge.setdefault(a, []).append({"t_A": float(tr.t_A[i]), "t_B": tb, "robust_safe": bool(w["all_safe"]) and node["robust_safe"],
                                               "worst_margin": w["margin"], "worst_case": wc, "_ij": (i, j),
                                               "starts_kept": len(starts) - 1})
        for a, tr in items:
            checked = per_edge.get(a, [])
            margins = [c["worst_margin"] for c in checked]
            worst = min(checked, key=lambda c: c["worst_margin"]) if checked else None
            edges.append({"from": a, "to": b, "nominal_class": int(tr.cls), "rows_available": int(tr.available.sum()),
                          "target_flow_safe": node["robust_safe"],
                          "cells_checked": len(checked), "worst_margin": min(margins) if margins else None,
                          "worst_case": None if worst is None else {"t_A": worst["t_A"], "t_B": worst["t_B"],
                                                                   **worst["worst_case"]},
                          "cells": {"row": [int(c["_ij"][0]) for c in checked],  # t_A rows, at the nominal best t_B
                                    "robust_safe": [int(c["robust_safe"]) for c in checked], "worst_margin": margins}})
            if roa_starts is not None:
                kept = [c["starts_kept"] for c in checked]
                edges[-1]["cells"]["starts_kept"] = kept
                edges[-1]["start_in_roa"] = {"radius": float(prims[a].radius), "drawn": roa_starts.samples * len(kept),
                                             "kept": int(sum(kept))}
    rg = _robust_graph(g, edges, unc.nodes)
    scen = {"per_cell": S, "corners": KIND.count("corner"), "samples": unc.samples, "search_rounds": unc.search,
            "disturbance_segments": K, "parameters": {n: list(unc.parameters[n].range) for n in names},
            "initial_state": dict(unc.initial_state),
            "disturbance": None if dist is None else {"inputs": list(dist.inputs), "bound": bound.tolist()}
            if force is None else {"force": {"frame": force.frame, "bound": bound.tolist(),
                                             "duration": force.duration}},
            "nodes": sorted(among),
            "seed": unc.seed, "cells_per_edge": unc.cells, "start_in_roa": None}
    if roa_starts is not None:
        scen["start_in_roa"] = {"level": SAMPLED, "samples": roa_starts.samples, "seed": roa_starts.seed,
                                "drawn": sum(e["start_in_roa"]["drawn"] for e in edges),
                                "kept": sum(e["start_in_roa"]["kept"] for e in edges),
                                "projected": bool(sys.is_rigid_body)}
    t1 = time.perf_counter()
    seq = None
    if spec.project.sequence is not None and unc.runs > 0:
        if progress:
            progress(spec.name, "sequence under uncertainty", 0, 3)
        seq = sequence_under_uncertainty(spec, prims, settings, {"graph": (g, lookup_table(g)),
                                                                 "robust_graph": (rg, lookup_table(rg))},
                                         unc.runs, unc.seed)
    timing = {"robust_s": time.perf_counter() - t0, "robust_build_s": build_s, "robust_rollouts": n_roll,
              "robust_sequence_s": time.perf_counter() - t1}
    edges.sort(key=lambda e: (e["from"], e["to"]))
    if memo is not None:
        memo.put(key, {"edges": edges, "nodes": nodes, "scenarios": scen, "sequence": seq, "rollouts": n_roll})
    return RobustResult(rg, edges, _assertions(unc, rg), scen, timing, seq, nodes)


def _assertions(unc, rg: MotionPrimitiveGraph) -> list[AssertionResult]:
    checks = evaluate_assertions(unc.assertions, rg, {})
    for c in checks:
        c.kind = f"robust {c.kind}"
        c.description = f"robust: {c.description}"
    return checks


def _robust_graph(g: MotionPrimitiveGraph, edges: list[dict], nodes: list[str] | None = None) -> MotionPrimitiveGraph:
    """The nominal graph (on `nodes` only, when given) with each edge's transition cut to its robust
    cells; fills each edge record's robust class, windows and weights."""
    keep = set(g.G.nodes) if nodes is None else set(nodes)
    trs = {k: tr for k, tr in g.transitions.items() if k[0] in keep and k[1] in keep}
    for e in edges:
        tr = g.transitions[(e["from"], e["to"])]
        ok = {(i, int(np.argmin(np.abs(tr.t_B - tr.best_t_B[i]))))
              for i, safe in zip(e["cells"]["row"], e["cells"]["robust_safe"]) if safe}
        ev = [[x if (i, j) in ok else dataclasses.replace(x, verdict=0, status="unsafe") for j, x in enumerate(row)]
              for i, row in enumerate(tr.evidence)]
        rt = Transition(tr.source, tr.target, tr.t_A, tr.t_B, ev)
        rt.classify()
        trs[(e["from"], e["to"])] = rt
        e.update(robust_class=int(rt.cls), survives=rt.cls is not TransitionClass.NONE, cells_robust=len(ok),
                 robust_windows=[list(w) for w in rt.windows], robust_weights=dict(rt.weights))
    return MotionPrimitiveGraph({n: dict(g.G.nodes[n]) for n in g.G.nodes if n in keep}, trs)
