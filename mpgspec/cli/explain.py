"""`mpgspec explain CODE`: what an error code means and how to fix it."""
from __future__ import annotations

from ..codes import CODES, explain
from ..errors import EXIT_OK, UsageError


def cmd_explain(args) -> int:
    if args.code is None:
        for code, (title, _text) in CODES.items():
            print(f"{code}  {title}")
        return EXIT_OK
    text = explain(args.code)
    if text is None:
        raise UsageError(f"unknown error code {args.code[:20]!r}; `mpgspec explain` lists them all")
    print(text)
    return EXIT_OK
