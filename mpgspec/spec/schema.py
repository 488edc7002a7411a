"""JSON Schemas of the spec files for editors and CI: project.yaml, a primitive file and a system
file, each with $schema, $id and a description on every property.

Point an editor at one with a first line such as
`# yaml-language-server: $schema=../project.schema.json` (write it with `mpgspec schema > ...`).
"""
from __future__ import annotations

import copy

BASE_ID = "https://mpgspec.invalid/schema/"
KINDS = ("project", "primitive", "system")

# Descriptions of properties whose model field has none (by property name).
DESCRIPTIONS = {
    "Q": "LQR state weight: a states x states matrix (or its diagonal)",
    "R": "LQR input weight: an inputs x inputs matrix (or its diagonal)",
    "accuracy": "oracle accuracy preset: low | medium | high | very_high (finer steps, more refinement)",
    "alpha": "Baumgarte velocity gain of the contact constraint",
    "assertions": "what must hold of the graph, plans and sequence runs; each failure fails the project",
    "baumgarte": "contact drift stabilisation: J a + Jdot v = -2 alpha J v - beta^2 z_foot",
    "beta": "Baumgarte position gain of the contact constraint",
    "class": "fixed (a set point), periodic (needs period) or transient (needs domain and next); "
             "in an edge assertion: the required transition class, 1 or 2",
    "commands": "goals of the sequence: at time t switch towards goal",
    "controller": "the control law k(x, t): expression, pd, lqr, id_qp, ...",
    "description": "free text shown in the report",
    "disturbance": "bounded disturbance or parameter uncertainty the transitions must tolerate",
    "domain": "clock interval [t_0, t_f] of a transient primitive (seconds)",
    "duration": "length in seconds",
    "dynamics": "xdot = f(x) + g(x) u (control-affine) or a full xdot",
    "edge": "a transition that must exist: from, to and optionally its class and evidence (simulated | certified)",
    "eq": "an equality constraint expression, held within tol",
    "expect": "the expected outcome (true: safe)",
    "expr": "one expression per state, in the primitive's clock t",
    "f": "drift term f(x), one expression per state",
    "feedforward": "feedforward input terms added to the PD law, one per output",
    "feet": "feet in contact during this phase",
    "floating_base": "whether the robot's base is a free-floating joint",
    "friction": "Coulomb friction coefficient of the feet",
    "from": "source primitive",
    "g": "input matrix g(x): states x inputs expressions; in parameters: gravity",
    "goal": "primitive to reach",
    "grid": "oracle grid sizes: number of t_A and t_B samples",
    "h": "safety function h(x, t); the safe set is h >= 0",
    "horizon": "longest oracle rollout in seconds",
    "inputs": "input names",
    "interpolation": "how samples are interpolated: linear or cubic",
    "kd": "derivative gains, one per output",
    "kind": "analytic (closed-form dynamics) or rigid_body (a URDF robot)",
    "kp": "proportional gains, one per output",
    "matrix": "the full weight matrix W of the region of attraction",
    "max_cost": "largest allowed plan cost",
    "max_inconclusive": "most oracle calls that may stay inconclusive",
    "max_iter": "iteration limit of the solver",
    "name": "name (a node of the graph for primitives; a safety function's name in the report)",
    "next": "primitive a transient hands over to at the end of its domain",
    "no_edge": "a transition that must not exist: from, to",
    "oracle": "oracle settings: horizon, dt, accuracy, grid, method",
    "parameters": "named constants usable in expressions",
    "period": "period of a periodic primitive: an expression in seconds",
    "plan": "a plan that must exist: from, to, weight, max_cost",
    "posture_kd": "posture task derivative gain",
    "posture_kp": "posture task proportional gain",
    "posture_weight": "weight of the posture task in the QP",
    "primitives": "primitive files (or inline primitives) of the project",
    "profile": "cubic motion profile from the state at switch-in (eq. 7): its duration",
    "profile_duration": "duration of the cubic motion profile in seconds",
    "project": "project name: a safe identifier, also the report folder's name",
    "radius": "radius r of E = {||W^(1/2)(x - x*(t))|| < r}",
    "range": "range of values",
    "reachable_from": "every primitive must be reachable from this one",
    "regularization": "Tikhonov regularisation of the QP",
    "require": "least level of evidence for the radius: certified | empirical | given",
    "roa": "the explicit safe region of attraction E: radius, weights or matrix, or a method computing it",
    "safe_set": "the safe set C: safety functions h >= 0 (or reusable blocks via `use`)",
    "safe_sets": "reusable blocks of safety functions, used as `- use: NAME`",
    "samples": "setpoint samples, one row per time; or a sample count",
    "seed": "random seed",
    "sequence": "a goal sequence to run naive and through the graph",
    "setpoint": "the setpoint x*(t): expressions, samples, or a CSV file",
    "simulation_safe": "mode (naive | graph) whose sequence run must be safe (or unsafe with expect: false)",
    "start": "primitive the sequence starts in",
    "states": "state names",
    "system": "the system: a system file or an inline system",
    "t": "time in seconds",
    "t_A": "samples of the source clock t_A",
    "t_B": "samples of the target clock t_B",
    "times": "sample times in seconds",
    "to": "target primitive",
    "tol": "tolerance",
    "type": "kind of this block",
    "u": "one expression per input",
    "until": "end of this phase in the primitive's clock (seconds)",
    "weight": "plan weight: duration, peak_input or hops",
    "weights": "diagonal of the weight matrix W of E",
    "when": "window in which the safety function is active: [a, b] on the clock, or anchored on a contact "
            "event: {before: E}, {after: E, delay: d, for: l} (E: first_touchdown | takeoff)",
}


def _clean(node, name: str | None = None):
    """Drop `discriminator` (editors report every branch of a union otherwise), fill descriptions."""
    if isinstance(node, dict):
        node.pop("discriminator", None)
        for k, v in list(node.items()):
            if k == "properties" and isinstance(v, dict):
                for prop, sub in v.items():
                    _clean(sub, prop)
                    if isinstance(sub, dict) and "description" not in sub:
                        sub["description"] = DESCRIPTIONS.get(prop, prop.replace("_", " "))
            else:
                _clean(v)
    elif isinstance(node, list):
        for v in node:
            _clean(v)
    return node


def _model(kind: str):
    if kind == "project":
        from .models import Project

        return Project
    if kind == "primitive":
        from .primitive import Primitive

        return Primitive
    if kind == "system":
        from pydantic import TypeAdapter

        from .system import System

        return TypeAdapter(System)
    raise ValueError(f"unknown schema kind {kind!r}; expected one of {', '.join(KINDS)}")


def spec_schema(kind: str = "project") -> dict:
    """JSON Schema (draft 2020-12) of a project, primitive or system file."""
    m = _model(kind)
    raw = m.json_schema(by_alias=True) if hasattr(m, "json_schema") else m.model_json_schema(by_alias=True)
    raw = _clean(copy.deepcopy(raw))
    title = {"project": "mpgspec project (project.yaml)", "primitive": "mpgspec motion primitive file",
             "system": "mpgspec system file"}[kind]
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": f"{BASE_ID}{kind}.json",
            "title": title, **{k: v for k, v in raw.items() if k != "title"}}
