"""Progress display: plain lines with elapsed time (rate-limited within a phase), the closing summary."""
from __future__ import annotations

import io
from types import SimpleNamespace

from mpgspec.progress import Display, phase_of, summary


def test_plain_lines_name_the_phase_and_the_elapsed_time():
    out = io.StringIO()
    d = Display(out, live=False)
    d("p", "load", 0, 1)
    d("p", "oracle Swing(1)", 1, 10)
    for k in range(2, 10):
        d("p", "oracle Swing(1)", k, 10)  # within the same phase: not a line each
    d("p", "oracle Swing(1)", 10, 10)
    d.close()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("[p] load (0/1) · ") and lines[0].endswith(" s")
    assert lines[1].startswith("[p] oracle Swing(1) (1/10)") and lines[-1].startswith("[p] oracle Swing(1) (10/10)")
    assert len(lines) == 3 and phase_of("oracle on 2 processes") == "oracle"


def test_summary_across_projects():
    def proj(status, calls, warns=0):
        return SimpleNamespace(status=status, report={"timing": {"oracle_calls": calls, "cache_hits": 1},
                                                      "assumptions": [{"status": "warn"}] * warns})

    text = summary([proj("pass", 10, 2), proj("fail", 5), SimpleNamespace(status="error", report=None)], 3.21)
    assert text == ("3 projects: 1 passed, 1 failed, 1 errors; 15 oracle calls (2 from the cache); 2 warnings; "
                    "3.2 s in all")
