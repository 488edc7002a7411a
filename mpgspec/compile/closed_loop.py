"""The closed loop of a motion primitive (Definition 1) as one typed object.

CompiledPrimitive holds the named CasADi Functions of the loop under its law (f_cl, control, h,
the RoA margin, the setpoint), its contact plan (compile/contacts.py), E's weight W, the safe
set's windows and the clock's switching times; oracle/flow.py steps it. It pickles through
CasADi's serialisation, so the compile cache and worker processes can store and ship it.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import pickle
import re
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..spec.models import PrimitiveClass
from .contacts import ContactPlan, wrap_clock
from .events import EventWindow
from .guards import Guards
from .hold import SampledLaw
from .numeric import content_hash
from .system import CompiledSystem


@dataclass
class CompiledPrimitive:
    """A motion primitive as CasADi Functions plus the numbers the graph builder needs."""

    name: str
    cls: PrimitiveClass
    system: CompiledSystem
    period: float | None
    domain: tuple[float, float] | None
    next: str | None
    horizon: float | None
    grid_A: int
    grid_B: int
    h_names: list[str]
    radius: float
    f_cl: ca.Function  # (x, t, s, x_sw) -> xdot under the saturated control law
    control: ca.Function  # (x, t, s, x_sw) -> (u_raw, u_sat)
    h: ca.Function  # (x, t, s, x_sw) -> h values; >= 0 is safe
    roa_margin: ca.Function  # (x, t) -> r - ||x - x*(t)||_W ; > 0 is inside E
    setpoint: ca.Function  # t -> x*(t)
    W: np.ndarray  # the weight of E's norm ||x - x*(t)||_W (zero on event clocks)
    info: dict = field(default_factory=dict)  # the record the report prints: the law's data, the contact
    # plan and W as lists; code reads the typed fields
    contacts: ContactPlan | None = None  # which feet the dynamics hold, and when; None without contacts
    jump: ca.Function | None = None  # (x, u, t, s) -> x: the discrete part of a step (quaternion, contacts)
    loop: ca.Function | None = None  # (x, t, s, x_sw) -> (xdot, h, u_raw, u) with one control evaluation
    loop_raw: ca.Function | None = None  # the same with every safety function active (no `when` windows)
    windows: list[tuple[float, float] | EventWindow | None] = field(default_factory=list)  # per safety function:
    # a clock window [t0, t1) or one anchored on a contact event (compile/events.py); None: always active
    boundaries: tuple[float, ...] = ()  # clock times where C or the contact schedule switches
    hybrid: bool = False  # the state jumps (contact events or a contact schedule), not only renormalised
    sampled: SampledLaw | None = None  # a law the oracle solves at a control rate and holds in between
    loop_u: ca.Function | None = None  # (x, t, s, x_sw, u_raw) -> (xdot, h, u_raw, u): the open loop under a
    # given input, every safety function active (as loop_raw); set with `sampled`
    guards: Guards = field(default_factory=Guards)  # where f_cl switches or kinks (compile/guards.py)
    open_loop: ca.Function | None = None  # loop_u's signature for every law (loop_u itself when sampled): h under
    # an input the law did not ask at x (a law reading a delayed or noisy state); made of loop_raw's expressions,
    # so not part of the digest
    grid_phase: float = 0.0  # clock of a periodic primitive's first grid sample (spec: grid.phase)
    narrow: tuple[tuple[float, float], ...] = ()  # phase intervals [lo, hi) where E(t) is narrower (roa.before_touchdown)
    narrow_ratio: float = 1.0  # E's radius there over `radius`
    cache: dict = field(default_factory=dict, repr=False)  # compiled oracle chunks by settings

    def __reduce__(self):
        """Pickles through CasADi's serialisation (compiled chunks are dropped and rebuilt from the
        on-disk cache where they are needed), so a closed loop can be shipped to worker processes."""
        state = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "cache"}
        with ca.global_pickle_context():
            blob = pickle.dumps(state)
        return _restore, (blob,)

    @property
    def needs(self) -> set[str]:
        """Capabilities a backend must have to run this closed loop."""
        out = {"hybrid"} if self.hybrid else set()
        if self.sampled is not None or not self.f_cl.is_a("SXFunction"):
            out.add("compiled")
        return out

    def horizons(self, T: float, t0s) -> np.ndarray:
        """How long the oracle runs from each switch-in clock t0: the primitive's own horizon, else
        the project's T, and never past the end t_f of a transient's domain."""
        t0s = np.atleast_1d(np.asarray(t0s, float))
        h = np.full(t0s.shape, float(self.horizon or T))
        if self.cls is PrimitiveClass.TRANSIENT:
            h = np.minimum(h, self.domain[1] - t0s)
        return np.maximum(h, 0.0)

    def digest(self) -> str:
        """Content hash of everything that decides an oracle verdict of this closed loop."""
        if "digest" not in self.cache:
            parts = [content_hash(f) for f in (self.loop_raw or self.loop, self.f_cl, self.roa_margin, self.setpoint,
                                                self.jump, self.loop_u) if f is not None]
            if self.sampled is not None:
                parts += [content_hash(self.sampled.solve), repr(self.sampled.period)]
            nums = repr((self.name, self.cls.value, self.period, self.domain, self.next, self.horizon, self.h_names,
                         self.radius, self.narrow, self.narrow_ratio, self.windows, self.boundaries, self.hybrid, self.W.tolist(),
                         self.system.u_lo.tolist(), self.system.u_hi.tolist()))
            self.cache["digest"] = hashlib.sha256("\n".join([*parts, nums]).encode()).hexdigest()
        return self.cache["digest"]

    @property
    def t_range(self) -> tuple[float, float]:
        """Clock interval sampled by the grids (Algorithm 1)."""
        if self.cls is PrimitiveClass.PERIODIC:
            return (0.0, float(self.period))
        if self.cls is PrimitiveClass.TRANSIENT:
            return self.domain
        return (0.0, 0.0)

    def start_clock(self) -> float:
        """The clock the primitive starts at when no verified t_B gives one: its domain's start for a
        transient, else 0."""
        return self.domain[0] if self.cls is PrimitiveClass.TRANSIENT else 0.0

    def clock_grid(self, n: int, role: str = "B") -> np.ndarray:
        """Grid over the clock: one point (fixed), n over one period (from grid_phase on), n over the domain.

        As a source (role 'A') a transient's grid ends at t_f, where it hands over to `next`;
        as a target (role 'B') it stops short of t_f, where no time would be left to converge.
        """
        a, b = self.t_range
        if self.cls is PrimitiveClass.FIXED:
            return np.zeros(1)
        if self.cls is PrimitiveClass.PERIODIC:
            return a + np.sort(np.mod(self.grid_phase + (b - a) * np.arange(n) / n, b - a))
        if n == 1:
            return np.array([b if role == "A" else a])
        return np.linspace(a, b, n) if role == "A" else np.linspace(a, b, n + 1)[:-1]

    def x_star(self, t) -> np.ndarray:
        return np.array(self.setpoint(t)).ravel()

    def radius_scale(self, t):
        """E(t)'s radius over `radius` at clock(s) t: narrow_ratio in the `narrow` phase intervals, else 1."""
        return narrowing(t, self.narrow, self.narrow_ratio, self.period)

    def radius_at(self, t):
        """E(t)'s radius at clock(s) t."""
        return self.radius * self.radius_scale(t)

    def with_radius(self, radius: float) -> "CompiledPrimitive":
        """The same primitive with E resized (a narrower stretch keeps its ratio); only the RoA margin is rebuilt."""
        margin = roa_margin_function(self.system, self.setpoint, self.W, radius, function_name(self.name),
                                     self.narrow, self.narrow_ratio, self.period)
        return dataclasses.replace(self, radius=radius, roa_margin=margin, cache={})


def _restore(blob: bytes) -> "CompiledPrimitive":
    with ca.global_unpickle_context():
        state = pickle.loads(blob)
    return CompiledPrimitive(**state)


def narrowing(t, narrow: tuple, ratio: float, period: float | None):
    """ratio where the clock t (a number, numpy array or CasADi expression), wrapped into the period, lies in
    one of the `narrow` intervals [lo, hi), else 1."""
    if not narrow:
        return ca.DM(1.0) if isinstance(t, (ca.SX, ca.MX)) else np.ones_like(np.asarray(t, float))[()]
    ph = wrap_clock(t, period)
    if isinstance(t, (ca.SX, ca.MX)):  # logic_or takes two operands: fold over the intervals
        inside = functools.reduce(ca.logic_or, [ca.logic_and(ph >= lo, ph < hi) for lo, hi in narrow])
        return ca.if_else(inside, ratio, 1.0)
    ph = np.asarray(ph, float)
    inside = np.zeros(ph.shape, bool)
    for lo, hi in narrow:
        inside |= (ph >= lo) & (ph < hi)
    return np.where(inside, ratio, 1.0)[()]


def roa_margin_function(sys: CompiledSystem, setpoint: ca.Function, W: np.ndarray, radius: float, ident: str,
                        narrow: tuple = (), ratio: float = 1.0, period: float | None = None) -> ca.Function:
    """(x, t) -> r(t) - ||x - x*(t)||_W, positive inside E(t); wrapped states measured the short way round.
    r(t) is `radius`, times `ratio` in the `narrow` phase intervals of the period."""
    sym = ca.MX if not setpoint.is_a("SXFunction") else ca.SX  # a table lookup is an MX Function
    x, t = (ca.MX.sym("x", sys.nx) if sym is ca.MX else sys.x), sym.sym("t")
    dx = sys.wrapped_error(x - setpoint(t))
    r = radius * narrowing(t, narrow, ratio, period) if narrow else radius
    margin = r - ca.sqrt(ca.mtimes([dx.T, ca.DM(W), dx]))
    return ca.Function(f"roa_{ident}", [x, t], [margin], ["x", "t"], ["margin"])


def function_name(name: str) -> str:
    """A valid CasADi Function name part for a node name such as 'Swing(-1.5)' or '_B'.

    CasADi accepts only ASCII letters, digits and single underscores, starting with a letter
    (its callers prefix one). Names that had to be changed get a short hash, so that distinct
    nodes (Swing(-1), Swing(1)) keep distinct Function names.
    """
    base = re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "p"
    if base != name:
        base += "_" + hashlib.sha1(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return base
