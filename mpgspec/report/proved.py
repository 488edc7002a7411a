"""The t_A intervals a report proves for every t_A in them, written without claiming more.

A proved interval [a, b] is shown rounded inwards (a up, b down), so that the text never covers a
t_A the proof did not; the report keeps the unrounded numbers.
"""
from __future__ import annotations

from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal


def proved_windows(tr: dict | None) -> list[list[float]]:
    """The intervals of a report transition's `certified` record; [] when nothing was proved."""
    return [list(w) for w in ((tr or {}).get("certified") or {}).get("windows") or []]


def _rounded(v: float, digits: int, rounding: str) -> Decimal:
    d = Decimal(repr(float(v)))  # the float's shortest decimal: 0.1 stays 0.1
    if d == 0:
        return d
    return d.quantize(Decimal(1).scaleb(d.adjusted() - digits + 1), rounding=rounding)


def interval_text(a: float, b: float, digits: int = 4) -> str:
    """[a, b] with a rounded up and b down to `digits` significant digits (in full when that empties it)."""
    lo, hi = _rounded(a, digits, ROUND_CEILING), _rounded(b, digits, ROUND_FLOOR)
    if lo > hi:
        return f"[{float(a)!r}, {float(b)!r}]"
    return f"[{float(lo):.{digits}g}, {float(hi):.{digits}g}]"


def proved_text(tr: dict | None, digits: int = 4) -> str:
    """'certified for every t_A in [a, b], ...' of a report transition, or '' when nothing was proved."""
    ws = proved_windows(tr)
    if ws and all(a == b for a, b in ws):  # a fixed source: its one t_A is its grid cell
        return "certified at its one t_A = " + ", ".join(f"{a:.{digits}g}" for a, _ in ws)
    return "certified for every t_A in " + ", ".join(interval_text(a, b, digits) for a, b in ws) if ws else ""
