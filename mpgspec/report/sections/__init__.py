"""Report sections as plug-ins: each one is a module with its data (from the pipeline's results),
its schema model, its template part and its line in the summary, registered under the entry-point
group `mpgspec.report_sections` (registry.py).

To add a section, define a ReportSection and register it:

    [project.entry-points."mpgspec.report_sections"]
    my_section = "my_package.my_module:section"

Its data goes to report.json under `sections.<name>` (validated by its model), its template part is
rendered after the page section named by `after`. The built-in sections keep their report-v2 keys
at the top level of report.json (`top_level`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from pydantic import BaseModel


@dataclass(frozen=True)
class ReportSection:
    """One section of the report.

    data(cp, vg, ch): its JSON data from the pipeline's results (CompiledProject, VerifiedGraph,
    Checks), None when the project has nothing to show; model: the schema of that data;
    template: Jinja text rendered with r (the report), v (the page's view), s (this section's
    data) and sv (view(s)); count(s): its (label, number, detail) line in the summary, or None;
    after: the page section it follows ('edges' or 'sequence'); label: its link in the page's
    navigation, anchored at `name` unless anchor says otherwise."""

    name: str
    data: Callable[[Any, Any, Any], dict | None]
    model: Any
    template: str
    description: str = ""
    label: str = ""
    after: str = "sequence"
    view: Callable[[dict], Any] | None = None
    count: Callable[[dict], tuple | None] | None = None
    top_level: bool = False
    anchor: str = ""

    def validate(self, data) -> None:
        """Raise pydantic.ValidationError when data does not match the section's model."""
        if isinstance(self.model, type) and issubclass(self.model, BaseModel):
            self.model.model_validate(data)
