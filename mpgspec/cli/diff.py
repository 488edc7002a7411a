"""`mpgspec diff OLD NEW`: what a change gained or lost between two verified reports."""
from __future__ import annotations

from ..errors import EXIT_CHECK_FAILED, EXIT_OK
from ..report.diff import diff_reports, format_diff, load_for_diff
from .output import append_step_summary


def cmd_diff(args) -> int:
    old, note_old = load_for_diff(args.old)
    new, note_new = load_for_diff(args.new)
    d = diff_reports(old, new)
    notes = [n for n in (note_old, note_new) if n]
    print(format_diff(d, args.format, notes))
    if args.format == "github":
        append_step_summary(format_diff(d, "markdown", notes) + "\n")
    return EXIT_CHECK_FAILED if d["regression"] else EXIT_OK
