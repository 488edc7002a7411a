"""Load projects: find project files, read YAML with positions, validate, expand and cross-check.

The result is a `ProjectSpec`: validated models plus a way to locate any key in its source file,
so that later stages (expression compilation) can still report file:line:column.

Every path a spec names (included system and primitive files, setpoint tables, URDFs) must lie
inside the project folder, the data folder of a `share:` package or a folder passed in
`allow_paths` (mpgspec.spec.paths); files are read with a size bound. Errors in a file outside
the project folder show none of its lines or values.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterable

from pydantic import ValidationError

from ..errors import Location, SpecError, SpecErrors, UsageError
from .models import EventWindow, Primitive, PrimitiveClass, Project, SafetyFunction
from .paths import (
    SAFE_NAME_TEXT,
    ReadProblem,
    clip,
    clip_repr,
    confine,
    confine_share,
    in_project,
    name_problem,
    project_root,
    read_text_bounded,
    resolve_roots,
)
from .primitive import node_label
from .project import node_refs
from .yamlpos import PositionMap, parse_yaml

PROJECT_FILE = "project.yaml"
BUILTIN_BLOCKS = ("joint_limits", "ground_contact", "no_slip", "aerial", "touchdown_gap")
"""Safe-set blocks the rigid-body system provides (the paper's C_{q,qdot}, C_ground, no slip, C_aerial, and
the touchdown gaps of a contact schedule)."""

Locator = Callable[[tuple], Location]


@dataclass(frozen=True)
class PrimitiveInstance:
    """One node of the graph: a primitive, with its argument value bound (Section III-B)."""

    name: str
    base: str
    spec: Primitive
    argument: dict[str, float]
    safe_set: tuple[SafetyFunction, ...]
    locate: Locator = field(compare=False, repr=False)
    source: Path = field(default=Path("."), compare=False)  # the YAML file the primitive is written in
    roots: tuple[Path, ...] = field(default=(), compare=False, repr=False)  # folders its files may be in

    @property
    def cls(self) -> PrimitiveClass:
        return self.spec.class_


@dataclass
class ProjectSpec:
    """A validated project, ready to compile."""

    path: Path
    project: Project
    system: Any
    system_locate: Locator
    primitives: list[PrimitiveInstance]
    locate: Locator
    roots: tuple[Path, ...] = ()
    """Folders the files a spec names may lie in: the project folder first, then allow_paths."""

    @property
    def name(self) -> str:
        return self.project.project

    def primitive(self, name: str) -> PrimitiveInstance:
        for p in self.primitives:
            if p.name == name:
                return p
        raise KeyError(name)


def discover(path: str | Path) -> list[Path]:
    """Project files under `path`: the file itself, `path/project.yaml`, or all below a folder."""
    p = Path(path)
    if not p.exists():
        raise UsageError(f"{p}: no such file or folder")
    if p.is_file():
        return [p]
    if (p / PROJECT_FILE).is_file():
        return [p / PROJECT_FILE]
    found = sorted(p.rglob(PROJECT_FILE))
    if not found:
        raise UsageError(f"{p}: no {PROJECT_FILE} found in this folder or below it")
    return found


def _data_path(data, loc: tuple) -> tuple:
    """The part of a pydantic error location that indexes the document (drops union tags and types)."""
    out, node = [], data
    for i, k in enumerate(loc):
        if isinstance(node, dict) and k in node:
            out.append(k)
            node = node[k]
        elif isinstance(node, list) and isinstance(k, int) and k < len(node):
            out.append(k)
            node = node[k]
        elif isinstance(node, dict) and i == len(loc) - 1 and isinstance(k, str) and "[" not in k:
            out.append(k)  # a missing or unknown key: name it
    return tuple(out)


def _validation_errors(err: ValidationError, positions: PositionMap, prefix: tuple = (),
                       data=None) -> list[SpecError]:
    out = []
    errs = err.errors()
    model_errors = [e for e in errs if not (e["type"] == "string_type" and isinstance(e.get("input"), (dict, list)))]
    for e in errs:
        if model_errors and e["type"] == "string_type" and isinstance(e.get("input"), (dict, list)):
            continue  # the file-name branch of an inline part: the model branch explains the error
        loc = prefix + tuple(e["loc"])
        data_loc = _data_path(data, loc)
        key = clip(".".join(str(x) for x in data_loc) or "<root>")
        found = e.get("input")
        found_s = clip_repr(found) if not isinstance(found, (dict, list)) else type(found).__name__
        msg = clip(e["msg"], 300)
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        code = "MPG102" if e["type"] == "extra_forbidden" else "MPG103" if e["type"] == "missing" else "MPG104"
        ctx = e.get("ctx") or {}  # custom errors (e.g. an unknown contact event) say what was expected
        expected, hint = str(ctx.get("expected", "")), str(ctx.get("hint", ""))
        if e["type"] == "extra_forbidden":
            msg = "unknown key"
            found_s = clip_repr(data_loc[-1]) if data_loc else ""
        elif e["type"] == "missing":
            msg = "required key is missing"
            found_s = ""
        out.append(
            SpecError(msg, location=positions.locate(data_loc), key=key, expected=expected, found=found_s, code=code,
                      hint=hint)
        )
    _suggest_keys(out, errs, prefix, data)
    # one union branch usually explains the problem best; keep distinct locations
    seen, unique = set(), []
    for s in out:
        k = (s.key, s.message)
        if k not in seen:
            seen.add(k)
            unique.append(s)
    return unique


@lru_cache(maxsize=1)
def _spec_keys() -> tuple[str, ...]:
    """Every key the spec language knows (property names of the project, primitive and system schemas)."""
    from .schema import spec_schema

    names: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            names.update((node.get("properties") or {}).keys())
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    for kind in ("project", "primitive", "system"):
        walk(spec_schema(kind))
    return tuple(sorted(names))


def _suggest_keys(out: list[SpecError], errs, prefix: tuple, data) -> None:
    """'did you mean' for unknown keys: a required key missing next to it, else a known key."""
    import difflib

    missing: dict[tuple, list[str]] = {}
    for e in errs:
        if e["type"] == "missing":
            loc = _data_path(data, prefix + tuple(e["loc"]))
            if loc and isinstance(loc[-1], str):
                missing.setdefault(tuple(loc[:-1]), []).append(loc[-1])
    for s in out:
        if s.code != "MPG102" or s.hint:
            continue
        parts = s.key.split(".")
        word = parts[-1]
        parent = tuple(int(x) if x.isdigit() else x for x in parts[:-1])
        near = difflib.get_close_matches(word, missing.get(parent, []), n=1, cutoff=0.6) or \
            difflib.get_close_matches(word, [k for k in _spec_keys() if k != word], n=1, cutoff=0.8)  # valid elsewhere
        if near:
            s.hint = f"did you mean {near[0]!r}?"


def _at(pos: PositionMap, loc: tuple, offset: int | None) -> Location:
    """Location of a key, or of character `offset` inside its value when an offset is given."""
    return pos.locate(loc) if offset is None else pos.locate_in_value(loc, offset)


def _read(path: Path, quote: bool = True, what: str = "project file") -> tuple[Any, PositionMap]:
    """The project file itself (or a gait file: `what`): a missing file is a usage error, other
    problems spec errors, a byte that is not UTF-8 placed at its line and column."""
    try:
        text = read_text_bounded(path, allow_empty=True)
    except ReadProblem as p:
        if p.missing:
            raise UsageError(f"{path}: no such file") from None
        raise SpecErrors([SpecError(p.message, location=Location(str(path), p.line, p.column, quote),
                                    key=what, expected=p.expected, found=p.found, code="MPG100")]) from None
    return parse_yaml(text, str(path), quote)


def _read_included(path: Path, written: str, where: Location, key: str, roots=()) -> tuple[Any, PositionMap]:
    """An included spec file, read bounded; a problem is a SpecError at the key that names it.

    A file outside the project folder (roots[0]) is parsed with quote=False."""
    try:
        text = read_text_bounded(path)
    except ReadProblem as p:
        if p.missing:
            raise SpecError("included file not found", location=where, key=key,
                            expected="a path relative to the project file", found=clip_repr(written),
                            code="MPG301") from None
        raise SpecError(f"included file: {p.message}", location=where, key=key, expected=p.expected,
                        found=f"{clip_repr(written)} ({p.found})" if p.found else clip_repr(written),
                        code="MPG301") from None
    data, positions = parse_yaml(text, str(path), in_project(path, roots))
    if data is None:
        raise SpecError("included file has no content", location=where, key=key,
                        expected="a YAML mapping", found="only comments", code="MPG301")
    return data, positions


def _within(item: SafetyFunction, when) -> SafetyFunction:
    """A block's safety function restricted to the `when` window of the `use` that includes it.

    Two clock windows intersect; a window anchored on a contact event is taken as it is when the
    other side has none (ValueError when both have a window and one is anchored on an event)."""
    if when is None:
        return item
    if item.when is not None:
        if not (isinstance(when, tuple) and isinstance(item.when, tuple)):
            raise ValueError("the block's function has a window of its own")
        when = (max(when[0], item.when[0]), min(when[1], item.when[1]))
    return item.model_copy(update={"when": when})


def _event_window_errors(project: Project, p: Primitive, loc_fn: Locator, block_loc: Locator) -> list[SpecError]:
    """Windows anchored on a contact event need contact events in the state: a rigid-body system with
    `contact_events: true`, whose contact set is not set by a clock (contact_schedule, trot)."""
    events = bool(getattr(project.system, "contact_events", False))
    scheduled = p.contact_schedule is not None or getattr(p.controller, "schedules_contacts", False)
    if events and not scheduled:
        return []
    out = []
    for j, sf in enumerate(p.safe_set):
        places = [(loc_fn(("safe_set", j, "when")), f"primitive '{clip(p.name, 60)}': safe_set.{j}.when", sf.when)]
        if sf.use is not None and sf.use in project.safe_sets:
            places += [(block_loc(("safe_sets", sf.use, k, "when")), f"safe_sets.{clip(sf.use, 60)}.{k}.when", it.when)
                       for k, it in enumerate(project.safe_sets[sf.use])]
        for where, key, when in places:
            if not isinstance(when, EventWindow):
                continue
            if not events:
                kind = getattr(project.system, "kind", "analytic")
                out.append(SpecError(
                    "a window anchored on a contact event needs contact events in the state", location=where,
                    key=key, expected="a rigid_body system with contact_events: true",
                    found="an analytic system" if kind == "analytic" else "contact_events: false",
                    hint="set contact_events: true under system, or give a clock window [t0, t1]", code="MPG108"))
            else:
                out.append(SpecError(
                    "a window anchored on a contact event needs contacts that follow events, not the clock",
                    location=where, key=key, expected="a primitive without contact_schedule or a trot controller",
                    found="a contact schedule", hint="the schedule fixes the contact times: give a clock window",
                    code="MPG108"))
    return out


def _expand(p: Primitive) -> list[tuple[str, dict[str, float], str | None]]:
    """(node name, argument, label) of each node of a primitive."""
    if not p.arguments:
        return [(p.name, {}, None)]
    (arg, values), = p.arguments.items()
    items = values.items() if isinstance(values, dict) else ((node_label(v), v) for v in values)
    return [(f"{p.name}({label})", {arg: float(v)}, label) for label, v in items]


NODE_FIXED = ("name", "class", "arguments", "nodes")
"""Keys a node cannot set for itself: they make the family it belongs to."""


def _merged(base, over):
    """base with over's keys: mappings merge key by key, any other value replaces."""
    if isinstance(base, dict) and isinstance(over, dict):
        return {**base, **{k: _merged(base.get(k), v) for k, v in over.items()}}
    return over


def _written(over: dict, loc: tuple) -> tuple[int, bool]:
    """How many keys of `loc` a node's entry writes, and whether the key at `loc` is its (written there, or
    inside a value the entry replaces)."""
    node, depth = over, 0
    for k in loc:
        if not isinstance(node, dict) or k not in node:
            return depth, False
        node, depth = node[k], depth + 1
        if not isinstance(node, dict):
            return depth, True
    return depth, True


def _node_spec(p: Primitive, label: str | None, loc_fn: Locator, errors: list) -> tuple[Primitive, Locator]:
    """The primitive of one node: its `nodes` entry merged in (None when that entry is invalid, which is
    then in errors), and a locator that finds the keys the entry sets in the entry."""
    over = p.nodes.get(label) if label is not None else None
    base = p.model_copy(update={"nodes": {}})
    if not over:
        return base, loc_fn

    def locate(loc, offset=None):
        return loc_fn(("nodes", label, *loc), offset) if _written(over, tuple(loc))[1] else loc_fn(loc, offset)

    fixed = [k for k in over if k in NODE_FIXED]
    if fixed:
        errors.append(SpecError("a node cannot set this key", location=loc_fn(("nodes", label, fixed[0])),
                                key=f"nodes.{label}.{fixed[0]}", expected=f"keys of the primitive other than "
                                f"{', '.join(NODE_FIXED)}", found=fixed[0], code="MPG104"))
        return None, locate
    data = _merged(base.model_dump(by_alias=True, exclude_unset=True), over)
    try:
        return Primitive.model_validate(data), locate
    except ValidationError as e:
        errors += _validation_errors(e, _EntryErrors(loc_fn, label, over), data=data)
        return None, locate


class _EntryErrors:
    """Where _validation_errors puts an error of a node's merged primitive: at the deepest key of the path
    that the node's entry writes (its entry made the primitive invalid), else at the family's key."""

    def __init__(self, loc_fn: Locator, label: str, over: dict):
        self.loc_fn, self.label, self.over = loc_fn, label, over

    def locate(self, loc, offset=None):
        depth = _written(self.over, tuple(loc))[0]
        return self.loc_fn(("nodes", self.label, *loc[:depth]), offset) if depth else self.loc_fn(loc, offset)


def load_project(path: str | Path, allow_paths: Iterable[str | Path] | None = None,
                 root: str | Path | None = None) -> ProjectSpec:
    """Read, validate and cross-check one project file; raise SpecErrors listing every problem.

    Files the spec names must lie inside the project folder (the folder of `path`, symlinks
    resolved), inside the data folder of a `share:` package, or inside one of `allow_paths`.
    root replaces the project folder for a project named by another spec (a gait file) that lies
    outside that spec's folder: nothing of the project's files is then quoted in errors.
    """
    path = Path(path)
    roots = resolve_roots(Path(root) if root is not None else project_root(path), allow_paths)
    data, pos = _read_project(path, roots)
    name_errors = _name_errors(data, pos)  # reported with the errors of whichever later pass fails
    errors: list[SpecError] = []
    sys_included = isinstance(data.get("system"), str)
    data, system_locate = _include_system(data, pos, path, roots, errors)
    prims_in, prim_locates, prim_sources = _include_primitives(data, pos, path, roots, errors)
    if errors:
        raise SpecErrors(name_errors + errors)
    data = {**data, "primitives": prims_in}
    merged = _MergedPositions(pos, system_locate if sys_included else None, prim_locates)
    try:
        project = Project.model_validate(data)
    except ValidationError as e:
        raise SpecErrors(name_errors + _validation_errors(e, merged, data=data)) from None
    errors = name_errors + _check_named_files(path, project, prim_locates, prim_sources, system_locate, roots)
    instances = _instances(project, prim_locates, prim_sources, roots, merged, errors)
    errors += _reference_errors(project, {p.name for p in instances}, prim_locates, merged)
    if errors:
        raise SpecErrors(errors)
    return ProjectSpec(path, project, project.system, system_locate, instances, merged.locate, roots)


def _read_project(path: Path, roots) -> tuple[dict, PositionMap]:
    """The project file's mapping and its positions; the file must lie inside the allowed folders."""
    try:
        confine(path.name, path.absolute().parent, roots, where=Location(str(path)), key="project file")
    except SpecError as err:
        raise SpecErrors([err]) from None
    data, pos = _read(path, in_project(path, roots))
    if not isinstance(data, dict):
        raise SpecErrors([SpecError("a project file must be a mapping", location=Location(str(path), 1, 1, pos.quote),
                                    expected="keys project, system, primitives", found=type(data).__name__,
                                    code="MPG104")])
    return data, pos


def _name_errors(data: dict, pos: PositionMap) -> list[SpecError]:
    """The project's name must be safe as a folder name (reports go to <out>/<project>)."""
    name = data.get("project")
    if isinstance(name, str) and name_problem(name):
        return [SpecError(f"project name is not a safe name ({name_problem(name)})",
                          location=pos.locate(("project",)), key="project", expected=SAFE_NAME_TEXT,
                          found=clip_repr(name), code="MPG104", hint="reports are written to <out>/<project>")]
    return []


def _include_system(data: dict, pos: PositionMap, path: Path, roots, errors: list) -> tuple[dict, Locator]:
    """The document with an included system file read in, and a locator into the system's source."""
    system_locate: Locator = lambda loc, offset=None: _at(pos, ("system",) + tuple(loc), offset)
    sys_data = data.get("system")
    if isinstance(sys_data, str):
        try:
            sys_path = confine(sys_data, path.parent, roots, where=pos.locate(("system",)), key="system")
            sd, spos = _read_included(sys_path, sys_data, pos.locate_value(("system",)), "system", roots)
        except SpecError as err:
            errors.append(err)
        else:
            if not isinstance(sd, dict):  # a string would be read as the name of another file
                errors.append(SpecError("an included system file must hold a mapping",
                                        location=pos.locate_value(("system",)), key="system",
                                        expected="a system (mapping)", found=type(sd).__name__, code="MPG104"))
                return data, system_locate
            data = {**data, "system": sd}
            system_locate = lambda loc, offset=None, spos=spos: _at(spos, tuple(loc), offset)
    return data, system_locate


def _include_primitives(data: dict, pos: PositionMap, path: Path, roots, errors: list):
    """(primitives, a locator per primitive, the file each is written in): included files read in."""
    prim_locates: list[Locator] = []
    prim_sources: list[Path] = []
    prims_in: list = []
    prims_raw = data.get("primitives")
    if "primitives" not in data:
        errors.append(SpecError("required key is missing", location=pos.locate(("primitives",)), key="primitives",
                                expected="a list of primitive files or inline primitives",
                                found="no key primitives in the project file", code="MPG103"))
    elif not isinstance(prims_raw, list):
        errors.append(SpecError("primitives must be a list", location=pos.locate(("primitives",)), key="primitives",
                                expected="a list of primitive files or inline primitives",
                                found="null" if prims_raw is None else type(prims_raw).__name__, code="MPG104"))
        prims_raw = None
    for i, item in enumerate(prims_raw or []):
        if not isinstance(item, str):
            prims_in.append(item)
            prim_locates.append(lambda loc, offset=None, i=i: _at(pos, ("primitives", i) + tuple(loc), offset))
            prim_sources.append(path)
            continue
        key = f"primitives.{i}"
        try:
            ppath = confine(item, path.parent, roots, where=pos.locate(("primitives", i)), key=key)
            pd_, ppos = _read_included(ppath, item, pos.locate_value(("primitives", i)), key, roots)
        except SpecError as err:
            errors.append(err)
            continue
        if not isinstance(pd_, (dict, list)):
            errors.append(SpecError("an included primitive file must hold a mapping or a list of mappings",
                                    location=pos.locate_value(("primitives", i)), key=key,
                                    expected="a primitive (mapping) or a list of primitives",
                                    found=type(pd_).__name__, code="MPG104"))
            continue
        items = pd_ if isinstance(pd_, list) else [pd_]
        for j, it in enumerate(items):
            prims_in.append(it)
            pre = (j,) if isinstance(pd_, list) else ()
            prim_locates.append(lambda loc, offset=None, ppos=ppos, pre=pre: _at(ppos, pre + tuple(loc), offset))
            prim_sources.append(ppath)
    return prims_in, prim_locates, prim_sources


class _MergedPositions:
    """Positions for the merged document: route into the file each part came from."""

    def __init__(self, pos: PositionMap, system_locate: Locator | None, prim_locates: list[Locator]):
        self.pos, self.system_locate, self.prim_locates = pos, system_locate, prim_locates

    def locate(self, loc, offset=None):
        if loc and loc[0] == "system" and self.system_locate is not None:
            return self.system_locate(loc[1:], offset)
        if len(loc) >= 2 and loc[0] == "primitives" and isinstance(loc[1], int) and loc[1] < len(self.prim_locates):
            return self.prim_locates[loc[1]](loc[2:], offset)
        return _at(self.pos, loc, offset)


def _instances(project: Project, prim_locates: list[Locator], prim_sources: list[Path], roots,
               merged: _MergedPositions, errors: list) -> list[PrimitiveInstance]:
    """One node per primitive and argument value (Section III-B), with its safe set resolved."""
    instances: list[PrimitiveInstance] = []
    names: dict[str, Location] = {}
    for i, p in enumerate(project.primitives):
        resolved, origins = _resolve_safe_set(project, p, prim_locates[i], errors)
        loc_fn = _safe_set_locator(prim_locates[i], merged.locate, origins)
        errors += [e for e in _event_window_errors(project, p, loc_fn, merged.locate)  # a block's: once
                   if all((e.key, str(e.location)) != (o.key, str(o.location)) for o in errors)]
        nodes = _expand(p)
        labels = [label for _n, _a, label in nodes]
        for label in p.nodes:
            if label not in labels:
                errors.append(SpecError("no node of that label", location=prim_locates[i](("nodes", label)),
                                        key=f"nodes.{label}", expected="one of " + ", ".join(map(str, labels)),
                                        found=clip_repr(label), code="MPG104"))
        for name, arg, label in nodes:
            node, node_loc = _node_spec(p, label, loc_fn, errors)
            if node is None:
                continue
            if name in names:
                errors.append(SpecError("duplicate primitive name", location=loc_fn(("name",)),
                                        key="name", expected="unique names",
                                        found=f"{clip_repr(name)} also defined at {names[name]}", code="MPG303"))
            names[name] = loc_fn(("name",))
            node_set = resolved
            if node.safe_set != p.safe_set:  # the node's own safe set, its blocks expanded
                node_set, origins = _resolve_safe_set(project, node, node_loc, errors)
                node_loc = _safe_set_locator(node_loc, merged.locate, origins)
            instances.append(PrimitiveInstance(name, p.name, node, arg, tuple(node_set), node_loc, prim_sources[i],
                                               roots))
    return instances


def _safe_set_locator(loc_fn: Locator, block_loc: Locator, origins: list[tuple]) -> Locator:
    """The primitive's locator, with ("safe_set", j, ...) of the resolved safe set mapped to where
    function j is written: the primitive's own entry, or the item of the project block it uses."""
    def locate(loc, offset=None):
        if len(loc) >= 2 and loc[0] == "safe_set" and isinstance(loc[1], int) and 0 <= loc[1] < len(origins):
            o = origins[loc[1]]
            if o[0] == "block":
                return block_loc(("safe_sets", o[1], o[2], *loc[2:]), offset)
            return loc_fn(("safe_set", o[1], *loc[2:]), offset)
        return loc_fn(loc, offset)
    return locate


def _resolve_safe_set(project: Project, p: Primitive, loc_fn: Locator,
                      errors: list) -> tuple[list[SafetyFunction], list[tuple]]:
    """The primitive's safety functions with project blocks (`use`) expanded (the system's own
    blocks are expanded at compile time), and where each is written: ("primitive", j) or
    ("block", name, k)."""
    resolved: list[SafetyFunction] = []
    origins: list[tuple] = []
    for j, sf in enumerate(p.safe_set):
        if sf.use is None:
            resolved.append(sf)
            origins.append(("primitive", j))
        elif sf.use in BUILTIN_BLOCKS and sf.use not in project.safe_sets:
            resolved.append(sf)  # expanded by the system at compile time
            origins.append(("primitive", j))
        elif sf.use not in project.safe_sets:
            errors.append(SpecError("unknown safe-set block", location=loc_fn(("safe_set", j, "use")),
                                    key=f"primitive '{clip(p.name, 60)}': safe_set.{j}.use",
                                    expected=clip("one of " + ", ".join(
                                        sorted(project.safe_sets) + list(BUILTIN_BLOCKS)), 300),
                                    found=clip_repr(sf.use), code="MPG302"))
        else:
            for k, item in enumerate(project.safe_sets[sf.use]):
                try:
                    resolved.append(_within(item, sf.when))
                    origins.append(("block", sf.use, k))
                except ValueError as why:
                    errors.append(SpecError(
                        "cannot restrict this block to the use's window", location=loc_fn(("safe_set", j, "when")),
                        key=f"primitive '{clip(p.name, 60)}': safe_set.{j}.when",
                        expected="a use window only for block functions without one, or clock windows on both",
                        found=f"{why} (safe_sets.{clip(sf.use, 60)}.{k}.when)", code="MPG104"))
    return resolved, origins


def _reference_errors(project: Project, node_names: set[str], prim_locates: list[Locator],
                      merged: _MergedPositions) -> list[SpecError]:
    """Node names a project refers to (next, assertions, the sequence) must exist."""
    errors: list[SpecError] = []

    def check_name(n: str, loc: tuple, key: str):
        if n not in node_names:
            errors.append(SpecError("unknown primitive", location=merged.locate(loc), key=key,
                                    expected=clip("one of " + ", ".join(sorted(node_names)), 300),
                                    found=clip_repr(n), code="MPG304"))

    for i, p in enumerate(project.primitives):
        if p.next is not None and p.next not in node_names:
            errors.append(SpecError("unknown next primitive", location=prim_locates[i](("next",)),
                                    key=f"primitive '{clip(p.name, 60)}': next",
                                    expected=clip("one of " + ", ".join(sorted(node_names)), 300),
                                    found=clip_repr(p.next), code="MPG304"))
    for i, a in enumerate(project.assertions):
        for name, where in node_refs(a) or ():
            check_name(name, ("assertions", i) + where, ".".join(map(str, ("assertions", i) + where)))
    if project.sequence is not None:
        check_name(project.sequence.start, ("sequence", "start"), "sequence.start")
        for i, c in enumerate(project.sequence.commands):
            check_name(c.goal, ("sequence", "commands", i, "goal"), f"sequence.commands.{i}.goal")
    return errors


def _check_named_files(path: Path, project: Project, prim_locates: list[Locator], prim_sources: list[Path],
                       system_locate: Locator, roots: tuple[Path, ...]) -> list[SpecError]:
    """Confinement of the files the validated models name: setpoint tables and the URDF.

    They are read later (compile stage), which checks again; checking here reports them with
    every other spec error and before anything is compiled.
    """
    errors = []
    for i, p in enumerate(project.primitives):
        file = p.setpoint.file
        if file is not None:
            try:
                confine(file, prim_sources[i].parent, roots, where=prim_locates[i](("setpoint", "file")),
                        key=f"primitive '{clip(p.name, 60)}': setpoint.file")
            except SpecError as err:
                errors.append(err)
    urdf = getattr(project.system, "urdf", None)
    if isinstance(urdf, str):
        where = system_locate(("urdf",))
        try:
            if urdf.startswith("share:"):
                confine_share(urdf, roots, where=where, key="system.urdf")
            else:
                confine(urdf, path.parent, roots, where=where, key="system.urdf")
        except SpecError as err:
            errors.append(err)
    return errors
