"""Command line: a thin layer over mpgspec.api (arguments in args.py, one module per command).

    mpgspec verify PATH [--out reports] [--format human|json|github|junit|sarif]
    mpgspec plan PROJECT --from A --to B [--weight duration|peak_input|hops]
    mpgspec simulate PROJECT [--mode naive|graph|both] [--uncertain --runs N --seed S]
    mpgspec diff OLD NEW [--format human|json|markdown|github]
    mpgspec explain [CODE]
    mpgspec schema [--kind project|primitive|system|report]

plan and simulate reuse what verify wrote (reports/<project>/report.json) while it matches the
spec files, and rebuild otherwise.

Exit codes: 0 all checks pass, 1 a check failed, 2 a spec or usage error.
"""
from __future__ import annotations

import argparse
import os
import sys

from ..errors import EXIT_OK, EXIT_USAGE, MpgError, SpecError, SpecErrors, gh_command
from .args import parser
from .output import _annotation, _json_doc, _print_errors  # noqa: F401 (_annotation: GitHub annotations)
from .signals import Terminated, _signal_handlers

__all__ = ["main", "parser"]


def _silence_stdout() -> None:
    """The reader of stdout went away: point fd 1 at /dev/null so that nothing more (not even the
    interpreter's last flush) fails."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


def _fail(args, errors: list[dict], plain: str | None = None, code: int = EXIT_USAGE) -> int:
    """Report an error that ended the command; exit code 2 (or code). With verify --format json the
    error is the JSON document on stdout as well."""
    args.exit_code = code
    fmt = getattr(args, "format", "human")
    if getattr(args, "cmd", None) == "verify" and fmt == "json":
        print(_json_doc(None, errors, code))
    elif getattr(args, "cmd", None) == "verify" and fmt in ("junit", "sarif"):
        import json

        from ..report.ci import junit, sarif

        print(junit([], errors=errors), end="") if fmt == "junit" else \
            print(json.dumps(sarif([], exit_code=code, errors=errors), separators=(",", ":")))
    if plain is not None:
        print(gh_command("error", plain) if fmt == "github" else plain, file=sys.stderr)
    else:
        _print_errors(errors, fmt)
    return code


_stopped: list = []
"""The signals that ended commands of this process (entry() then exits without exit hooks)."""


def _run(args) -> int:
    try:
        return args.fn(args)
    except SpecErrors as e:
        return _fail(args, [x.to_dict() | {"text": x.format()} for x in e.errors])
    except SpecError as e:
        return _fail(args, [e.to_dict() | {"text": e.format()}])
    except MpgError as e:
        return _fail(args, [{"code": e.code, "message": str(e)}], f"mpgspec: {e.code} {e}")
    except BrokenPipeError:
        raise
    except KeyboardInterrupt:
        _stopped.append("SIGINT")
        return _fail(args, [{"code": "MPG002", "message": "interrupted"}], "mpgspec: interrupted")
    except Terminated as e:
        _stopped.append(e.code)
        return _fail(args, [{"code": "MPG002", "message": "terminated by a signal"}], "mpgspec: terminated", e.code)
    except Exception as e:  # a bug, not the user's mistake: say so, keep the details
        import traceback

        rc = _fail(args, [{"code": "MPG900", "message": f"internal error: {type(e).__name__}: {e}"}],
                   f"mpgspec: internal error: {type(e).__name__}: {e}")
        if os.environ.get("MPGSPEC_DEBUG"):
            traceback.print_exc()
        else:
            print("set MPGSPEC_DEBUG=1 for the traceback", file=sys.stderr)
        return rc


def main(argv=None) -> int:
    args = argparse.Namespace()
    try:
        with _signal_handlers():
            try:
                args = parser().parse_args(argv)
            except SystemExit as e:
                return EXIT_USAGE if e.code not in (0, None) else EXIT_OK
            rc = _run(args)
            sys.stdout.flush()  # here, so that a closed pipe is seen while the exit code is known
            return rc
    except BrokenPipeError:  # the reader went away (e.g. `| head`): stop quietly, keep the exit code
        _silence_stdout()
        return getattr(args, "exit_code", EXIT_OK)
    except Terminated as e:  # a signal while an error was being reported
        _stopped.append(e.code)
        return e.code


def entry() -> None:
    """The console script and `python -m`: main(), then exit with its code. A run ended by a signal
    or Ctrl-C (its reports' temporaries already removed, its workers terminated) exits at once,
    without the interpreter's exit hooks: a process pool's thread that was reading a result from a
    worker killed mid-write would never return, and the exit would hang."""
    rc = main()
    if _stopped:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(rc)
    sys.exit(rc)

