"""Names in a project's `uncertainty` block refer to the system and the primitives; located errors."""
from __future__ import annotations

import difflib

from ..errors import SpecError, SpecErrors
from ..spec.loader import ProjectSpec
from ..spec.project import node_refs


def _hint(word: str, choices) -> str:
    close = difflib.get_close_matches(str(word), sorted(choices), n=2)
    return f"did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def check_uncertainty(spec: ProjectSpec) -> None:
    """Raise SpecErrors for unknown parameters, inputs, states and primitives, a nominal value that
    is not the system's, an unsupported system kind and assertion kinds the robust graph cannot answer."""
    unc = spec.project.uncertainty
    if unc is None:
        return
    errors: list[SpecError] = []
    loc = lambda *k: spec.locate(("uncertainty", *k))  # noqa: E731
    sys = spec.system
    if getattr(sys, "kind", "analytic") != "analytic":
        errors.append(SpecError("uncertainty is supported for analytic systems only", location=loc(),
                                key="uncertainty", expected="an analytic system (states, dynamics)",
                                found=f"a {sys.kind} system", code="MPG104"))
        raise SpecErrors(errors)
    params = dict(sys.parameters)
    for name, pr in unc.parameters.items():
        if name not in params:
            errors.append(SpecError("unknown parameter", location=loc("parameters", name),
                                    key=f"uncertainty.parameters.{name}",
                                    expected="one of " + ", ".join(sorted(params)) if params else "no parameters",
                                    found=repr(str(name)[:60]), hint=_hint(name, params), code="MPG107"))
            continue
        if pr.nominal is not None and pr.nominal != params[name]:
            errors.append(SpecError("nominal differs from the system's value", location=loc("parameters", name, "nominal"),
                                    key=f"uncertainty.parameters.{name}.nominal", expected=f"{params[name]:g}",
                                    found=f"{pr.nominal:g}", code="MPG104"))
        elif not pr.range[0] <= params[name] <= pr.range[1]:
            errors.append(SpecError("the system's value lies outside the range", location=loc("parameters", name, "range"),
                                    key=f"uncertainty.parameters.{name}.range",
                                    expected=f"a range containing {params[name]:g}", found=f"{list(pr.range)}",
                                    code="MPG104"))
    if unc.disturbance is not None:
        for i, u in enumerate(unc.disturbance.inputs):
            if u not in sys.inputs:
                errors.append(SpecError("unknown input", location=loc("disturbance", "inputs", i),
                                        key=f"uncertainty.disturbance.inputs.{i}",
                                        expected="one of " + ", ".join(sys.inputs) if sys.inputs else "no inputs",
                                        found=repr(str(u)[:60]), hint=_hint(u, sys.inputs), code="MPG107"))
    for name in unc.initial_state:
        if name not in sys.states:
            errors.append(SpecError("unknown state", location=loc("initial_state", name),
                                    key=f"uncertainty.initial_state.{name}", expected="one of " + ", ".join(sys.states),
                                    found=repr(str(name)[:60]), hint=_hint(name, sys.states), code="MPG107"))
    nodes = {p.name for p in spec.primitives}

    def node(n: str, path: tuple, key: str):
        if n not in nodes:
            errors.append(SpecError("unknown primitive", location=loc(*path), key=f"uncertainty.{key}",
                                    expected="one of " + ", ".join(sorted(nodes)), found=repr(str(n)[:60]),
                                    hint=_hint(n, nodes), code="MPG304"))

    for i, a in enumerate(unc.assertions):
        base = ("assertions", i)
        refs = node_refs(a)
        for name, where in refs or ():
            node(name, base + where, ".".join(map(str, base + where)))
        if refs is None:
            errors.append(SpecError("this assertion does not apply to the robust graph", location=loc(*base),
                                    key=f"uncertainty.assertions.{i}", expected="edge, no_edge, plan or reachable_from",
                                    found=type(a).__name__, code="MPG104"))
    if errors:
        raise SpecErrors(errors)
