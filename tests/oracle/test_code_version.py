"""Cached results are keyed by the source that computes them (code_version): a change to how results
are shown (PRESENTATION: the command line, pages, pictures, CI formats) keeps the cache, any other
source change does not."""
from __future__ import annotations

import re
from pathlib import Path

from mpgspec.oracle.cache import PRESENTATION, code_files

ROOT = Path(__file__).resolve().parents[2]


def test_presentation_is_left_out_and_everything_that_computes_is_hashed():
    hashed = {f.relative_to(ROOT).as_posix() for f in code_files(ROOT)}
    for entry in PRESENTATION:  # every entry names something that exists: the list cannot rot silently
        assert (ROOT / entry).exists(), entry
        assert not any(h.startswith(entry) for h in hashed), entry
    for computes in ("mpgspec/oracle/cache.py", "mpgspec/oracle/pieces.py", "mpgspec/execute/sequence.py",
                     "mpgspec/execute/crosscheck/compare.py", "mpgspec/robust/graph.py", "mpgspec/pipeline/stages.py",
                     "mpgspec/report/build.py", "mpgspec/report/compact.py", "mpgspec/report/read.py",
                     "verifiers/rk4.py"):
        assert computes in hashed, computes


def test_no_presentation_module_touches_the_cache():
    for entry in PRESENTATION:
        path = ROOT / entry
        for f in ([path] if path.is_file() else sorted(path.rglob("*.py"))):
            text = f.read_text(encoding="utf-8")  # neither reads nor writes stored results
            assert not re.search(r"\bmemo\b|ResultStore\(|Memo\(|\.put\(|code_version", text), f
