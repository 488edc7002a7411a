"""Fuzzing the spec loader and compiler: any YAML a pull request can contain gives a project or a
located spec error, never an internal error.

Hypothesis mutates the tiny CLI fixture project (scalar integrator, three primitives): it replaces
leaves by hostile values (wrong types, NaN, inf, huge numbers, long or broken expressions),
deletes keys, adds unknown ones, and writes expressions from a token alphabet. Each example is
loaded and compiled (CasADi symbolic construction, no oracle). A second project (BLOCKS) adds the
newer blocks: uncertainty (parameters, disturbance, start_in_roa, nodes, assertions, budget), clock
windows, typed verifier options and a cross-check; its examples also go through the checks the
pipeline runs on them before any work. Fixed budget (MPGSPEC_FUZZ_BUDGET examples each),
derandomised, so CI runs the same examples every time.
"""
from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from mpgspec.api import compile_project  # noqa: E402
from mpgspec.certify.roa import check_roa_specs  # noqa: E402
from mpgspec.errors import MpgError  # noqa: E402
from mpgspec.spec.loader import load_project  # noqa: E402
from mpgspec.spec.uncertainty_refs import check_uncertainty, check_uncertainty_compiled  # noqa: E402

BASE = yaml.safe_load((Path(__file__).parents[1] / "fixtures" / "cli_tiny" / "project.yaml").read_text())
BUDGET = int(__import__("os").environ.get("MPGSPEC_FUZZ_BUDGET", 300))
BLOCKS = copy.deepcopy(BASE)
BLOCKS["system"]["parameters"] = {"k": 2}
BLOCKS["primitives"][0]["controller"]["u"] = ["-k*(x - x_star)"]
BLOCKS["primitives"][0]["safe_set"].append({"name": "late", "h": "3 - x", "when": [0.5, 2.0]})
BLOCKS["primitives"][2]["roa"] = {"method": "sampling", "options": {"samples": 16, "rtol": 0.1, "r_max": 1.0}}
BLOCKS["crosscheck"] = {"simulator": "mujoco", "control_rate": 1000}
BLOCKS["uncertainty"] = {"parameters": {"k": {"nominal": 2, "range": [1.5, 2.5]}},
                         "disturbance": {"inputs": ["u"], "bound": [0.2]}, "samples": 2, "corners": 4, "search": 1,
                         "cells": 2, "runs": 2, "budget": 100000, "start_in_roa": {"samples": 2},
                         "nodes": ["Left", "Mid", "Right"], "assertions": [{"edge": {"from": "Left", "to": "Mid"}}]}

TOKENS = ["x", "u", "t", "s", "x_star", "pi", "e", "inf", "1", "0", "-1", "2.5", "1e308", "+", "-", "*", "/", "^",
          "(", ")", ",", " ", "<", ">=", "==", "and", "or", "not", "sin", "sqrt", "log", "abs", "min", "max",
          "clip", "if_else", "piecewise", "norm_2", "__import__", "os", ".", "[", "]", "'", '"', "lambda", "nan"]
HOSTILE = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=40), st.lists(st.integers(-3, 3), max_size=4), st.dictionaries(st.text(max_size=5), st.integers(), max_size=3),
    st.lists(st.sampled_from(TOKENS), max_size=25).map("".join),
    st.just("x" * 5000), st.just("(" * 300 + "x" + ")" * 300), st.just("+".join(["x"] * 1500)),
)


def _paths(node, prefix=()):
    """Every (path, value) in the nested dict/list structure."""
    yield prefix, node
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _set(doc, path, value):
    node = doc
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value


def _delete(doc, path):
    node = doc
    for p in path[:-1]:
        node = node[p]
    del node[path[-1]]


MUTATION = st.tuples(st.sampled_from(["replace", "delete", "add", "expr"]), st.integers(0, 10**6), HOSTILE)


def _mutate(doc, mutations) -> None:
    for kind, pick, value in mutations:
        paths = [p for p, _ in _paths(doc) if p]
        if not paths:
            break
        path = paths[pick % len(paths)]
        if kind == "replace":
            _set(doc, path, value)
        elif kind == "delete":
            _delete(doc, path)
        elif kind == "add":
            parent = [p for p, v in _paths(doc) if isinstance(v, dict)]
            _set(doc, parent[pick % len(parent)] + (f"extra_{pick % 7}",), value)
        else:  # an expression position gets token soup
            exprs = [p for p, v in _paths(doc) if isinstance(v, str) and p and p[-1] in ("h", "u", 0)]
            if exprs:
                _set(doc, exprs[pick % len(exprs)], value if isinstance(value, str) else str(value))


def _load_and_compile(tmp_path, doc, checks: bool = False) -> None:
    """doc written, loaded and compiled (with `checks`, also the pipeline's checks of the uncertainty
    and verifier blocks): a project or a located spec error, never anything else."""
    path = tmp_path / "project.yaml"
    try:
        path.write_text(yaml.safe_dump(doc, allow_unicode=True))
    except (ValueError, UnicodeEncodeError):  # a value YAML itself cannot represent
        return
    try:
        spec = load_project(path)
        if checks:
            check_roa_specs(spec)
            check_uncertainty(spec)
        prims = compile_project(spec)
        if checks:
            check_uncertainty_compiled(spec, prims)
    except MpgError as err:  # a spec error: located and printable
        assert err.format() if hasattr(err, "format") else str(err)


FUZZ = dict(max_examples=BUDGET, deadline=None, derandomize=True,
            suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@settings(**FUZZ)
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4))
def test_loader_and_compiler_never_fail_internally(tmp_path, mutations):
    doc = copy.deepcopy(BASE)
    _mutate(doc, mutations)
    _load_and_compile(tmp_path, doc)


@settings(**FUZZ)
@given(mutations=st.lists(MUTATION, min_size=1, max_size=4))
def test_the_newer_blocks_never_fail_internally(tmp_path, mutations):
    doc = copy.deepcopy(BLOCKS)
    _mutate(doc, mutations)
    _load_and_compile(tmp_path, doc, checks=True)
