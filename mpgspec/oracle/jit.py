"""CasADi Functions compiled to shared libraries with the system C compiler, cached by content.

compile_cached(fn, flags) compiles one Function; compile_many(fns, flags) generates the C code of
several and runs up to one gcc per usable core at once (two gcc at once take about half the wall
time of the same two one after the other). A library's file name is the Function's name and the
hash of its C code, the flags and CasADi's version: unchanged code is never compiled twice, and
two different Functions of the same name load their own libraries. A library is written to a
private temporary folder and moved into the cache with os.replace, so concurrent processes never
load a half-written one. When the compiler is missing or fails, the Function is returned
uncompiled (CasADi's virtual machine) with a warning. Every library is sealed when compiled (a
.mac file beside it: an HMAC of its name and content, mpgspec.integrity) and loaded only when its
seal verifies; a library replaced or edited in the cache is compiled again, never loaded.

compile_library(name, fns, flags) compiles several Functions and their reverse derivatives into one
library (a robot's dynamics, built once); compile_many(fns, flags, libs=[...]) links Functions that
call it (casadi.external of the library) against it. The library's path, which the dependents' C
code names through its symbols, carries the hash of its code.

library_job(name, fns, flags) generates a library's code and compile_libraries(jobs) compiles
several side by side (gcc only: it may run in a background thread); the loop libraries
(looplib.py) are built this way.

with_cse(fn) rebuilds a Function with CasADi's common-subexpression elimination (`cse`): for the
robot's generated loops smaller C, less gcc time and faster steps (bench/bench_jit.py). cse(fn) does
so unless CSE is off (only to measure what it saves).

Hot code: a Function named with HOT_PREFIX (a guarded step's smooth path, run at every step) is
optimised at HOT_LEVEL inside a library compiled at -O0 (a chunk calling a loop library, whose
rarely run parts, such as the location of a crossing, are most of its code): GCC's per-function
`optimize` pragma around its generated code, so gcc's time grows with the hot code only.

Quick compiler: code compiled without optimisation (-O0: the oracle's and the traces' chunks, the
robust gradients) goes to the Tiny C Compiler when it is installed (QUICK_CC), hot code included;
code compiled with optimisation goes to CC (default gcc). On CasADi's generated C, tcc takes about a
twentieth of gcc -O0's time and its code computes the same floats (IEEE double arithmetic in the
order written, the same libm); the reports are identical apart from timing. The library's name
carries the compiler, and a failed tcc compile falls back to gcc.

Compile log: when the environment variable MPGSPEC_JIT_LOG names a file, every Function that
compile_cached or compile_many is asked for appends one JSON line to it:
    {"name": ..., "c_bytes": size of its C code, "gcc_s": seconds gcc ran (0 on a hit),
     "hit": true when the library was already cached, "flags": [the flags gcc was given],
     "cc": the compiler that built it (tcc or CC)}
A failed compile is logged with "hit": false and "failed": true.
"""
from __future__ import annotations

import atexit
import hashlib
import json
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import casadi as ca

from ..cores import usable_cores
from ..integrity import file_authentic, file_mac

try:
    import fcntl
except ImportError:  # not on POSIX: concurrent processes may compile the same library twice
    fcntl = None

HOT_PREFIX = "hot_"
"""Functions so named are compiled at HOT_LEVEL in a library whose flags optimise less."""
HOT_LEVEL = "O1"
"""Measured on the A1's Walk(fast) judged chunk (0.75 MB of C): gcc takes 3.3 s at -O0, 3.5 s with its
hot code at -O1, 10.2 s all at -O1; the four walks' guarded oracle takes 0.87x the time of the same
chunks all at -O0 (7 interleaved rounds; bench/RESULTS.md, "Guards: stepping piece by piece (A1)")."""
_HOT_HEADER = re.compile(r"^/\* %s[A-Za-z0-9_]*:\(" % HOT_PREFIX, re.MULTILINE)
_HELPER = re.compile(r"^(casadi_real|casadi_int|void|int) casadi_[a-z_0-9]+\(")
_HELPERS_END = re.compile(r"^(/\* Configuration|/\* External functions|static const casadi_|/\* [A-Za-z0-9_]+:\()")

LARGE_CODE = 1_000_000
LARGE_CODE_FLAGS = ("-fno-tree-ter", "-fno-tree-fre", "-fno-tree-dominator-opts")
"""For generated C above LARGE_CODE bytes (robot loops: megabytes in one function) these -O1
passes are superlinear: without them a 3.4 MB chunk compiles in 39 s instead of minutes and runs
1.6x slower than with them (2.4x faster than -O0)."""

QUICK_CC = "tcc"
"""The compiler for unoptimised code when on PATH (MPGSPEC_QUICK_CC names another; empty: none, all to
CC). Measured on a cold verify of specs/a1 (2 cores): 34 libraries at -O0 took 25.0 CPU-s of gcc and
0.7 s of tcc; the oracle's calls ran at the same rate (the hot code's -O1 pragma, which tcc ignores,
is not missed), the whole verify 171 s against 183 s, the report identical. Optimised code stays
with gcc: everything through tcc took 396 s (the loop libraries at about half their -O1 speed)."""

CSE = True
"""cse(fn) eliminates common subexpressions; False only to measure what that saves."""

_LOG_LOCK = threading.Lock()


def cache_dir() -> Path:
    """Where compiled libraries are kept between runs (MPGSPEC_CACHE, else ~/.cache/mpgspec); a
    folder that cannot be created or written (MPGSPEC_CACHE naming a file, a read-only place) is
    replaced for this process by a temporary one, with one warning."""
    return _usable(str(Path(os.environ.get("MPGSPEC_CACHE", Path.home() / ".cache" / "mpgspec")) / "jit"))


@lru_cache(maxsize=None)
def _usable(folder: str) -> Path:
    p = Path(folder)
    try:
        p.mkdir(parents=True, exist_ok=True)
        if not os.access(p, os.W_OK | os.X_OK):
            raise PermissionError(f"{p} is not writable")
        return p
    except OSError as e:
        tmp = Path(tempfile.mkdtemp(prefix="mpgspec-jit-"))
        atexit.register(shutil.rmtree, tmp, True)
        warnings.warn(f"the compiled-code cache {p} cannot be used ({e}); compiling into {tmp} for this run")
        return tmp


def with_cse(fn: ca.Function) -> ca.Function:
    """fn rebuilt with common subexpressions eliminated (same name, inputs and outputs)."""
    a = fn.sx_in() if fn.is_a("SXFunction") else fn.mx_in()
    return ca.Function(fn.name(), a, fn.call(a, True, False), fn.name_in(), fn.name_out(), {"cse": True})


def cse(fn: ca.Function) -> ca.Function:
    """with_cse(fn), unless CSE is off."""
    return with_cse(fn) if CSE else fn


def cse_sx(fn: ca.Function) -> ca.Function:
    """cse(fn) for an SX Function (the large generated loops, called from MX graphs); an MX one as it is."""
    return cse(fn) if fn.is_a("SXFunction") else fn


@dataclass
class _Job:
    """One library to compile: its name, C code, the flags, the libraries it links and its path."""

    name: str
    fn: ca.Function | None
    code: str
    flags: tuple[str, ...]
    lib: Path
    hit: bool
    links: tuple[str, ...] = ()
    gcc_s: float = 0.0
    error: str | None = None
    cc: str | None = None
    """The quick compiler (tcc) for this job, or None: CC."""


def _job(fn: ca.Function, flags: tuple[str, ...], libs: tuple[Path, ...] = ()) -> _Job:
    cg = ca.CodeGenerator(f"{fn.name()}.c", {"with_header": False})
    cg.add(fn)
    return _library_job(fn.name(), fn, cg.dump(), flags, libs)


def _library_job(name: str, fn, code: str, flags: tuple[str, ...], libs: tuple[Path, ...] = (),
                 large: bool = True) -> _Job:
    """`large`: drop the superlinear passes (LARGE_CODE_FLAGS) when the code is large."""
    if large and len(code) > LARGE_CODE:
        flags = (*flags, *LARGE_CODE_FLAGS)
    links = tuple(a for lib in libs for a in (str(lib), f"-Wl,-rpath,{lib.parent}"))
    cc = None if optimising(flags) else quick_compiler()
    code = hot_code(code, flags) if cc is None else code
    key = hashlib.sha256((code + " ".join(flags + links) + ca.__version__ + (cc or "")).encode()).hexdigest()[:24]
    lib = cache_dir() / f"{name}_{key}.so"
    return _Job(name, fn, code, tuple(flags), lib, sealed(lib), links, cc=cc)


def quick_compiler() -> str | None:
    """QUICK_CC's path (or MPGSPEC_QUICK_CC's) when it is installed and builds a shared library that
    links the math library, else None."""
    return _usable_compiler(os.environ.get("MPGSPEC_QUICK_CC", QUICK_CC))


@lru_cache(maxsize=None)
def _usable_compiler(name: str) -> str | None:
    exe = shutil.which(name) if name else None
    if exe is None:
        return None
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "probe.c"
        src.write_text("#include <math.h>\ndouble probe(double x) { return sin(x) * x; }\n")
        try:
            subprocess.run([exe, "-shared", "-fPIC", str(src), "-o", str(Path(tmp) / "probe.so"), "-lm"], check=True,
                           capture_output=True, timeout=30)
        except (OSError, subprocess.SubprocessError):
            return None
    return exe


def optimising(flags: tuple[str, ...]) -> bool:
    """Whether gcc flags ask for optimisation (an -O other than -O0)."""
    return any(f.startswith("-O") and f != "-O0" for f in flags)


def hot_code(code: str, flags: tuple[str, ...]) -> str:
    """code with each HOT_PREFIX Function's definition (from its header comment to its closing brace,
    as CasADi generates it) and CasADi's helpers (casadi_copy, casadi_fmax, ...: small, called from
    every Function) compiled at HOT_LEVEL, when `flags` optimise less (no -O or -O0) and the code
    holds a HOT_PREFIX Function."""
    if optimising(flags) or not _HOT_HEADER.search(code):
        return code
    out, inside, helpers = [], False, "before"
    for line in code.split("\n"):
        if helpers == "before" and _HELPER.match(line):
            out += ["#pragma GCC push_options", f'#pragma GCC optimize ("{HOT_LEVEL}")']
            helpers = "in"
        elif helpers == "in" and _HELPERS_END.match(line):
            out.append("#pragma GCC pop_options")
            helpers = "after"
        if not inside and _HOT_HEADER.match(line):
            out += ["#pragma GCC push_options", f'#pragma GCC optimize ("{HOT_LEVEL}")']
            inside = True
        out.append(line)
        if inside and line == "}":
            out.append("#pragma GCC pop_options")
            inside = False
    return "\n".join(out)


def _seal_path(lib: Path) -> Path:
    return lib.with_name(lib.name + ".mac")


def sealed(lib: Path) -> bool:
    """Whether the library lies in the cache folder and its seal verifies (compiled here, unchanged)."""
    lib = Path(lib)
    try:
        return lib.parent.resolve() == cache_dir().resolve() and lib.is_file() and \
            file_authentic(_seal_path(lib).read_text(encoding="ascii").strip(), lib)
    except (OSError, ValueError):
        return False


def _seal(lib: Path) -> None:
    tmp = _seal_path(lib).with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(file_mac(lib), encoding="ascii")
    os.replace(tmp, _seal_path(lib))


def _gcc(job: _Job) -> None:
    """Compile job's code into its library (atomically), once across processes: a process that finds
    the library's lock taken waits for it and loads what the other compiled (test workers, oracle
    worker processes and parallel runs share one cache). On failure, job.error says why."""
    folder = job.lib.parent
    folder.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    with open(folder / f"{job.lib.stem}.lock", "a") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
        if sealed(job.lib):  # compiled by another process while this one waited
            job.hit = True
        else:
            _compile(job, folder)
    job.gcc_s = time.perf_counter() - t


def _compile(job: _Job, folder: Path) -> None:
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        src = Path(tmp) / f"{job.name}.c"
        src.write_text(job.code)
        out = Path(tmp) / job.lib.name
        tail = ["-fPIC", "-shared", str(src), "-o", str(out), *job.links, "-lm"]
        try:
            if job.cc is not None:
                try:
                    subprocess.run([job.cc, *tail], check=True, capture_output=True, text=True)
                except (OSError, subprocess.CalledProcessError):
                    job.cc = None  # what tcc cannot build, gcc can
            if job.cc is None:
                subprocess.run([os.environ.get("CC", "gcc"), *job.flags, *tail], check=True, capture_output=True,
                               text=True)
            os.replace(out, job.lib)  # atomic: concurrent processes never load a half-written library
            _seal(job.lib)
        except (OSError, subprocess.CalledProcessError) as err:
            job.error = getattr(err, "stderr", "") or str(err)


def _log(job: _Job) -> None:
    path = os.environ.get("MPGSPEC_JIT_LOG")
    if not path:
        return
    rec = {"name": job.name, "c_bytes": len(job.code), "gcc_s": round(job.gcc_s, 4), "hit": job.hit,
           "flags": list(job.flags), "cc": Path(job.cc).name if job.cc else os.environ.get("CC", "gcc")}
    if job.error is not None:
        rec["failed"] = True
    with _LOG_LOCK, open(path, "a") as f:
        f.write(json.dumps(rec) + "\n")


def _run_gcc(work: list[_Job], n_jobs: int | None = None) -> None:
    """gcc of the jobs not yet compiled, up to n_jobs at once (default: the usable cores); the same
    library twice is compiled once, its twin taking its outcome. Every job is logged."""
    todo = {}
    for j in work:
        if not j.hit and j.lib not in todo:
            todo[j.lib] = j
    if len(todo) > 1 and (n_jobs or usable_cores()) > 1:
        with ThreadPoolExecutor(max_workers=min(len(todo), n_jobs or usable_cores())) as pool:
            list(pool.map(_gcc, todo.values()))
    else:
        for j in todo.values():
            _gcc(j)
    for j in work:
        j.error = todo.get(j.lib, j).error
        _log(j)


def compile_many(fns: list[ca.Function], flags: tuple[str, ...], n_jobs: int | None = None,
                 libs: tuple[Path, ...] | list[tuple[Path, ...]] = ()) -> list[ca.Function]:
    """fns compiled (in their order), up to n_jobs gcc at once (default: the usable cores), linked
    against the libraries `libs` (of compile_library) whose Functions they call (one tuple for all,
    or a list with one tuple per Function); each library reused when its code and flags are
    unchanged. A Function whose compile fails comes back uncompiled, with a warning."""
    each = libs if isinstance(libs, list) else [tuple(libs)] * len(fns)
    work = [_job(fn, tuple(flags), tuple(lb)) for fn, lb in zip(fns, each)]
    _run_gcc(work, n_jobs)
    out = []
    for j in work:
        if j.error is not None:  # no compiler: CasADi's virtual machine
            warnings.warn(f"compiling {j.name} failed, running it uncompiled: {j.error[:300]}")
            out.append(j.fn)
        else:
            out.append(ca.external(j.fn.name(), str(j.lib)))
    return out


def compile_cached(fn: ca.Function, flags: tuple[str, ...], libs: tuple[Path, ...] = ()) -> ca.Function:
    """fn compiled to a shared library with the system C compiler (linked against `libs`), reused
    when the generated C code and the flags are unchanged (the library's name is the hash of both)."""
    return compile_many([fn], flags, libs=tuple(libs))[0]


def compile_library(name: str, fns: list[ca.Function], flags: tuple[str, ...], reverse: bool = True,
                    large: bool = False, libs: tuple[Path, ...] = (), wait: bool = True) -> Path | None:
    """The path of one library holding fns and (`reverse`) each one's reverse derivative (adj1_<name>,
    what a gradient through casadi.external of it calls), linked against `libs`, compiled once with
    `flags` (and LARGE_CODE_FLAGS when `large` and the code is large) and reused while its code is
    unchanged; None when the compiler fails (with a warning). Without `wait`, gcc runs in a
    background thread (no CasADi there) and None is returned at once: a later call with the same
    code waits on the library's lock and loads it."""
    job = library_job(name, fns, flags, reverse, large, libs)
    if not wait:
        if not job.hit:
            threading.Thread(target=_gcc, args=(job,), name=f"gcc {name}", daemon=True).start()
        return None
    return compile_libraries([job])[0]


def library_job(name: str, fns: list[ca.Function], flags: tuple[str, ...], reverse: bool = False,
                large: bool = False, libs: tuple[Path, ...] = ()) -> _Job:
    """The C code of one library holding fns (and each one's reverse derivative when `reverse`),
    generated in this thread: what compile_library and compile_libraries compile."""
    cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for fn in fns:
        cg.add(fn)
        if reverse:
            cg.add(fn.reverse(1))
    return _library_job(name, None, cg.dump(), tuple(flags), tuple(libs), large=large)


def compile_libraries(jobs: list[_Job], n_jobs: int | None = None) -> list[Path | None]:
    """The libraries of library_job, compiled side by side (up to n_jobs gcc at once, default the
    usable cores; no CasADi here, so this may run in a background thread); None where gcc failed."""
    _run_gcc(jobs, n_jobs)
    out = []
    for j in jobs:
        if j.error is not None:
            warnings.warn(f"compiling {j.name} failed: {j.error[:300]}")
        out.append(None if j.error is not None else j.lib)
    return out
