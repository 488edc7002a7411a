"""The gait library: one table per trot node, written from the closed loop's own orbit.

A gait file (e.g. specs/a1/gaits.yaml) names the project, the trot primitive and the step:

    project: project.yaml
    primitive: Walk
    dt: 0.001

The project must lie in the gait file's folder (or a folder passed in `allow_paths`), like every
path a spec names (mpgspec.spec.paths); errors are located in the gait file.

`mpgspec gait specs/a1/gaits.yaml` compiles every node of the primitive, finds its orbit
(gait/orbit.py) and writes the table its `controller.gait` and `setpoint.file` name: a header
of `# key: value` lines (solver status, residual, calibrated command, Floquet multipliers, the hash
of the inputs the table depends on) and one row per step of one period. `--check` regenerates
into memory and compares with the tables on disk instead of writing.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field

from ....compile.exprs import ExprCompiler
from ....compile.primitive import compile_primitive
from ....compile.setpoint import spec_file
from ....compile.system import compile_system
from ....errors import Location, SpecError
from ....oracle.flow import switched_flow
from ....report.write import write_atomic
from ....spec.base import Strict
from ....spec.loader import ProjectSpec, _read, load_project
from ....spec.paths import ReadProblem, confine, in_project, project_root, read_text_bounded, resolve_roots
from ....spec.primitive import Setpoint
from ....spec.yamlpos import PositionMap
from ..models import TrotController
from ..setup import check_ready, trot_inputs
from ..stance import nominal_state
from .orbit import Orbit, StrideMap, find_orbit

TOLERANCE = 1e-6  # tables agree when every state differs by less than this (the Newton tolerance is 1e-10)


class TransientEntry(Strict):
    """A transient primitive whose setpoint table is its closed loop's own flow."""

    primitive: str = Field(description="a transient primitive whose law does not read x* (controller type jump, "
                                       "or pd with a fixed target); its setpoint.file is written")
    duration: float = Field(gt=0, description="length of the flow (s), at least the primitive's domain")
    start: str | None = Field(default=None, description="start from this transient's x* at the end of its "
                                                        "domain (default: the stance of controller.pose)")
    rest: bool = Field(default=False, description="write the flow's end state as a constant x*: the state the "
                                                  "loop comes to rest in (e.g. Land's crouch after the landing)")


class GaitFile(Strict):
    """What `mpgspec gait` generates."""

    project: str = Field(description="the project file, relative to this file")
    primitive: str = Field(description="the trot primitive (all of its nodes)")
    dt: float = Field(default=0.001, gt=0, description="the oracle step the orbit is computed with (s)")
    transients: list[TransientEntry] = Field(default_factory=list, description="transient primitives whose "
                                             "x*(t) is the flow of their loop from the stance of controller.pose")


@dataclass
class GaitTable:
    node: str
    path: Path
    orbit: Orbit
    inputs: str

    @property
    def failure(self) -> str | None:
        """What went wrong when no orbit was found, with what to try (None when one was)."""
        o = self.orbit
        if o.status == "converged":
            return None
        return (f"no orbit found ({o.status} after {o.iterations} Newton steps, residual {o.residual:.1e}): try "
                "a lower speed, the robot's own stance (controller.pose, controller.height), diagonal pairs "
                "(controller.pairs) and the legs of system.legs; `mpgspec simulate` shows the loop's flow")

    def text(self, state_names: list[str]) -> str:
        o = self.orbit
        head = {
            "generator": "mpgspec gait (Newton shooting on the stride map of the closed loop)",
            "node": self.node, "status": o.status, "residual": f"{o.residual:.3e}", "iterations": o.iterations,
            "speed": f"{o.speed:g}", "command": repr(float(o.command)), "period": f"{o.period:g}", "dt": f"{o.dt:g}",
            "mean_speed": f"{o.stats['mean_speed']:.6f}",
            "spectral_radius": f"{o.spectral_radius:.6f}",
            "multipliers": json.dumps([[round(float(m.real), 6), round(float(m.imag), 6)] for m in o.multipliers]),
            "neutral": json.dumps({k: [round(v[0], 6), float(f"{v[1]:.2e}")] for k, v in o.neutral.items()}),
            "peak_torque": f"{o.stats['peak_torque']:.4f}",
            "least_normal_force": f"{o.stats['least_normal_force']:.4f}",
            "least_cone_margin": f"{o.stats['least_cone_margin']:.4f}",
            "largest_touchdown_gap": f"{o.stats['largest_touchdown_gap']:.3e}",
            "inputs": self.inputs,
        }
        lines = [f"# {k}: {v}" for k, v in head.items()]
        lines.append(",".join(["t", *state_names]))
        for k, t in enumerate(o.t):
            lines.append(",".join([f"{t:.6f}", *(f"{v:.12g}" for v in o.X[:, k])]))
        return "\n".join(lines) + "\n"


@dataclass
class FlowTable:
    """x*(t) of a transient primitive: its loop's flow from the controller's stance (Definition 1
    holds by construction on the oracle's discrete flow at the same dt)."""

    node: str
    path: Path
    t: np.ndarray
    X: np.ndarray
    stats: dict
    inputs: str

    def text(self, state_names: list[str]) -> str:
        head = {"generator": "mpgspec gait (the closed loop's own flow, RK4 with contact events)",
                "node": self.node, "duration": f"{self.t[-1]:g}",
                **{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in self.stats.items()},
                "inputs": self.inputs}
        lines = [f"# {k}: {v}" for k, v in head.items()]
        lines.append(",".join(["t", *state_names]))
        for k, t in enumerate(self.t):
            lines.append(",".join([f"{t:.6f}", *(f"{v:.12g}" for v in self.X[:, k])]))
        return "\n".join(lines) + "\n"


def _entry_at(pos: PositionMap | None, index: int, name: str) -> tuple[Location | None, str]:
    """Where a field of the index-th transient entry is written in the gait file, and its key."""
    where = pos.locate_value(("transients", index, name)) if pos is not None else None
    return where, f"transients.{index}.{name}"


def _start_state(spec, sys, entry: TransientEntry, done: dict, pos: PositionMap | None = None,
                 index: int = 0) -> np.ndarray:
    """x0 of a flow: the stance of the controller's pose, or another transient's x* at the end of its
    domain (from the table generated before it, else from the compiled primitive)."""
    if entry.start is None:
        inst = next(i for i in spec.primitives if i.name == entry.primitive)
        return nominal_state(sys, dict(inst.spec.controller.pose))
    src = next((i for i in spec.primitives if i.name == entry.start), None)
    if src is None or src.spec.domain is None:
        where, key = _entry_at(pos, index, "start")
        raise SpecError("no transient primitive of that name", location=where, key=key,
                        expected="the name of a transient primitive", found=entry.start, code="MPG104")
    if entry.start in done:
        table = done[entry.start]
        k = int(np.argmin(np.abs(table.t - float(src.spec.domain[1]))))
        return table.X[:, k].copy()
    prim = compile_primitive(src, sys)
    return prim.x_star(prim.domain[1])


def flow_table(spec, sys, entry: TransientEntry, dt: float, progress=print, done: dict | None = None,
               pos: PositionMap | None = None, index: int = 0) -> FlowTable:
    """Roll out a transient primitive's closed loop from its start for entry.duration, with the
    oracle's step (RK4, the step-end rule, the jump with contact events); with `rest`, x* is the
    end state held. pos and index locate errors at the entry (transients[index]) of the gait file."""
    inst = next((i for i in spec.primitives if i.name == entry.primitive), None)
    ctrl = inst.spec.controller if inst is not None else None
    free = ctrl is not None and not getattr(ctrl, "reads_setpoint", True)
    if inst is None or not free or inst.spec.setpoint.file is None:
        where, key = _entry_at(pos, index, "primitive")
        raise SpecError("no transient primitive of that name whose law does not read x*, with a setpoint table",
                        location=where, key=key,
                        expected="a primitive with controller type jump (or pd with a target) and setpoint.file",
                        found=entry.primitive, code="MPG104")
    path = spec_file(inst, inst.spec.setpoint.file, inst.locate(("setpoint", "file")),
                     f"primitive '{inst.name}': setpoint.file")[1]
    x0 = _start_state(spec, sys, entry, done or {}, pos, index)
    named = {n: float(v) for n, v in zip(sys.state_names, x0) if v != 0.0 and not n.startswith(("contact_", "since_"))}
    start = dataclasses.replace(inst, spec=inst.spec.model_copy(update={"setpoint": Setpoint(named=named)}))
    progress(f"compiling {inst.name} (its law does not read x*)")
    prim = compile_primitive(start, sys)
    n = int(round(entry.duration / dt))
    X = switched_flow(prim, x0, 0.0, dt, n)
    t = np.arange(n + 1) * dt
    stats = {}
    for event in ("takeoff", "first_touchdown"):
        name = f"since_{event}"
        if name in sys.state_names and X[sys.state_names.index(name), -1] < t[-1]:
            stats[event] = float(t[-1] - X[sys.state_names.index(name), -1])
    if entry.rest:  # x* is the state the flow comes to rest in
        m = sys.model
        stats["rest_speed"] = float(np.abs(X[m.nq:m.nq + m.nv, -1]).max())
        t, X = np.array([0.0, t[-1]]), np.repeat(X[:, -1:], 2, axis=1)
    text = json.dumps({"controller": ctrl.model_dump(mode="json"), "dt": dt, "n": n, "rest": entry.rest, "x0": [round(float(v), 12) for v in x0],
                       "friction": float(sys.friction), "u_hi": [float(v) for v in sys.u_hi]}, sort_keys=True)
    progress(f"{inst.name}: {n} steps; " + ", ".join(f"{k} {v:.4g}" for k, v in stats.items()))
    return FlowTable(inst.name, path, t, X, stats, hashlib.sha256(text.encode()).hexdigest()[:16])


def load_gait_file(path: Path) -> GaitFile:
    """The validated gait file (a located SpecError otherwise)."""
    return read_gait_file(path)[0]


def read_gait_file(path: Path) -> tuple[GaitFile, PositionMap]:
    """The validated gait file and the positions of its keys, to locate later errors in it."""
    data, pos = _read(Path(path), what="gait file")
    try:
        return GaitFile.model_validate(data), pos
    except Exception as err:  # pydantic's ValidationError, located by the first failing key
        errs = getattr(err, "errors", lambda: [])()
        loc = tuple(errs[0]["loc"]) if errs else ()
        raise SpecError("invalid gait file", location=pos.locate(loc), key=".".join(map(str, loc)) or "gait file",
                        expected="keys project, primitive and dt", found=str(errs[0]["msg"] if errs else err)[:200],
                        code="MPG104") from None


def gait_project(path: str | Path, allow_paths=None) -> tuple[GaitFile, PositionMap, ProjectSpec]:
    """The gait file, its positions and the project it names, loaded with `allow_paths`.

    The project is a path a spec names: it must lie in the gait file's folder (symlinks resolved)
    or in an allowed folder, else a located SpecError (MPG305) before it is read. A project in an
    allowed folder is loaded with the gait file's folder as its root: its files are not quoted.
    """
    path = Path(path)
    gf, pos = read_gait_file(path)
    roots = resolve_roots(project_root(path), allow_paths)
    target = confine(gf.project, path.absolute().parent, roots, where=pos.locate_value(("project",)),
                     key="project")
    root = None if in_project(target, roots) else roots[0]
    return gf, pos, load_project(path.parent / gf.project, allow_paths=allow_paths, root=root)


def generate(path: str | Path, progress=print, allow_paths=None) -> list:
    """Find the orbit of every node of the gait file's primitive and the flow of every transient
    entry; return the tables (not yet written). allow_paths: folders outside the gait file's
    folder that its project (and the files the project names) may lie in."""
    gf, pos, spec = gait_project(path, allow_paths)
    sys = compile_system(spec)
    nodes = [i for i in spec.primitives if i.base == gf.primitive]
    if not nodes or not isinstance(nodes[0].spec.controller, TrotController):
        raise SpecError("no trot primitive of that name", location=pos.locate_value(("primitive",)), key="primitive",
                        expected="the name of a primitive with controller type trot", found=gf.primitive,
                        code="MPG104")
    for inst in nodes:  # the checks verify runs, located in the spec, before any orbit is computed
        check_ready(inst.spec.controller, sys, ExprCompiler(inst.locate, f"primitive '{inst.name}'"))
    targets = {}  # written only inside the project: checked before any orbit is computed
    for inst in nodes:
        raw = inst.spec.controller.gait or f"gaits/{gf.primitive.lower()}_{{speed}}.csv"
        targets[inst.name] = spec_file(inst, raw, inst.locate(("controller", "gait")),
                                       f"primitive '{inst.name}': controller.gait")[1]
    maps: dict[str, tuple] = {}  # (stride map, stance) per law: nodes of several files may differ in more than speed
    out = []
    for inst in nodes:
        ctrl = inst.spec.controller
        law = json.dumps(ctrl.model_dump(mode="json", exclude={"speed", "gait"}), sort_keys=True)
        if law not in maps:
            progress(f"compiling the stride map of {inst.name if maps else gf.primitive} (dt = {gf.dt:g} s)")
            try:
                maps[law] = StrideMap(sys, ctrl, gf.dt), nominal_state(sys, dict(ctrl.pose))
            except ValueError as err:  # the trot's switching times are not on the step grid
                raise SpecError("the gait's step does not divide the trot's timing", location=pos.locate(("dt",)),
                                key="dt", expected="a step that divides swing and double_support",
                                found=f"{gf.dt:g} s ({err})", code="MPG104") from None
        speed = float(next(iter(inst.argument.values()))) if inst.argument else float(ctrl.speed)
        orbit = find_orbit(*maps[law], speed)
        table = GaitTable(inst.name, targets[inst.name], orbit, trot_inputs(ctrl, sys, speed))
        out.append(table)
        if table.failure:
            progress(f"{inst.name}: {table.failure} ({orbit.seconds:.1f} s)")
            continue
        progress(f"{inst.name}: {orbit.status} in {orbit.iterations} Newton steps, residual {orbit.residual:.1e}, "
                 f"command {orbit.command:.4f} m/s for a mean speed of {orbit.stats['mean_speed']:.4f} m/s, "
                 f"largest multiplier {orbit.spectral_radius:.4f} ({orbit.seconds:.1f} s)")
    done: dict[str, FlowTable] = {}
    for index, entry in enumerate(gf.transients):
        done[entry.primitive] = flow_table(spec, sys, entry, gf.dt, progress, done, pos, index)
        out.append(done[entry.primitive])
    return out


def write(tables: list[GaitTable], state_names: list[str]) -> list[Path]:
    """Write the tables of found orbits and flows; return their paths (a failed orbit writes nothing)."""
    done = []
    for t in tables:
        if getattr(t, "failure", None):
            continue
        t.path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(t.path, t.text(state_names))
        done.append(t.path)
    return done


def compare(tables: list[GaitTable], state_names: list[str]) -> list[str]:
    """Differences between the regenerated tables and those on disk (empty when they agree)."""
    problems = []
    for t in tables:
        if getattr(t, "failure", None):
            problems.append(f"{t.node}: {t.failure}")
            continue
        if not t.path.is_file():
            problems.append(f"{t.node}: {t.path} is missing")
            continue
        old = _table_on_disk(t.path)
        if old is None:
            problems.append(f"{t.node}: {t.path} is not a table of numbers with a header line")
            continue
        new = np.vstack([t.orbit.t, t.orbit.X]) if isinstance(t, GaitTable) else np.vstack([t.t, t.X])
        if old.shape != new.shape:
            problems.append(f"{t.node}: {old.shape[1]} rows on disk, {new.shape[1]} regenerated")
            continue
        diff = float(np.abs(old - new).max())
        if not diff <= TOLERANCE:
            problems.append(f"{t.node}: states differ by up to {diff:.2e} (tolerance {TOLERANCE:g})")
    return problems


def _table_on_disk(path: Path) -> np.ndarray | None:
    """The columns of a gait table on disk (time first), read with the bound of every spec file;
    None when it is not a table of numbers (nothing of the file goes into a message)."""
    try:
        lines = read_text_bounded(path).splitlines()
        rows = [ln for ln in lines if ln and not ln.startswith("#")][1:]
        old = np.array([[float(v) for v in r.split(",")] for r in rows], float).T
    except (ReadProblem, ValueError):
        return None
    return old if old.ndim == 2 else None
