"""One compiled library per primitive whose closed loop is large: its loop, jump and sampled law.

A large closed loop (a robot's: SX beyond INLINE_NODES, or an MX loop around an optimisation-based
law) is called from the MX graphs of the oracle's judged chunks, the trace chunks, the gait's
period map and the cross-check; inlined, each of them generates and compiles its own copy. Here it
is compiled once per primitive, with the other large per-primitive parts the chunks call:
- loop (x, t, s, x_sw) -> (xdot, h, u_raw, u): the closed loop every safety function active
  (integrator.loop_of), or for a sampled law loop_u (..., u_held) and the law's solve;
- jump (x, u, t, s) -> x: the discrete update after a step (flow.jump_of);
- loop_g (x, t, s, x_sw) -> (xdot, h, u_raw, u, g): the loop and its guards (compile/guards.py),
  for a loop stepped piece by piece (oracle/pieces.py);
- roa_margin (x, t) when it is large (a setpoint looked up in a gait's table), not a small SX one.
A large RoA margin is a library of its own (E is sized after the loop is compiled: the loop's
library then serves both the sizing and the graph), and so is the jump (primitives whose jumps are
the same Function, a robot's contact events, share one). The dependents call them through
casadi.external and are linked against them. Symbols carry the hash of the Functions the parts are
built from (and of the flags and CasADi's version), files the hash of their code, so what is
compiled against a library changes when the loop does. The values are those of the inlined parts (the
same expressions, evaluated in the same order).

build_all compiles the libraries of several primitives side by side (code generated in this
thread, gcc in up to the usable cores); attach puts a primitive's library on it (prim.cache), so
integrator.py builds its chunks through it. An index file next to the library lets a worker
process find it without generating its code again. Without a compiler everything stays inlined.
"""
from __future__ import annotations

import hashlib
import threading
from dataclasses import dataclass
from pathlib import Path

import casadi as ca

from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..compile.contacts import wrap_clock
from ..compile.events import EventWindow
from ..compile.numeric import NumericFunction, content_hash, numeric
from .flow import jump_of
from .jit import cache_dir, compile_libraries, compile_many, library_job, sealed, with_cse

INLINE_NODES = 4000
"""Closed loops up to this many SX nodes are inlined (fastest code); larger ones become calls
in an MX graph, so each Function is generated once and jit compilation stays quick."""

LOOP_FLAGS = ("-O1",)
"""gcc flags of a loop library. Measured (bench/bench_looplib.py, 2 shared cores): -O2 costs 1.3-2.5
CPU-s more per library (Walk(slow)'s 0.8 MB: 3.5 against 5.1 s) and its judged chunks ran 0.88-1.08x
the inlined ones' speed against 0.86-0.91x at -O1, within the machine's noise; -O1 keeps gcc low,
as the A1 compiles eight."""

CALLER_FLAGS = ("-O0",)
"""gcc flags of a Function whose large parts are calls into a loop library (a judged or trace chunk,
the gait's period map): its own code is bookkeeping around the calls. Measured on Walk(slow)'s
judged chunk of 16 steps: -O0 1.7 CPU-s of gcc against 6.1 at -O1, the same run time (the calls
dominate it) and the same bits. A guarded step's smooth path, run at every step and a small part of
the code, is compiled at jit.HOT_LEVEL inside it (jit.hot_code): the guards' bookkeeping at -O0 cost
the walks about 13 % of their oracle time."""

_LOCK = threading.Lock()


@dataclass(frozen=True)
class LoopLibrary:
    """A primitive's compiled loop library: its files (the loop's and, when large, the RoA margin's)
    and its Functions by kind (externals)."""

    paths: tuple[Path, ...]
    fns: dict

    def get(self, kind: str) -> ca.Function | None:
        return self.fns.get(kind)


def plain_loop(prim: CompiledPrimitive, held: bool = False) -> ca.Function:
    """The closed loop (x, t, s, x_sw) -> (xdot, h, u_raw, u), or with `held` the open loop loop_u
    (x, t, s, x_sw, u_raw) -> (xdot, h, u_raw, u); large SX loops with common subexpressions
    eliminated, one Function object per primitive so that its code is generated once."""
    loop = prim.loop_u if held else (prim.loop_raw or prim.loop)
    key = "cse_loop_u" if held else "cse_loop"
    if loop.is_a("SXFunction") and (loop.n_nodes() if held else prim.f_cl.n_nodes()) > INLINE_NODES:
        if key not in prim.cache:
            prim.cache[key] = with_cse(loop)
        return prim.cache[key]
    return loop


def is_large(prim: CompiledPrimitive) -> bool:
    """Whether the primitive's closed loop is called from MX graphs (not inlined as SX)."""
    if prim.loop is None:
        return False
    return not (prim.f_cl.is_a("SXFunction") and prim.f_cl.n_nodes() <= INLINE_NODES)


def guarded(prim: CompiledPrimitive) -> bool:
    """The primitive's steps are taken piece by piece (oracle/pieces.py): its closed loop has guards
    and its law is evaluated continuously (a sampled law is held between samples, each solved at a
    step's start: it switches only there)."""
    return prim.guards.fn is not None and prim.sampled is None


def loop_and_guards(prim: CompiledPrimitive) -> ca.Function:
    """(x, t, s, x_sw) -> (xdot, h, u_raw, u, g): the closed loop (as plain_loop) and its guards in
    one Function, with common subexpressions eliminated: a large loop stepped piece by piece
    evaluates it once per point, for the step and its guards alike."""
    if "loop_and_guards" not in prim.cache:
        loop = plain_loop(prim)
        a = loop.sx_in()
        fn = ca.Function("loop_g", a, [*loop.call(a), prim.guards.fn(*a)], ["x", "t", "s", "x_sw"],
                         ["xdot", "h", "u_raw", "u", "g"])
        prim.cache["loop_and_guards"] = with_cse(fn)
    return prim.cache["loop_and_guards"]


def _parts(prim: CompiledPrimitive, kinds: tuple[str, ...]) -> dict[str, ca.Function]:
    make = {"loop": lambda: plain_loop(prim), "loop_u": lambda: plain_loop(prim, True),
            "solve": lambda: prim.sampled.solve, "jump": lambda: jump_of(prim), "roa_margin": lambda: prim.roa_margin,
            "loop_g": lambda: loop_and_guards(prim)}
    return {k: make[k]() for k in kinds}


def _renamed(fn: ca.Function, name: str) -> ca.Function:
    """fn under another name: an SX Function rebuilt (with cse: same values), an MX one called."""
    if fn.is_a("SXFunction"):
        a = fn.sx_in()
        return ca.Function(name, a, fn.call(a, True, False), fn.name_in(), fn.name_out(), {"cse": True})
    a = fn.mx_in()
    return ca.Function(name, a, fn.call(a), fn.name_in(), fn.name_out())


def _library_parts(tag: str, parts: dict[str, ca.Function]) -> list[ca.Function]:
    """The parts under their names in library `tag`. With loop_g the plain loop is a call into it
    that drops the guards (the loop's code is generated and compiled once, not twice: gcc on a
    walk's library 4.8 -> 2.9 CPU-s; the guards add about 1 % to its code)."""
    named = {k: _renamed(fn, f"{tag}_{k}") for k, fn in parts.items() if not (k == "loop" and "loop_g" in parts)}
    if "loop" in parts and "loop_g" in parts:
        g = named["loop_g"]
        a = g.mx_in()
        named["loop"] = ca.Function(f"{tag}_loop", a, g.call(a)[:4], parts["loop"].name_in(), parts["loop"].name_out())
    return [named[k] for k in parts]


LAYOUT = 2
"""Version of what a library holds and how its parts are built (part of its name): 2 calls loop_g
for the plain loop of a guarded primitive and puts the jump in a library of its own."""


def _units(prim: CompiledPrimitive, flags: tuple[str, ...]) -> list[tuple[str, tuple[str, ...]]]:
    """(name, kinds) of the primitive's libraries: its loop's, its jump's (the same for the primitives
    of a robot that share contact events or a schedule's touchdowns: compiled once for them) and,
    when large (x*(t) looked up in a gait's table), its RoA margin's, apart because E is sized after
    the loop is compiled. A name is the hash of the Functions its parts are built from, the kinds,
    the flags, LAYOUT and CasADi's version: a process that finds a library compiled loads it without
    building its parts."""
    key = ("looplib_units", flags)
    if key not in prim.cache:
        kinds = (("loop",) if prim.sampled is None else ("loop_u", "solve")) + (("loop_g",) if guarded(prim) else ())
        sources = [prim.loop_raw or prim.loop, prim.f_cl, prim.loop_u] + \
            ([prim.sampled.solve] if prim.sampled is not None else []) + ([prim.guards.fn] if guarded(prim) else [])
        units = [(_name("loop", sources, kinds, flags), kinds),
                 (_name("jump", [jump_of(prim)], ("jump",), flags), ("jump",))]
        if not prim.roa_margin.is_a("SXFunction") or prim.roa_margin.n_nodes() > INLINE_NODES:
            units.append((_name("margin", [prim.roa_margin], ("roa_margin",), flags), ("roa_margin",)))
        prim.cache[key] = units
    return prim.cache[key]


def _name(prefix: str, sources: list, kinds: tuple[str, ...], flags: tuple[str, ...]) -> str:
    digest = hashlib.sha256(" ".join((*kinds, *flags, str(LAYOUT), str(INLINE_NODES), ca.__version__)).encode())
    for fn in sources:
        if fn is not None:
            digest.update(content_hash(fn).encode())
    return f"{prefix}_{digest.hexdigest()[:16]}"


def _index(tag: str) -> Path:
    return cache_dir() / f"{tag}.lib"


def _known(tag: str) -> Path | None:
    """The library of this tag compiled before (its index names a sealed library), else None."""
    try:
        path = Path(_index(tag).read_text().strip())
    except (OSError, ValueError):
        return None
    return path if sealed(path) else None


def _load(units: list, paths: list) -> LoopLibrary | None:
    """The library of compiled units (None when one of them failed: the primitive stays inlined)."""
    if any(path is None for path in paths):
        return None
    fns = {k: ca.external(f"{tag}_{k}", str(path)) for (tag, kinds), path in zip(units, paths) for k in kinds}
    return LoopLibrary(tuple(paths), fns)


def build_all(prims, flags: tuple[str, ...] = LOOP_FLAGS) -> None:
    """Compile the loop libraries of the large primitives side by side (their code generated here,
    gcc in up to the usable cores) and attach each to its primitive. A failure leaves it inlined."""
    todo, jobs, new = [], [], {}
    for p in {id(p): p for p in prims}.values():
        if not is_large(p) or "looplib" in p.cache:
            continue
        units = _units(p, flags)
        paths = [_known(tag) for tag, _kinds in units]
        for (tag, kinds), path in zip(units, paths):
            if path is None and tag not in new:  # the same library for two primitives is compiled once
                new[tag] = len(jobs)
                jobs.append(library_job(tag, _library_parts(tag, _parts(p, kinds)), flags))
        todo.append((p, units, paths))
    built = compile_libraries(jobs)
    for tag, i in new.items():
        if built[i] is not None:
            with _LOCK:
                _write_index(tag, built[i])
    for p, units, paths in todo:
        p.cache["looplib"] = _load(units, [path or built[new[tag]] for (tag, _k), path in zip(units, paths)])


def _write_index(tag: str, path: Path) -> None:
    tmp = _index(tag).with_suffix(f".tmp{threading.get_ident()}")
    tmp.write_text(str(path))
    tmp.replace(_index(tag))  # atomic: a reader sees the old index or the new one


def attach(prim: CompiledPrimitive, flags: tuple[str, ...] = LOOP_FLAGS) -> LoopLibrary | None:
    """The primitive's loop library (built now when not yet compiled), remembered on it; None for a
    small loop or when gcc fails."""
    if "looplib" not in prim.cache:
        if is_large(prim):
            build_all([prim], flags)
        prim.cache.setdefault("looplib", None)
    return prim.cache["looplib"]


def attached(prim: CompiledPrimitive) -> LoopLibrary | None:
    """The loop library attached to the primitive, if any (nothing is built)."""
    return prim.cache.get("looplib")


def part(prim: CompiledPrimitive, kind: str) -> ca.Function | None:
    """The compiled part `kind` (loop, loop_u, solve, jump, roa_margin, loop_g) of the primitive's attached
    loop library, None without one or when it does not hold that part."""
    lib = attached(prim)
    return lib.get(kind) if lib is not None else None


def compile_callers(prims: list[CompiledPrimitive], fns: list[ca.Function],
                    flags: tuple[str, ...] | list[tuple[str, ...]]) -> list:
    """fns (each built from the primitive beside it) compiled side by side, in their order: those
    calling a loop library at CALLER_FLAGS and linked against it, the others at `flags` (one tuple
    for all, or one per Function)."""
    each = flags if isinstance(flags, list) else [tuple(flags)] * len(fns)
    groups: dict = {}
    for k, p in enumerate(prims):
        groups.setdefault(caller_flags(p, each[k]), []).append(k)
    out: list = [None] * len(fns)
    for fl, ks in groups.items():
        for k, fn in zip(ks, compile_many([fns[k] for k in ks], fl, libs=[libs_of(prims[k]) for k in ks])):
            out[k] = fn
    return out


def caller_flags(prim: CompiledPrimitive, flags: tuple[str, ...]) -> tuple[str, ...]:
    """The gcc flags of a Function built from the primitive: CALLER_FLAGS when it calls the attached
    library, else `flags`."""
    return CALLER_FLAGS if attached(prim) is not None else tuple(flags)


def libs_of(prim: CompiledPrimitive) -> tuple[Path, ...]:
    """What a Function built from the primitive's attached library links against."""
    lib = attached(prim)
    return lib.paths if lib is not None else ()


def windowed(prim: CompiledPrimitive, h_all, x, t, s):
    """h with each safety function INACTIVE outside its `when` window, from every one active (as
    compile/primitive.py applies the windows: the same operations, so the same values)."""
    if not any(w is not None for w in prim.windows):
        return h_all
    xs, ts, ss = ca.SX.sym("x", prim.system.nx), ca.SX.sym("t"), ca.SX.sym("s")
    hs = ca.SX.sym("h", len(prim.windows))
    tc = wrap_clock(ts, prim.period)
    out = []
    for i, w in enumerate(prim.windows):
        if isinstance(w, tuple):
            out.append(ca.if_else(ca.logic_and(tc >= float(w[0]), tc < float(w[1])), hs[i], INACTIVE))
        elif isinstance(w, EventWindow):
            out.append(ca.if_else(w.active(xs[w.clock], ss), hs[i], INACTIVE))
        else:
            out.append(hs[i])
    return ca.Function("windows", [hs, xs, ts, ss], [ca.vertcat(*out)])(h_all, x, t, s)


def held_law(prim: CompiledPrimitive) -> tuple[NumericFunction, NumericFunction] | None:
    """(solve, open loop) of a sampled law (the ID-QP), None for any other: solve(x, t, s, x_sw, w)
    -> (u_raw, w_next) is the solve the oracle makes at every control sample, warm-started from the
    previous one; open(x, t, s, x_sw, u) -> (h with its windows, u saturated) the loop under that
    held input. Through the primitive's loop library (attached, built when not yet compiled), else
    in CasADi's virtual machine. A compiled solve that does not converge raises; the virtual machine
    returns its last iterate."""
    if prim.sampled is None:
        return None
    if "looplib_held" not in prim.cache:
        lib = attach(prim)
        lib = lib if lib is not None and lib.get("solve") is not None and lib.get("loop_u") is not None else None
        prim.cache["looplib_held"] = (numeric(lib.get("solve") if lib is not None else prim.sampled.solve),
                                      _windowed_open(prim, lib.get("loop_u") if lib is not None else prim.loop_u, "held"))
    return prim.cache["looplib_held"]


def _windowed_open(prim: CompiledPrimitive, loop_u: ca.Function, name: str) -> NumericFunction:
    """(x, t, s, x_sw, u) -> (h with its windows, u saturated) of an open loop with loop_u's signature."""
    a = [ca.MX.sym(n, *loop_u.sparsity_in(i).shape) for i, n in enumerate(("x", "t", "s", "x_sw", "u"))]
    _xdot, h_all, _u_raw, u = loop_u.call(a)
    return numeric(ca.Function(name, a, [windowed(prim, h_all, a[0], a[1], a[2]), u]))


def open_law(prim: CompiledPrimitive) -> NumericFunction | None:
    """(x, t, s, x_sw, u) -> (h with its windows, u saturated): the loop under an input the law did not
    ask at x, for a law that is not sampled (held_law's open loop serves one that is); None for a
    primitive built without `open_loop`. What the safety functions read when the law acts on a
    delayed or noisy state while the plant is at x: the ground forces under the input applied. In
    CasADi's virtual machine (about 0.1 ms per call on the A1): only sensing errors call it."""
    if prim.open_loop is None:
        return None
    if "looplib_open" not in prim.cache:
        prim.cache["looplib_open"] = _windowed_open(prim, prim.open_loop, "open_law")
    return prim.cache["looplib_open"]


def law(prim: CompiledPrimitive) -> NumericFunction | None:
    """(x, t, s, x_sw) -> (h with its windows, u) through the attached library's loop (None without
    one): what prim.loop gives the cross-check, evaluated in compiled code on numpy buffers."""
    lib = attached(prim)
    if lib is None or lib.get("loop") is None:
        return None
    if "looplib_law" not in prim.cache:
        a = [ca.MX.sym(n, *prim.loop.sparsity_in(i).shape) for i, n in enumerate(("x", "t", "s", "x_sw"))]
        _xdot, h_all, _u_raw, u = lib.get("loop").call(a)
        prim.cache["looplib_law"] = numeric(ca.Function("law", a, [windowed(prim, h_all, a[0], a[1], a[2]), u]))
    return prim.cache["looplib_law"]
