"""The robust section: the edges that withstood the project's uncertainty in every scenario tried,
each target's own flow and the goal sequence under sampled uncertainty (mpgspec.robust; empirical)."""
from __future__ import annotations

from importlib.resources import files

from . import ReportSection


def data(cp, vg, ch) -> dict | None:
    """The robust graph, when the project declares `uncertainty`."""
    return ch.robust.to_dict() if ch.robust is not None else None


LISTED = 4
"""Nominal-only edges the summary names; more are counted (the robust section lists them)."""


def count(rob: dict) -> tuple:
    """The summary line of the robust graph: edges that survive uncertainty, the nominal-only ones and
    the safe runs of the goal sequence under sampled uncertainty per mode (and, through a graph, those
    that were in every goal: a run that waits safely in one primitive is safe but gets nowhere)."""
    sm = rob.get("summary") or {}
    lost = sm.get("nominal_only") or []
    runs = ((rob.get("sequence") or {}).get("modes") or {}).items()
    names = {"graph": "nominal graph", "robust_graph": "robust graph"}
    seq = "; disturbed sequence safe: " + ", ".join(
        f"{names.get(m, m)} {x['safe_runs']}/{x['runs']}"
        + (f" ({x['reached_goal']} in every goal)" if m != "naive" and "reached_goal" in x else "") for m, x in runs)
    return ("robust edges", sm.get("robust_edges", "–"),
            f"of {sm.get('nominal_edges', '–')}; " + ((f"nominal only: {', '.join(lost)}" if len(lost) <= LISTED
                                                        else f"{len(lost)} nominal only (listed under robust)")
                                                       if lost else "none lost")
            + (seq if runs else "") + " (empirical)")


section = ReportSection(
    name="robust", data=data, model=dict, top_level=True, after="edges", label="robust",
    template=files(__package__).joinpath("robust.html.j2").read_text(encoding="utf-8"),
    description="the robust graph (mpgspec.robust): edges that withstood the project's uncertainty in every "
                "scenario tried; empirical, not proof",
    count=count)
