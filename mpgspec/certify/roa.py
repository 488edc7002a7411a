"""Give every primitive its E: the spec's radius, or one a verifier certified or estimated.

A radius from a verifier replaces the spec's; when the spec also gives a radius and it is larger
than the verified one, the smaller one is used and the record says so. A verifier that fails
leaves the spec's radius (labelled 'given') or, without one, an empty E (radius 0): no flow can
enter it, so no transition into the primitive is claimed. A level-set verifier's region is recorded
as {V <= rho} and as the W-ball inside it; with `roa.options.region: level_set` E is the level set
itself (level_set.py). A spec's `require: certified` turns on `require_certified` of a verifier
that reads it (lyapunov's certified route).
"""
from __future__ import annotations

import dataclasses
import difflib
import time
from dataclasses import dataclass, field

import numpy as np
from pydantic import ValidationError

from ..compile.primitive import CompiledPrimitive
from ..errors import SpecError, SpecErrors
from ..oracle.executors import InProcess
from ..oracle.tasks import Failed
from ..spec.loader import ProjectSpec
from .level_set import level_set_of, use_level_set
from .problem import RoAResult, from_primitive
from .registry import accepted_options, option_model, roa_methods

RANK = {"certified": 3, "empirical": 2, "given": 1, "failed": 0}


@dataclass
class RoARecord:
    """How one primitive's radius was obtained."""

    primitive: str
    method: str
    level: str
    radius: float
    spec_radius: float | None = None
    message: str = ""
    evidence: dict = field(default_factory=dict)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _estimate(method: str, prim: CompiledPrimitive, options: dict) -> RoAResult:
    verifiers = roa_methods()
    if method not in verifiers:
        raise KeyError(f"no RoA verifier {method!r}; installed: {', '.join(sorted(verifiers))}")
    W = np.asarray(prim.W)
    return verifiers[method].estimate(from_primitive(prim, weights=W), dict(options))


def _did_you_mean(word: str, choices) -> str:
    close = difflib.get_close_matches(word, sorted(choices), n=2)
    return f"did you mean {' or '.join(repr(c) for c in close)}?" if close else ""


def _check_values(model, inst, owner: str, roa, errors: dict) -> None:
    """Type and range of each known option of a built-in verifier, as located spec errors (MPG104)."""
    try:
        model.model_validate({k: v for k, v in roa.options.items() if k in model.model_fields})
    except ValidationError as e:
        for x in e.errors():
            key = str(x["loc"][0]) if x["loc"] else ""
            field = model.model_fields.get(key)
            err = SpecError(f"invalid option of the {roa.method} verifier: {x['msg']}",
                            location=inst.locate(("roa", "options", key) if key else ("roa", "options")),
                            key=f"{owner}: roa.options.{key}",
                            expected=(field.description or str(field.annotation)) if field else "",
                            found=repr(roa.options.get(key))[:60], code="MPG104")
            errors.setdefault(err.format(), err)


def check_roa_specs(spec: ProjectSpec) -> None:
    """Every `roa.method` names an installed verifier (or 'given'), every `roa.options` key is one
    the verifier reads and, for verifiers with typed options, every value has its type and range;
    raises SpecErrors naming each wrong value, with a suggestion."""
    verifiers = roa_methods()
    methods = sorted({"given", *verifiers})
    errors: dict[str, SpecError] = {}
    for inst in spec.primitives:
        roa = inst.spec.roa
        owner = f"primitive '{inst.base}'"
        if roa.method not in methods:
            err = SpecError("unknown region-of-attraction method", location=inst.locate(("roa", "method")),
                            key=f"{owner}: roa.method", expected="one of " + ", ".join(methods),
                            found=repr(roa.method[:60]), hint=_did_you_mean(roa.method, methods), code="MPG104")
            errors.setdefault(err.format(), err)
            continue
        accepted = frozenset() if roa.method == "given" else accepted_options(roa.method)
        if accepted is None:
            continue
        model = None if roa.method == "given" else option_model(roa.method)
        if model is not None:
            _check_values(model, inst, owner, roa, errors)
        for key in roa.options:
            if key in accepted:
                continue
            what = ("a radius given by the spec takes no options" if roa.method == "given"
                    else f"unknown option of the {roa.method} verifier")
            err = SpecError(what, location=inst.locate(("roa", "options", key)), key=f"{owner}: roa.options.{key}",
                            expected="one of " + ", ".join(sorted(accepted)) if accepted else "no options",
                            found=repr(str(key)[:60]), hint=_did_you_mean(str(key), accepted), code="MPG102")
            errors.setdefault(err.format(), err)
    if errors:
        raise SpecErrors(list(errors.values()))


def size_regions(spec: ProjectSpec, prims: dict[str, CompiledPrimitive], memo=None, executor=None,
                 progress=None) -> dict[str, RoARecord]:
    """Run each primitive's RoA method; recompile primitives whose radius changed (in place).

    The methods and options are checked first (check_roa_specs). memo (optional, with
    key/get/put) keeps records by the primitive's content hash, method and options, so an
    unchanged primitive is not sized again. Primitives whose method only simulates (its verifier says
    `simulates = True`: no solver threads, which a forked worker could inherit mid-use) are spread
    over the executor's workers (mpgspec.oracle.executors; in this process when omitted), the others
    sized here; each method is seeded by its options, so the records do not depend on where they
    ran. A primitive whose result could not come back from a worker is sized again here.
    """
    check_roa_specs(spec)
    tol = float(spec.project.oracle.h_tolerance)
    records, todo, keys = {}, [], {}
    for inst in spec.primitives:
        roa = inst.spec.roa
        prim = prims[inst.name]
        if roa.method == "given":
            records[inst.name] = RoARecord(inst.name, "given", "given", float(roa.radius), roa.radius,
                                           "radius chosen by the spec author")
            continue
        keys[inst.name] = memo.key("roa", prim.digest(), roa.method, sorted(_options(inst, tol).items()), roa.radius) \
            if memo else None
        known = memo.get(keys[inst.name]) if memo else None
        if known is not None:
            records[inst.name] = RoARecord(**known)
            continue
        todo.append(inst)
    jobs = [(inst.name, inst.spec.roa.method, _options(inst, tol)) for inst in todo]
    methods = roa_methods()
    pooled = [j for j in jobs if getattr(methods.get(j[1]), "simulates", False)]
    done = dict(zip((j[0] for j in pooled), (executor or InProcess()).map(
        _sized, pooled, progress, label="regions of attraction", shared=prims)))
    for inst, job in zip(todo, jobs):
        res = done.get(inst.name)
        if res is None or isinstance(res, Failed):  # a solver's method, or a result lost on its way back
            res = _sized(prims, job)
        rec = _record(inst, *res)
        records[inst.name] = rec
        if memo and rec.level != "failed":
            memo.put(keys[inst.name], rec.to_dict())
    apply_radii(prims, {n: r.radius for n, r in records.items()})
    _regions(spec, prims, records)
    return records


def _options(inst, h_tolerance: float = 0.0) -> dict:
    """The options a primitive's RoA verifier is given: the spec's `roa.options`, with
    `require_certified` on when the spec says `require: certified` and the verifier reads that
    option (its certified route, e.g. lyapunov's branch-and-bound for non-polynomial loops), and for
    floquet the oracle's h_tolerance when it is not 0 (`oracle_h_tolerance`: a gait's tube draws its
    starts where the oracle may enter E, h >= -tol)."""
    roa = inst.spec.roa
    opts = dict(roa.options)
    if roa.require == "certified" and "require_certified" in (accepted_options(roa.method) or ()):
        opts.setdefault("require_certified", True)
    if roa.method == "floquet" and h_tolerance > 0:
        opts["oracle_h_tolerance"] = h_tolerance
    return opts


def _sized(prims: dict, job: tuple) -> tuple:
    """(level, radius, message, evidence, seconds) of one primitive's RoA method (the function the
    executor maps); a verifier crash is this primitive's evidence."""
    name, method, options = job
    t0 = time.perf_counter()
    try:
        res = _estimate(method, prims[name], options)
        level, r, msg, ev = res.level, float(res.radius), res.message, res.evidence
    except Exception as err:  # a verifier crash is this primitive's evidence
        level, r, msg, ev = "failed", 0.0, f"{type(err).__name__}: {err}", {}
    return level, r, msg, ev, time.perf_counter() - t0


def _record(inst, level, r: float, msg: str, ev: dict, seconds: float) -> RoARecord:
    """The record of a primitive's RoA method, with the spec's own radius weighed against it."""
    roa = inst.spec.roa
    if level not in RANK or not np.isfinite(r):  # a plug-in's answer must be a level and a finite radius
        msg = f"{msg}; the verifier answered level {str(level)[:40]!r} and radius {r!r}"
        level, r = "failed", 0.0
    rec = RoARecord(inst.name, roa.method, level, r, roa.radius, msg, ev, seconds)
    if level == "failed" or r <= 0:
        rec.radius = float(roa.radius or 0.0)
        rec.level = "given" if roa.radius else "failed"
        rec.message = f"{roa.method} failed ({msg}); " + ("using the spec's radius" if roa.radius else "E is empty")
    elif roa.radius is not None and roa.radius > r:
        rec.message = f"the spec's radius {roa.radius:g} exceeds the {level} radius {r:.4g}; using {r:.4g}. " + msg
    elif roa.radius is not None:
        rec.radius = float(roa.radius)
        rec.message = f"the spec's radius {roa.radius:g} lies within the {level} radius {r:.4g}. " + msg
        rec.level = level
    return rec


def _regions(spec: ProjectSpec, prims: dict[str, CompiledPrimitive], records: dict[str, RoARecord]) -> None:
    """Record each level-set verifier's region, {V <= rho} and the W-ball inside it, and make E that
    level set (in place) where the spec asks for `region: level_set`."""
    for inst in spec.primitives:
        rec = records[inst.name]
        ls = level_set_of(rec.evidence) if rec.level in ("certified", "empirical") else None
        if ls is None:
            continue
        prim = prims[inst.name]
        region = {"E": "ball", "level_set": ls.to_dict(), "ball": {"radius": rec.radius, "W": prim.W.tolist()}}
        if inst.spec.roa.options.get("region") == "level_set":
            new, info = use_level_set(prim, rec.evidence, rec.radius)
            region.update(info)
            if new is not None:
                prims[inst.name] = new
                rec.message = (f"E is the level set {{V <= {ls.rho:.6g}}} (V of degree {ls.degree}), checked in "
                               f"float64; the W-ball inside it has r = {rec.radius:.4g}. " + rec.message)
            else:
                rec.message = f"E is the W-ball: {info['reason']}. " + rec.message
        rec.evidence = {**rec.evidence, "region": region}


def apply_radii(prims: dict[str, CompiledPrimitive], radii: dict[str, float]) -> None:
    """Resize, in place, the E of the primitives whose radius differs from `radii`."""
    for name, prim in prims.items():
        r = radii.get(name, prim.radius)
        if r != prim.radius:
            prims[name] = prim.with_radius(r)
