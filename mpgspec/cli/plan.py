"""`mpgspec plan`: the shortest safe sequence between two primitives, through mpgspec.api.plan."""
from __future__ import annotations

import json
import sys

from .. import api
from ..errors import EXIT_CHECK_FAILED, EXIT_OK
from ..streams import stdout_to_stderr
from ..report.svg import window_text
from .output import _num


def _window_text(ws) -> str:
    return " ∪ ".join(window_text(a, b, lambda v: _num(v, ".4g")) for a, b in ws)


def notifier(args):
    """Why a verified report is not reused, on stderr (not with --format json)."""
    if args.format == "json":
        return None
    return lambda message: print(message, file=sys.stderr)


def cmd_plan(args) -> int:
    with stdout_to_stderr():
        doc = api.plan(args.project, args.source, args.goal, args.weight, args.out, args.rebuild, args.robust,
                       notifier(args))
    path, cost = doc["path"], doc["cost"]
    args.exit_code = EXIT_OK if path is not None else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps(doc, indent=1))
    elif path is not None:
        what = f"{args.weight} {cost:.4g}" if args.weight != "margin" else f"margin cost {cost:.4g}: the sum of 1 / margin"
        print(" -> ".join(path) + f"   ({what})")
        for h in doc["hops"]:
            wait = (f"wait until t_A of {h['from']} is in {_window_text(h['windows'])} s" if h["class"] == 2
                    else "switch at any t_A")
            print(f"  {h['from']} -> {h['to']}: class {h['class']}, {_num(h['duration'], '.3g')} s; {wait}")
    else:
        why = f": {doc['why']}" if doc.get("why") else ""
        print(f"no safe {'robust ' if args.robust else ''}transition sequence from {args.source} to {args.goal}{why}")
    return args.exit_code
