"""One compiled library per primitive whose closed loop is large: its loop, jump and sampled law.

A large closed loop (a robot's: SX beyond INLINE_NODES, or an MX loop around an optimisation-based
law) is called from the MX graphs of the oracle's judged chunks, the trace chunks, the gait's
period map and the cross-check; inlined, each of them generates and compiles its own copy. Here it
is compiled once per primitive, with the other large per-primitive parts the chunks call:
- loop (x, t, s, x_sw) -> (xdot, h, u_raw, u): the closed loop every safety function active
  (integrator._loop), or for a sampled law loop_u (..., u_held) and the law's solve;
- jump (x, u, t, s) -> x: the discrete update after a step (flow.jump_of);
- roa_margin (x, t) when it is large (a setpoint looked up in a gait's table), not a small SX one.
The dependents call them through casadi.external and are linked against the library. Its symbols
carry the hash of the primitive's content (and of the flags and CasADi's version), its file the
hash of its code, so what is compiled against the library changes when the loop does. The values are those of the inlined parts (the
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
from .flow import jump_of
from .jit import cache_dir, compile_libraries, library_job, with_cse

INLINE_NODES = 4000
"""Closed loops up to this many SX nodes are inlined (fastest code); larger ones become calls
in an MX graph, so each Function is generated once and jit compilation stays quick."""

LOOP_FLAGS = ("-O1",)
"""gcc flags of a loop library. Measured on Walk(slow)'s (0.8 MB of C, 2 shared cores): -O1 3.5 CPU-s,
-O2 5.1 CPU-s for judged chunks 10-20 % faster; -O1 keeps gcc low, as each build compiles eight."""

CALLER_FLAGS = ("-O0",)
"""gcc flags of a Function whose large parts are calls into a loop library (a judged or trace chunk,
the gait's period map): its own code is bookkeeping around the calls. Measured on Walk(slow)'s
judged chunk of 16 steps: -O0 1.7 CPU-s of gcc against 6.1 at -O1, the same run time (the calls
dominate it) and the same bits."""

_LOCK = threading.Lock()


@dataclass(frozen=True)
class LoopLibrary:
    """A primitive's compiled loop library: its path and its Functions by kind (externals)."""

    path: Path
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


def _kinds(prim: CompiledPrimitive) -> tuple[str, ...]:
    """The parts of the primitive's library (see the module's docstring)."""
    big_margin = not prim.roa_margin.is_a("SXFunction") or prim.roa_margin.n_nodes() > INLINE_NODES
    return (("loop",) if prim.sampled is None else ("loop_u", "solve")) + ("jump",) + \
        (("roa_margin",) if big_margin else ())  # e.g. x*(t) looked up in a gait's table


def _parts(prim: CompiledPrimitive) -> dict[str, ca.Function]:
    make = {"loop": lambda: plain_loop(prim), "loop_u": lambda: plain_loop(prim, True),
            "solve": lambda: prim.sampled.solve, "jump": lambda: jump_of(prim), "roa_margin": lambda: prim.roa_margin}
    return {k: make[k]() for k in _kinds(prim)}


def _renamed(fn: ca.Function, name: str) -> ca.Function:
    """fn under another name: an SX Function rebuilt (with cse: same values), an MX one called."""
    if fn.is_a("SXFunction"):
        a = fn.sx_in()
        return ca.Function(name, a, fn.call(a, True, False), fn.name_in(), fn.name_out(), {"cse": True})
    a = fn.mx_in()
    return ca.Function(name, a, fn.call(a), fn.name_in(), fn.name_out())


LAYOUT = 1
"""Version of what a library holds and how its parts are built (part of its name)."""


def _tag(prim: CompiledPrimitive, flags: tuple[str, ...]) -> str:
    """The library's name: the hash of the closed loop's content (CompiledPrimitive.digest: every
    Function the parts are built from), the parts, the flags, LAYOUT and CasADi's version. Cheap:
    a process that finds the library compiled loads it without building its parts."""
    text = " ".join((prim.digest(), *_kinds(prim), *flags, str(LAYOUT), str(INLINE_NODES), ca.__version__))
    return f"loop_{hashlib.sha256(text.encode()).hexdigest()[:16]}"


def _index(tag: str) -> Path:
    return cache_dir() / f"{tag}.lib"


def _known(tag: str) -> Path | None:
    """The library of this tag compiled before (its index names an existing file), else None."""
    try:
        path = Path(_index(tag).read_text().strip())
    except OSError:
        return None
    return path if path.exists() else None


def _load(tag: str, kinds, path: Path) -> LoopLibrary:
    return LoopLibrary(path, {k: ca.external(f"{tag}_{k}", str(path)) for k in kinds})


def build_all(prims, flags: tuple[str, ...] = LOOP_FLAGS) -> None:
    """Compile the loop libraries of the large primitives side by side (their code generated here,
    gcc in up to the usable cores) and attach each to its primitive. A failure leaves it inlined."""
    todo, jobs = [], []
    for p in {id(p): p for p in prims}.values():
        if not is_large(p) or "looplib" in p.cache:
            continue
        tag = _tag(p, flags)
        path = _known(tag)
        if path is not None:
            p.cache["looplib"] = _load(tag, _kinds(p), path)
            continue
        named = [_renamed(fn, f"{tag}_{k}") for k, fn in _parts(p).items()]
        todo.append((p, tag))
        jobs.append(library_job(tag, named, flags))
    for (p, tag), path in zip(todo, compile_libraries(jobs)):
        p.cache["looplib"] = None if path is None else _load(tag, _kinds(p), path)
        if path is not None:
            with _LOCK:
                _write_index(tag, path)


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


def caller_flags(prim: CompiledPrimitive, flags: tuple[str, ...]) -> tuple[str, ...]:
    """The gcc flags of a Function built from the primitive: CALLER_FLAGS when it calls the attached
    library, else `flags`."""
    return CALLER_FLAGS if attached(prim) is not None else tuple(flags)


def libs_of(prim: CompiledPrimitive) -> tuple[Path, ...]:
    """What a Function built from the primitive's attached library links against."""
    lib = attached(prim)
    return (lib.path,) if lib is not None else ()


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


def law(prim: CompiledPrimitive) -> ca.Function | None:
    """(x, t, s, x_sw) -> (h with its windows, u) through the attached library's loop (None without
    one): what prim.loop gives the cross-check, evaluated in compiled code."""
    lib = attached(prim)
    if lib is None or lib.get("loop") is None:
        return None
    if "looplib_law" not in prim.cache:
        a = [ca.MX.sym(n, *prim.loop.sparsity_in(i).shape) for i, n in enumerate(("x", "t", "s", "x_sw"))]
        _xdot, h_all, _u_raw, u = lib.get("loop").call(a)
        prim.cache["looplib_law"] = ca.Function("law", a, [windowed(prim, h_all, a[0], a[1], a[2]), u])
    return prim.cache["looplib_law"]
