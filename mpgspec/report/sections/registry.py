"""Registry of report sections, loaded from the entry-point group `mpgspec.report_sections`.

The built-in sections are listed here too, so that a source tree without installed metadata still
writes them; an installed entry point of the same name replaces one. register() adds an entry point
in this process, the way an installed one is found (a notebook or a test uses it)."""
from __future__ import annotations

from functools import lru_cache
from importlib.metadata import EntryPoint

from ... import plugins
from ...plugins import group_entry_points
from . import ReportSection

GROUP = "mpgspec.report_sections"
BUILTIN = {"robust": "mpgspec.report.sections.robust:section",
           "crosscheck": "mpgspec.report.sections.crosscheck:section"}


def register(ep: EntryPoint) -> None:
    """Add a report section through an entry point of the group, in this process."""
    plugins.add_entry_point(ep, GROUP)
    report_sections.cache_clear()


def unregister(name: str) -> None:
    """Remove a section added by register()."""
    plugins.remove_entry_point(GROUP, name)
    report_sections.cache_clear()


@lru_cache(maxsize=1)
def report_sections() -> dict[str, ReportSection]:
    """Every section by name: the built-in ones first, in their report-v2 order, then plug-ins."""
    found = {name: EntryPoint(name, target, GROUP) for name, target in BUILTIN.items()}
    found.update(group_entry_points(GROUP))
    out = {}
    for name, ep in found.items():
        section = ep.load()
        if not isinstance(section, ReportSection) or section.name != name:
            raise TypeError(f"report section entry point {name!r} ({ep.value}) is not a ReportSection named {name!r}")
        out[name] = section
    return out


def plugin_sections() -> dict[str, ReportSection]:
    """The sections whose data goes under `sections` in report.json (every one but the built-ins)."""
    return {n: s for n, s in report_sections().items() if not s.top_level}


def section_data(report: dict, section: ReportSection):
    """A section's data in a report dict (None when absent)."""
    if section.top_level:
        return report.get(section.name)
    return (report.get("sections") or {}).get(section.name)
