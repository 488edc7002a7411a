"""CasADi Functions called on numpy arrays through one bound FunctionBuffer, point by point or
mapped over many points.

`Function.__call__` converts every argument and result through DM, about 50 us per call; checks
that evaluate a small function hundreds of thousands of times (projections onto the contact
manifold, h on sampled states) spend most of their time there. A NumericFunction evaluates the
same compiled expression graph on preallocated arrays, so its numbers are the same bits.
"""
from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

import casadi as ca
import numpy as np

_F64 = np.dtype(float)


class NumericFunction:
    """fn(*arrays) -> list of dense numpy arrays (column-major vec of each output, as `.full().ravel("F")`).

    One set of buffers behind a lock (threads take turns); pickles as the Function it wraps."""

    def __init__(self, fn: ca.Function):
        self.fn = fn
        self._lock = threading.Lock()
        self.shapes = [fn.size_out(i) for i in range(fn.n_out())]
        self._buf, self._ev = fn.buffer()
        self._args, self._gather = _bound([fn.sparsity_in(i) for i in range(fn.n_in())], self._buf.set_arg)
        self._res, self._scatter = _bound([fn.sparsity_out(i) for i in range(fn.n_out())], self._buf.set_res)

    def __call__(self, *args) -> list[np.ndarray]:
        with self._lock:
            return self._call(args)

    def _call(self, args) -> list[np.ndarray]:
        for a, g, v in zip(self._args, self._gather, args):
            if g is None and (isinstance(v, float) or v.__class__ is np.ndarray and v.ndim == 1 and v.dtype is _F64):
                a[:] = v  # a float or a vector of doubles: copied as is (the common case, without conversions)
            else:
                v = np.ravel(np.asarray(v, float), order="F")
                a[:] = v if g is None else v[g]
        self._ev()
        if self._buf.ret():
            raise RuntimeError(f"evaluating {self.fn.name()} failed")
        out = []
        for r, s, (n, m) in zip(self._res, self._scatter, self.shapes):
            if s is None:
                out.append(r.copy())
            else:
                dense = np.zeros(n * m)
                dense[s] = r
                out.append(dense)
        return out

    def __reduce__(self):
        return NumericFunction, (self.fn,)


def _bound(sparsities: list, bind) -> tuple[list[np.ndarray], list]:
    """One array of nonzeros per sparsity, bound to the buffer by bind(i, memoryview), and the
    positions of those nonzeros in the dense column-major vector (None when dense)."""
    arrays = [np.zeros(sp.nnz()) for sp in sparsities]
    for i, a in enumerate(arrays):
        bind(i, memoryview(a))
    return arrays, [None if sp.is_dense() else np.asarray(sp.find(), int) for sp in sparsities]


def numeric(fn: ca.Function) -> NumericFunction:
    return NumericFunction(fn)


class NumericMap:
    """fn over many points at once: m(*args) -> list of (n, numel) arrays, row i the column-major vec
    of each output at point i (the bits NumericFunction gives point by point).

    Inputs listed in `shared` take one value for all points; every other input is an (n, numel)
    array, one point a row. The points go through CasADi maps of fn (serial: the same compiled
    expression graph per point), of power-of-two sizes so that a handful of maps serves any n."""

    def __init__(self, fn: ca.Function, shared: tuple[int, ...] = ()):
        self.fn, self.shared = fn, tuple(shared)
        self._maps: dict[int, NumericFunction] = {}
        self._lock = threading.Lock()
        self.sizes = [int(np.prod(fn.size_out(i))) for i in range(fn.n_out())]

    def _map(self, n: int) -> NumericFunction:
        with self._lock:
            if n not in self._maps:
                m = self.fn.map(f"{self.fn.name()}_map{n}", "serial", n, list(self.shared), [])
                self._maps[n] = NumericFunction(m)
            return self._maps[n]

    def __call__(self, *args) -> list[np.ndarray]:
        rows = [None if i in self.shared else np.atleast_2d(np.asarray(a, float)) for i, a in enumerate(args)]
        n = next(r.shape[0] for r in rows if r is not None)
        out = [np.empty((n, s)) for s in self.sizes]
        start = 0
        for bit in reversed(range(n.bit_length())):
            size = 1 << bit
            if not n & size:
                continue
            part = [a if r is None else r[start:start + size].T for a, r in zip(args, rows)]
            for o, v in zip(out, self._map(size)(*part)):
                o[start:start + size] = v.reshape(size, -1)
            start += size
        return out

    def __reduce__(self):
        return NumericMap, (self.fn, self.shared)


def numeric_map(fn: ca.Function, shared: tuple[int, ...] = ()) -> NumericMap:
    return NumericMap(fn, shared)


_HASHES: OrderedDict = OrderedDict()  # id(fn) -> (fn, hash); fn kept so its id is not reused while listed
_HASHES_KEPT = 256
_HASHES_LOCK = threading.Lock()


def by_column(fn, args: list[np.ndarray]) -> tuple[list[np.ndarray] | None, list[int]]:
    """(outputs, failed columns) of fn(*args) over the columns of args (each output at least 2-D): when
    the batch's call fails (RuntimeError: a compiled evaluation reporting an error, such as a control law
    that finds no input), each column alone, a failing one NaN in every output (None when all fail), so
    a failure is that column's evidence, not its batch's."""
    try:
        return [np.atleast_2d(o) for o in fn(*args)], []
    except RuntimeError:
        n = args[0].shape[1]
        outs, failed = None, []
        for c in range(n):
            try:
                res = [np.atleast_2d(o) for o in fn(*[a[:, [c]] for a in args])]
            except RuntimeError:
                failed.append(c)
                continue
            if outs is None:
                outs = [np.full((o.shape[0], n), np.nan) for o in res]
            for o, r in zip(outs, res):
                o[:, c] = r[:, 0]
        return outs, failed


def content_hash(fn: ca.Function) -> str:
    """sha256 of fn's serialization, computed once per Function object: a primitive's digest, its loop
    library's name and its records' keys all hash the same loops (the A1's take about 30 ms each)."""
    with _HASHES_LOCK:
        hit = _HASHES.get(id(fn))
        if hit is not None and hit[0] is fn:
            _HASHES.move_to_end(id(fn))
            return hit[1]
    h = hashlib.sha256(fn.serialize().encode()).hexdigest()
    with _HASHES_LOCK:
        _HASHES[id(fn)] = (fn, h)
        while len(_HASHES) > _HASHES_KEPT:
            _HASHES.popitem(last=False)
    return h
