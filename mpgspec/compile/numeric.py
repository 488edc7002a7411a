"""CasADi Functions called on numpy arrays through one bound FunctionBuffer.

`Function.__call__` converts every argument and result through DM, about 50 us per call; checks
that evaluate a small function hundreds of thousands of times (projections onto the contact
manifold, h on sampled states) spend most of their time there. A NumericFunction evaluates the
same compiled expression graph on preallocated arrays, so its numbers are the same bits.
"""
from __future__ import annotations

import threading

import casadi as ca
import numpy as np


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
