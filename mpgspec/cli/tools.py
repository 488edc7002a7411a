"""`mpgspec cache`, `mpgspec schema` and `mpgspec gait`: the oracle cache, JSON Schemas, gait tables."""
from __future__ import annotations

import sys

from .. import api
from ..errors import EXIT_CHECK_FAILED, EXIT_OK


def cmd_cache(args) -> int:
    d = api.cache(args.action)
    verb = "removed" if args.action == "clear" else "holds"
    print(f"{d['folder']} {verb}: {d['oracle_results']} oracle results ({d['results_bytes'] / 1e6:.1f} MB), "
          f"{d['compiled_chunks']} compiled chunks ({d['compiled_bytes'] / 1e6:.1f} MB)")
    return EXIT_OK


def cmd_schema(args) -> int:
    print(api.schema(args.kind), end="")
    return EXIT_OK


def cmd_gait(args) -> int:
    """Generate (or with --check, compare) the gait tables of a gait file."""
    say = None if args.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
    run = api.gait(args.file, check=args.check, progress=say, allow_paths=args.allow_path)
    if args.check:
        for p_ in run.stale:
            print(f"stale: {p_}")
        if not run.stale:
            print(f"{len(run.tables)} gait tables match their regeneration")
        return EXIT_CHECK_FAILED if run.stale or run.unstable else EXIT_OK
    for path in run.written:
        print(f"wrote {path}")
    for n in run.unstable:
        print(n if ": " in n else f"{n}: no stable orbit (see the table's header)")
    return EXIT_CHECK_FAILED if run.unstable else EXIT_OK
