"""`mpgspec cache`, `mpgspec schema` and `mpgspec gait`: the oracle cache, JSON Schemas, gait tables."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from ..errors import EXIT_CHECK_FAILED, EXIT_OK


def cmd_cache(args) -> int:
    from ..oracle import cache

    d = cache.clear() if args.action == "clear" else cache.info()
    verb = "removed" if args.action == "clear" else "holds"
    print(f"{d['folder']} {verb}: {d['oracle_results']} oracle results ({d['results_bytes'] / 1e6:.1f} MB), "
          f"{d['compiled_chunks']} compiled chunks ({d['compiled_bytes'] / 1e6:.1f} MB)")
    return EXIT_OK


def cmd_schema(args) -> int:
    if args.kind == "report":
        from ..report.schema import schema_path

        print(schema_path().read_text(encoding="utf-8"), end="")
    else:
        from ..spec.schema import spec_schema

        print(json.dumps(spec_schema(args.kind), indent=1, ensure_ascii=False))
    return EXIT_OK


def cmd_gait(args) -> int:
    """Generate (or with --check, compare) the gait tables of a gait file."""
    from ..compile.system import compile_system
    from ..robots.quadruped.gait.library import GaitTable, compare, generate, load_gait_file, write
    from ..spec.loader import load_project

    path = Path(args.file)
    say = (lambda m: None) if args.quiet else (lambda m: print(m, file=sys.stderr, flush=True))
    tables = generate(path, progress=say)
    gf = load_gait_file(path)
    names = compile_system(load_project(path.parent / gf.project)).state_names
    bad = [t.node for t in tables if isinstance(t, GaitTable) and (t.orbit.status != "converged"
                                                                   or not t.orbit.spectral_radius < 1)]
    if args.check:
        problems = compare(tables, names)
        for p_ in problems:
            print(f"stale: {p_}")
        if not problems:
            print(f"{len(tables)} gait tables match their regeneration")
        return EXIT_CHECK_FAILED if problems or bad else EXIT_OK
    write(tables, names)
    for t in tables:
        print(f"wrote {t.path}")
    for n in bad:
        print(f"{n}: no stable orbit (see the table's header)")
    return EXIT_CHECK_FAILED if bad else EXIT_OK
