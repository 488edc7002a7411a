"""`mpgspec diff OLD NEW`: what a change gained or lost between two verified reports."""
from __future__ import annotations

import os

from ..errors import EXIT_CHECK_FAILED, EXIT_OK
from ..report.diff import diff_reports, format_diff, load_for_diff


def cmd_diff(args) -> int:
    old, note_old = load_for_diff(args.old)
    new, note_new = load_for_diff(args.new)
    d = diff_reports(old, new)
    notes = [n for n in (note_old, note_new) if n]
    print(format_diff(d, args.format, notes))
    summary = os.environ.get("GITHUB_STEP_SUMMARY")
    if args.format == "github" and summary:
        with open(summary, "a", encoding="utf-8") as f:
            f.write(format_diff(d, "markdown", notes) + "\n")
    return EXIT_CHECK_FAILED if d["regression"] else EXIT_OK
