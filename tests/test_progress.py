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
                                                      "assumptions": [{"status": "warn"}] * warns},
                               warnings=warns)  # as ProjectResult.warnings counts them

    text = summary([proj("pass", 10, 2), proj("fail", 5), SimpleNamespace(status="error", report=None)], 3.21)
    assert text == ("3 projects: 1 passed, 1 failed, 1 errors; 15 oracle calls (2 from the cache); 2 warnings; "
                    "3.2 s in all")


def test_projects_side_by_side_keep_their_own_phases():
    out = io.StringIO()
    d = Display(out, live=False)
    for k in range(1, 6):  # two projects' events interleaved, each within one phase
        d("a", "oracle Walk", k, 5)
        d("b", "regions of attraction", k, 5)
    d.close()
    lines = out.getvalue().splitlines()
    assert [ln.split(" ", 1)[0] for ln in lines] == ["[a]", "[b]", "[a]", "[b]"]  # first and last of each
    live = io.StringIO()
    d = Display(live, live=True)
    if d._live is None:  # rich not installed
        return
    d("a", "oracle Walk", 1, 5)
    d("b", "regions of attraction", 1, 5)
    d("a", "oracle Walk", 5, 5)
    d("b", "traces", 0, 1)
    d.close()
    done = [ln for ln in live.getvalue().splitlines() if " done in " in ln]
    assert [ln.split()[0] for ln in done] == ["b", "a", "b"]  # b's roa when it changed, then each at the end
    assert len(d._tasks) == 2
