"""Assemble the versioned JSON report of one project from the pipeline's results."""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import asdict

import numpy as np

from .. import __version__
from ..compile.primitive import CompiledPrimitive
from .compact import (METHODS, REASONS, STATUS, compact_cells, compact_run, compact_series, h_families, rnd,
                      trace_samples)
from .sections.registry import plugin_sections, report_sections

SCHEMA_VERSION = "2.2"


def _f(v):
    if v is None:
        return None
    v = float(v)
    return v if np.isfinite(v) else None


def finite_json(v):
    """A copy of v that strict JSON can hold: inf and NaN become None (null), numpy scalars and
    arrays plain numbers and lists, tuples lists, keys strings; anything else is kept as it is."""
    if isinstance(v, dict):
        return {k if isinstance(k, str) else str(k): finite_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        if all(type(x) is float for x in v):  # the long series of traces: one pass, no call per number
            return [x if -math.inf < x < math.inf else None for x in v]
        return [finite_json(x) for x in v]
    if isinstance(v, np.ndarray):
        return finite_json(v.tolist())
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    return v


def primitive_entry(p: CompiledPrimitive, spec, roa=None) -> dict:
    c = spec.controller
    rec = roa.to_dict() if roa is not None else {"method": "given", "level": "given", "message": "", "evidence": {}}
    return {
        "name": p.name, "class": p.cls.value, "period": _f(p.period),
        "domain": list(p.domain) if p.domain else None, "next": p.next,
        "controller": c.type, "safety_functions": p.h_names, "roa_radius": _f(p.radius),
        **({"roa_before_touchdown": {"window": float(spec.roa.before_touchdown.window),
                                     "radius": _f(p.radius * p.narrow_ratio)}} if p.narrow else {}),
        "roa_method": rec["method"], "roa_level": rec["level"], "roa_message": rec["message"],
        "roa_evidence": rnd(finite_json(rec["evidence"])), "horizon": _f(p.horizon), "setpoint_t0": [float(v) for v in p.x_star(p.t_range[0])],
        "description": spec.description.strip(), "info": p.info, "guards": p.guards.record(),
    }


def _round(v, digits: int = 6):
    v = _f(v)
    return None if v is None else float(f"{v:.{digits}g}")


def _least(margins: dict, names: list[str]):
    vals = [v for v in (_f(margins.get(k)) for k in names) if v is not None]
    return min(vals) if vals else None


def transition_entry(tr, h_names: list[str]) -> dict:
    """One ordered pair's grid, its cells by field (see compact.py); each cell's least margins are
    listed by family (h_families, or the target's safety functions when every family has one member;
    cells.violated indexes those functions, the target primitive's safety_functions). method: 'certified' when every cell the verdict rests on was proved
    (Transition.method); certified: the t_A intervals proved for every t_A in them, or None."""
    ev = tr.evidence
    families, members = h_families(h_names)
    cells = [[{"verdict": e.verdict, "status": e.status, "reason": e.reason.value, "t_stop": _round(e.t_stop),
               "t_enter": _round(e.t_enter), "violated": e.violated, "checked": e.checked, "refined": e.refined,
               "margin": _round(e.margin), "error_bound": _round(e.error_bound),
               # rounded once, by compact_cells (4 digits): the switching rule's reserve and keep compare
               # the in-memory values rounded the same way (graph.transition CELL_DIGITS)
               "peak_input": [_f(v) for v in e.peak_input], "peak_demand": [_f(v) for v in e.peak_demand],
               "saturated": e.saturated,
               "min_margins": [_least(e.min_margins, m) for m in members],
               "best_roa_margin": _round(e.best_roa_margin), "message": e.message, "method": e.method}
              for e in row] for row in ev]
    flat = [e for row in ev for e in row]
    return {
        "from": tr.source, "to": tr.target, "class": int(tr.cls), "method": tr.method,
        **({"h_families": families} if families != h_names else {}),
        "t_A": [float(t) for t in tr.t_A], "t_B": [float(t) for t in tr.t_B],
        "verdicts": tr.verdicts.tolist(), "cells": compact_cells(cells, h_names),
        "windows": [list(w) for w in tr.windows], "best_t_B": tr.best_t_B, "weights": tr.weights,
        **({"row_margins": [finite_json(m) for m in tr.row_margins]} if tr.row_margins else {}),
        **({"from_roa": {"rows": tr.row_from_roa, "worst": finite_json(tr.from_roa_worst)}} if tr.row_from_roa else {}),
        "counts": {"safe": sum(e.verdict for e in flat), "total": len(flat),
                   "inconclusive": sum(e.status == "inconclusive" for e in flat),
                   "refined": sum(e.refined for e in flat), "errors": sum(e.reason.value == "error" for e in flat),
                   "certified": sum(e.method == "certified" for e in flat),
                   "certified_safe": sum(e.verdict == 1 and e.method == "certified" for e in flat)},
        "certified": finite_json(tr.certified) or None,  # unrounded: rounding could widen a proved interval
    }


def verdict_counts(graph) -> dict:
    """Oracle calls of the whole graph by status, with the refined and errored ones."""
    flat = [e for tr in graph.transitions.values() for row in tr.evidence for e in row]
    return {"total": len(flat), **{k: sum(e.status == k for e in flat) for k in ("safe", "unsafe", "inconclusive")},
            "refined": sum(e.refined for e in flat), "errors": sum(e.reason.value == "error" for e in flat),
            "certified": sum(e.method == "certified" for e in flat)}


def edge_entries(graph) -> list[dict]:
    """Every verified edge with its weights and whether the planner may take it (a transient hands
    over only to its `next`, at the end of its domain)."""
    from ..plan.planner import WEIGHTS, plan_graph

    usable = plan_graph(graph)
    out = []
    for a, b, d in graph.G.edges(data=True):
        e = {"from": a, "to": b, "class": d["cls"], **{k: d[k] for k in WEIGHTS if k in d}}
        e["usable"] = usable.has_edge(a, b)
        if not e["usable"]:
            nd = graph.G.nodes[a]
            e["unusable_reason"] = (f"{a} is transient: it hands over only to {nd.get('next')} at the end of its "
                                    f"domain" if nd.get("cls") == "transient" else "not executable")
            if b == nd.get("next"):
                e["unusable_reason"] = f"{a} is transient and this switch is not safe from the end of its domain"
            tr = graph.edge(a, b)
            if nd.get("cls") != "transient" and getattr(tr, "row_from_roa", None):
                w = tr.from_roa_worst or {}
                e["unusable_reason"] = (f"no verified switch is safe from every sample of E_{a}'s boundary or of the "
                                        f"spheres at 1/2 and 1/4 of its radius (the executor leaves {a} from within "
                                        f"E_{a}): at t_A = {w.get('t_A')} {w.get('status')}, "
                                        f"{w.get('violated') or w.get('reason')}")
        out.append(e)
    return out


def build_report(cp, vg, ch, digest: str | None = None) -> dict:
    """The report dict of a project from its stages' results (mpgspec.pipeline: CompiledProject,
    VerifiedGraph, Checks); see mpgspec/report/schema/report-v2.json. digest: of the spec files (see
    mpgspec.spec.digest), so that readers can tell whether the report is up to date. Each registered
    report section adds its data (mpgspec.report.sections)."""
    spec, prims, graph = cp.spec, cp.prims, vg.graph
    sysm = spec.system
    csys = next(iter(prims.values())).system
    bounds = {n: [float(lo), float(hi)] for n, lo, hi in zip(csys.input_names, csys.u_lo, csys.u_hi)
              if np.isfinite(lo) or np.isfinite(hi)}
    per_trace = trace_samples(len(vg.failure_traces) + len(vg.edge_traces))
    return {**{
        "schema_version": SCHEMA_VERSION,
        "mpgspec_version": __version__,
        "generated_at": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "project": {"name": spec.name, "path": str(spec.path), "description": spec.project.description.strip(),
                    "digest": digest},
        "codes": {"status": list(STATUS), "reason": list(REASONS), "method": list(METHODS)},
        "status": ch.status,
        "settings": asdict(cp.settings),
        "system": {"name": sysm.name, "kind": sysm.kind, "states": list(csys.state_names),
                   "inputs": list(csys.input_names), "input_bounds": bounds},
        "primitives": [_with_crossings(primitive_entry(prims[i.name], i.spec, (cp.roa or {}).get(i.name)),
                                       vg.edge_traces + vg.failure_traces) for i in spec.primitives],
        "transitions": [transition_entry(tr, prims[tr.target].h_names) for tr in graph.transitions.values()],
        "verdicts": verdict_counts(graph),
        "edges": edge_entries(graph),
        "failures": [_traced(f, per_trace) for f in vg.failure_traces],
        "edge_traces": [_traced(f, per_trace) for f in vg.edge_traces],
        "plans": [p.to_dict() for p in ch.plans],
        "lookup_table": ch.table,
        "assertions": [a.to_dict() for a in ch.assertions],
        "assumptions": rnd(finite_json([a.to_dict() for a in ch.assumptions])),
        "sequence": _sequence_entry(spec.project.sequence, csys.state_names, ch.runs),
        "timing": {**cp.timing, **vg.timing, **ch.timing},
    }, **section_entries({name: s.data(cp, vg, ch) for name, s in report_sections().items()})}


def _sequence_entry(seq, state_names, runs: dict) -> dict | None:
    """The goal sequence and its runs (mode -> SequenceRun), stored by column."""
    if seq is None:
        return None
    return {"start": seq.start, "duration": seq.duration,
            "commands": [{"t": c.t, "goal": c.goal, **({"reference": list(c.reference)} if c.reference else {})}
                         for c in seq.commands],
            "state_names": list(state_names),
            "runs": {m: compact_run(finite_json(r.to_dict())) for m, r in runs.items()}}


def section_entries(data: dict[str, dict | None]) -> dict:
    """The report keys of the registered sections: each built-in one under its own key (null when
    the project has nothing to show), the plug-ins' under `sections` (only when one is registered)."""
    out, plugins = {}, {}
    for name, section in report_sections().items():
        d = data.get(name)
        d = None if d is None else rnd(finite_json(d))
        if section.top_level:
            out[name] = d
        elif d is not None:
            plugins[name] = d
    if plugin_sections():
        out["sections"] = plugins
    return out


def _with_crossings(entry: dict, traces: list[dict]) -> dict:
    """The primitive's guard record with the crossings located along the traced rollouts that run
    its closed loop (edge and failure traces into it): {located, rollouts}, for a loop stepped piece
    by piece."""
    counts = [t["series"]["crossings"]["count"] for t in traces
              if t.get("to") == entry["name"] and isinstance((t.get("series") or {}).get("crossings"), dict)]
    if counts:
        entry["guards"] = {**entry["guards"], "crossings": {"located": int(sum(counts)), "rollouts": len(counts)}}
    return entry


def _traced(f: dict, samples: int) -> dict:
    """A failure or edge trace with its rollout rounded and decimated for pictures."""
    f = finite_json(f)
    return {**rnd({k: v for k, v in f.items() if k != "series"}),
            "series": compact_series(f.get("series") or {}, f.get("t_stop"), f.get("violated"), samples)}
