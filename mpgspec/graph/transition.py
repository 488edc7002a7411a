"""Transitions (Definition 2) and the motion primitive graph that holds them (Definition 3)."""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import networkx as nx
import numpy as np

from ..compile.primitive import INACTIVE
from ..oracle.evidence import OracleEvidence


class TransitionClass(IntEnum):
    """Class 1: some t_B works for every t_A (solid edge); Class 2: only for some t_A (dashed)."""

    NONE = 0
    CLASS_1 = 1
    CLASS_2 = 2


@dataclass
class Transition:
    """Oracle grid of one ordered pair (A, B) and what it implies for switching from A to B."""

    source: str
    target: str
    t_A: np.ndarray
    t_B: np.ndarray
    evidence: list[list[OracleEvidence]]  # [i_A][i_B]
    cls: TransitionClass = TransitionClass.NONE
    best_t_B: list[float | None] = field(default_factory=list)  # per t_A: the t_B to switch in at
    windows: list[tuple[float, float]] = field(default_factory=list)  # t_A intervals with a safe t_B
    weights: dict[str, float] = field(default_factory=dict)
    row_margins: list[float | None] = field(default_factory=list)
    """Per t_A: the least normalised safety margin of the cell at its best t_B (see measure_margins),
    None where no t_B is verified; empty until measured."""
    row_from_roa: list[list | None] = field(default_factory=list)
    """Per t_A: [share of r_A the executor may switch within, samples of E_A's boundary safe, samples drawn]
    at the row's best t_B (robust/from_roa.py; share 0: refused), None where the row was not checked;
    empty when no such check ran."""
    from_roa_worst: dict | None = None
    """The worst sample of E_A's boundary that was not safe: t_A, t_B, sample, status, violated h, margin."""
    certified: dict = field(default_factory=dict)
    """t_A intervals proved for every t_A in them, not only at grid points: {windows: [[a, b], ...],
    boxes: start boxes used, order: Taylor order, width: largest start-box width, seconds}; empty
    when no such proof was run."""

    @property
    def verdicts(self) -> np.ndarray:
        return np.array([[e.verdict for e in row] for row in self.evidence], dtype=int)

    @property
    def available(self) -> np.ndarray:
        """Per t_A: does some t_B give O_B = 1."""
        return self.verdicts.any(axis=1)

    def rests_on(self) -> list[OracleEvidence]:
        """The cells the pair's verdict rests on: the safe cells of an edge, every cell of a pair without one."""
        flat = [e for row in self.evidence for e in row]
        return [e for e in flat if e.verdict == 1] or flat

    @property
    def method(self) -> str:
        """'certified' when every cell the verdict rests on was proved (evidence method 'certified'),
        else 'simulated': one rollout judged by its error bounds is enough to make the pair simulated."""
        cells = self.rests_on()
        return "certified" if cells and all(e.method == "certified" for e in cells) else "simulated"

    def classify(self) -> None:
        """Algorithm 1 lines 9-14, then the switch-in clock, windows and weights."""
        V = self.verdicts
        avail = V.any(axis=1)
        self.cls = (TransitionClass.CLASS_1 if avail.all() else
                    TransitionClass.CLASS_2 if avail.any() else TransitionClass.NONE)
        self.best_t_B, durations, peaks = [], [], []
        for i in range(len(self.t_A)):
            ok = [j for j in range(len(self.t_B)) if V[i, j]]
            if not ok:
                self.best_t_B.append(None)
                continue
            j = min(ok, key=lambda j: self.evidence[i][j].t_enter)
            e = self.evidence[i][j]
            self.best_t_B.append(float(self.t_B[j]))
            durations.append(e.t_enter)
            peaks.append(max(e.peak_input, default=0.0))
        self.windows = _windows(self.t_A, avail)
        if durations:
            self.weights = {"duration": float(max(durations)), "peak_input": float(max(peaks)), "hops": 1.0}

    def measure_margins(self, names: list[str], scales: np.ndarray) -> float | None:
        """Fill row_margins and return the edge's least: per t_A, the least normalised safety margin of
        the cell it switches through (its best t_B): each safety function's error-aware lower bound
        over the rollout divided by its value at B's setpoint at that t_B (scales[j], one row per t_B
        in the order of names; a function at most 0 there, or parked outside its window, is left out).
        1: the flow keeps every function as far from its boundary as the setpoint does; 0: it touches
        one. 1 where no function can be normalised (B has none, or none is positive at its setpoint);
        None without a verified cell."""
        raw = [None if t_b is None else self._normalised(i, t_b, names, scales)
               for i, t_b in enumerate(self.best_t_B)]
        self.row_margins = [None if t_b is None else 1.0 if m is None else m for t_b, m in zip(self.best_t_B, raw)]
        kept = [m for m in raw if m is not None]
        return min(kept) if kept else 1.0 if any(m is not None for m in self.row_margins) else None

    def _normalised(self, i: int, t_b: float, names: list[str], scales: np.ndarray) -> float | None:
        """The least normalised margin of row i's cell at t_b, None when no function can be normalised."""
        j = int(np.argmin(np.abs(self.t_B - t_b)))
        e, out = self.evidence[i][j], None
        for k, h in enumerate(names):
            lb, ref = e.lower_bounds.get(h), float(scales[j][k])
            if lb is None or not np.isfinite(lb) or not (0 < ref < INACTIVE / 2):
                continue
            m = max(float(lb), 0.0) / ref
            out = m if out is None else min(out, m)
        return out

    def switch_clock(self, t_A: float) -> float | None:
        """The verified t_B for a grid time t_A, None where no transition starts."""
        i = int(np.argmin(np.abs(self.t_A - t_A)))
        return self.best_t_B[i] if abs(self.t_A[i] - t_A) < 1e-9 else None

    def _switched_cells(self) -> list[OracleEvidence | None]:
        """Per t_A: the cell it switches through (its best t_B), None where it has none."""
        return [None if t_b is None else self.evidence[i][int(np.argmin(np.abs(self.t_B - t_b)))]
                for i, t_b in enumerate(self.best_t_B)]

    @property
    def row_keeps(self) -> list[dict[str, float] | None]:
        """Per t_A: the least sampled value of each safety function family (friction_cone for
        friction_cone[FR_foot]) in the cell it switches through, to CELL_DIGITS as report.json keeps it
        (a family whose functions have no value there is absent)."""
        out: list[dict[str, float] | None] = []
        for e in self._switched_cells():
            if e is None:
                out.append(None)
                continue
            least: dict[str, float] = {}
            for name, v in e.min_margins.items():
                if v is not None and np.isfinite(v):
                    fam = family(name)
                    least[fam] = min(least.get(fam, np.inf), float(f"{float(v):.{CELL_DIGITS}g}"))
            out.append(least)
        return out

    @property
    def row_peaks(self) -> list[list[float] | None]:
        """Per t_A: the largest |u| of each input in the cell it switches through (its best t_B)."""
        return [None if e is None else list(e.peak_input) for e in self._switched_cells()]


MARGIN_SHARE = 0.8
"""Under the 'margin' rule, a t_A is taken when its row margin is at least this share of the edge's best."""
CELL_DIGITS = 4
"""Significant digits of a cell's peak inputs and least safety function values as report.json keeps them:
the reserve and keep compare these, so that a run from the report switches where the verify's run did."""


def family(name: str) -> str:
    """A safety function's family: its name before an index (friction_cone[FR_foot] -> friction_cone)."""
    return name.split("[", 1)[0]


def switch_clocks(tr, rule: str = "first", reserve: float | None = None, bound=None,
                  keep: dict[str, float] | None = None) -> list[float | None]:
    """Per t_A of a transition (Transition or a report's): the t_B an executor switches in at, None
    where it does not switch. 'first': at every verified t_A, so the first one the run meets is taken;
    'margin': only at the verified t_A whose row margin is at least MARGIN_SHARE of the edge's best
    (an executor in a periodic primitive then waits for the well-kept switches of its cycle; where the
    margins were not measured, as 'first'). With `reserve` and the inputs' bounds (largest |u| each),
    a t_A whose cell asks more than reserve x bound of some input, or whose peaks are unknown, is not
    taken either. With `keep` ({family: least value}), a t_A whose cell's least sampled value of a named
    safety function family is below the value given is not taken (a family the cell has no value of asks
    nothing; a row whose values are unknown altogether, such as a report without them, is not taken). A row checked from the boundary of E_A (row_from_roa) with a sample not safe is never
    taken: the executor leaves A from anywhere in E_A."""
    out = _by_rule(tr, rule)
    if keep:
        least = list(getattr(tr, "row_keeps", None) or [])
        out = [b if i < len(least) and least[i] is not None and
               all(least[i].get(f, np.inf) >= float(v) for f, v in keep.items()) else None
               for i, b in enumerate(out)]
    if reserve is None or bound is None:
        return out
    lim = reserve * np.asarray(bound, float)
    peaks = list(getattr(tr, "row_peaks", None) or [])
    within = [i < len(peaks) and peaks[i] is not None and len(peaks[i]) == len(lim) and
              all(p is not None and float(f"{p:.{CELL_DIGITS}g}") <= m for p, m in zip(peaks[i], lim))
              for i in range(len(out))]
    return [b if k else None for b, k in zip(out, within)]


def input_bounds(system) -> np.ndarray:
    """The largest |u| of each input of a system: the `bound` a reserve is a share of."""
    return np.maximum(np.abs(system.u_lo), np.abs(system.u_hi))


def executor_clocks(tr, transient: bool, rule: str, reserve: float | None = None, bound=None,
                    keep: dict[str, float] | None = None) -> list[float | None]:
    """switch_clocks as the graph executor takes them: a transient hands over to its next at the end of its
    domain, at every verified clock (no rule, reserve or keep chooses a time there); any other source by the
    sequence's rule, reserve and keep."""
    return switch_clocks(tr, "first") if transient else switch_clocks(tr, rule, reserve, bound, keep)


def switch_shares(tr) -> list[float]:
    """Per t_A: the share of r_A within which the executor may switch through the row (robust/from_roa.py):
    1 where the row was not checked from E_A's boundary, 0 where it was refused."""
    rows = list(getattr(tr, "row_from_roa", None) or [])
    return [1.0 if i >= len(rows) or rows[i] is None else float(rows[i][0]) for i in range(len(tr.best_t_B))]


def from_roa_ok(tr) -> list[bool]:
    """Per t_A: not refused by the check from E_A's boundary."""
    return [s > 0 for s in switch_shares(tr)]


def _by_rule(tr, rule: str) -> list[float | None]:
    """The rows the rule takes among those the check from E_A's boundary did not refuse."""
    best = [b if ok else None for b, ok in zip(tr.best_t_B, from_roa_ok(tr))]
    rows = list(getattr(tr, "row_margins", None) or [])
    if rule == "first" or len(rows) != len(best):
        return best
    top = max((m for m, b in zip(rows, best) if m is not None and b is not None), default=None)
    if top is None:
        return best
    return [b if b is not None and m is not None and m >= MARGIN_SHARE * top else None for b, m in zip(best, rows)]


def _windows(t: np.ndarray, avail: np.ndarray) -> list[tuple[float, float]]:
    """Maximal runs of available grid points as [first, last] t_A intervals."""
    out, start = [], None
    for i, a in enumerate(avail):
        if a and start is None:
            start = float(t[i])
        if not a and start is not None:
            out.append((start, float(t[i - 1])))
            start = None
    if start is not None:
        out.append((start, float(t[-1])))
    return out


class MotionPrimitiveGraph:
    """A networkx DiGraph of primitives (nodes, with their class) and Class 1/2 transitions (edges)."""

    def __init__(self, nodes: dict[str, dict], transitions: dict[tuple[str, str], Transition]):
        self.transitions = transitions
        self.G = nx.DiGraph()
        for name, attrs in nodes.items():
            self.G.add_node(name, **attrs)
        for (a, b), tr in transitions.items():
            if tr.cls is not TransitionClass.NONE:
                self.G.add_edge(a, b, cls=int(tr.cls), **tr.weights)

    def edge(self, a: str, b: str) -> Transition | None:
        tr = self.transitions.get((a, b))
        return tr if tr is not None and tr.cls is not TransitionClass.NONE else None

    @property
    def nodes(self) -> list[str]:
        return list(self.G.nodes)
