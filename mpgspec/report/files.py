"""Write one project's report set: JSON (the source of truth), HTML from it, the graph as DOT/GraphML."""
from __future__ import annotations

from pathlib import Path

from ..graph.transition import MotionPrimitiveGraph
from .export import to_dot, to_graphml
from .html import render_html
from .write import write_atomic, write_json


def write_reports(report: dict, graph: MotionPrimitiveGraph, folder: Path, formats=("json", "html", "dot", "graphml")) -> dict[str, str]:
    """Write the requested formats into folder; returns format -> path."""
    folder = Path(folder)
    files = {}
    if "json" in formats:
        files["json"] = str(write_json(folder / "report.json", report, compact=True))
        files["lookup_table"] = str(write_json(folder / "lookup_table.json", report["lookup_table"]))
    if "html" in formats:
        files["html"] = str(write_atomic(folder / "report.html", render_html(report)))
    if "dot" in formats:
        files["dot"] = str(write_atomic(folder / "graph.dot", to_dot(report)))
    if "graphml" in formats:
        files["graphml"] = str(write_atomic(folder / "graph.graphml", to_graphml(report)))
    return files
