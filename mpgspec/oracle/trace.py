"""Dense rollouts for pictures: h, the RoA margin and the input over time for one start point."""
from __future__ import annotations

import numpy as np

from ..compile.primitive import INACTIVE, CompiledPrimitive
from ..settings import OracleSettings
from .integrator import build_chunk, build_chunks, initial_state
from .pieces import guarded

TRACE_STEPS = 64
"""Steps per compiled call of a trace."""


def prebuild(prims: list[CompiledPrimitive], settings: OracleSettings) -> None:
    """Compile the trace chunks of several primitives side by side (gcc in parallel) before tracing.
    A primitive that cannot be built here is left to its own trace, which records the error."""
    if not (settings.jit and prims):
        return
    try:
        build_chunks(prims, settings.dt, TRACE_STEPS, tuple(settings.jit_flags), with_state=True, boundaries=False)
    except Exception:  # noqa: BLE001 - each trace builds its chunk again and reports its own failure
        pass


def trace(prim: CompiledPrimitive, x0: np.ndarray, t0: float, horizon: float, settings: OracleSettings,
          max_points: int = 400) -> dict:
    """Roll B's closed loop from x0 at clock t0 for `horizon` seconds; series decimated to max_points."""
    ch = build_chunk(prim, settings.dt, TRACE_STEPS, settings.jit, settings.jit_flags, with_state=True, boundaries=False)
    n = int(np.ceil(horizon / settings.dt - 1e-9)) + 1
    z = initial_state(prim, np.asarray(x0, float), t0)
    outs = []
    failed = None
    while sum(o.shape[1] for o in outs) < n:
        try:
            zf, out = ch.run(z[:, None])
        except RuntimeError as err:  # the trace ends where the compiled rollout failed
            failed = str(err)
            break
        outs.append(out[:, 0, :])
        z = zf[:, 0]
        if not np.isfinite(z).all():
            break
    if not outs:
        return {"t": [], "h": {name: [] for name in prim.h_names}, "roa_margin": [], "u": [[] for _ in range(prim.system.nu)],
                "x": [[] for _ in range(prim.system.nx)], "failed": failed}
    O = np.concatenate(outs, axis=1)[:, :n]
    r = ch.rows
    stride = max(1, O.shape[1] // max_points)
    sel = slice(0, O.shape[1], stride)
    t = O[r.s, sel]

    def clean(v):
        out = v.tolist()
        for k in np.flatnonzero(~(np.abs(v) < INACTIVE / 2)).tolist():  # non-finite or inactive
            out[k] = None
        return out

    return {
        "t": [float(a) for a in t],
        **({"crossings": _crossings(O[r.s], O[r.dt], settings.dt)} if guarded(prim) else {}),
        "h": {name: clean(O[i, sel]) for i, name in enumerate(prim.h_names)},
        "roa_margin": clean(O[r.margin, sel]),
        "u": [clean(O[r.u.start + i, sel]) for i in range(r.nu)],
        "x": [clean(O[r.x.start + i, sel]) for i in range(prim.system.nx)],
        **({"failed": failed} if failed else {}),
    }


MAX_CROSSINGS = 50
"""Times of located guard crossings a trace keeps (their count is always whole)."""


def _crossings(s: np.ndarray, dt: np.ndarray, step: float) -> dict:
    """Where the rollout's steps ended at a located guard crossing: a trace steps without window
    boundaries, so a step shorter than `step` is a piece that ends just before a crossing, or a
    sliver stepped across one right after its start (oracle/pieces.py); short steps ending within
    1e-4 `step` of each other are one crossing. {count, t: the first MAX_CROSSINGS crossings, in
    seconds after switch-in}."""
    ends = (s + dt)[dt < step * (1 - 1e-9)]
    ends = ends[np.concatenate([[True], np.diff(ends) > 1e-4 * step])] if len(ends) else ends
    return {"count": int(len(ends)), "t": [float(v) for v in ends[:MAX_CROSSINGS]]}
