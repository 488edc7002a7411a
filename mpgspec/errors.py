"""Errors a person can act on: what, where (file:line:col), expected vs found, and a stable code.

Exit codes follow the convention of linters and CI tools: 0 all checks pass, 1 a check failed,
2 the input or the run was broken.
"""
from __future__ import annotations

from dataclasses import dataclass, field

HIDDEN = "content not shown: the file lies outside the project folder"
"""What an error says instead of a value read from a file outside the project folder."""

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_USAGE = 2


@dataclass
class Location:
    """A place in a spec file; line and column are 1-based (0 when unknown).

    quote is False for a file outside the project folder: an error located there shows neither
    its lines nor the value found, so that a spec cannot make CI logs echo another file.
    """

    file: str = "<string>"
    line: int = 0
    column: int = 0
    quote: bool = field(default=True, compare=False, repr=False)

    def __str__(self) -> str:
        if self.line:
            return f"{self.file}:{self.line}:{self.column}"
        return self.file


def _cap(text: str, n: int = 200) -> str:
    """Text from a spec, cut so that one hostile value cannot flood a log."""
    text = str(text)
    return text if len(text) <= n else text[: n - 1] + "…"


class MpgError(Exception):
    """Base class of all mpgspec errors."""

    code = "MPG000"


class SpecError(MpgError, ValueError):
    """A user's spec is wrong. Carries location, key, expectation and what was found.

    Codes: MPG1xx spec structure and values, MPG2xx expressions, MPG3xx references between specs.
    """

    code = "MPG100"

    def __init__(
        self,
        message: str,
        *,
        location: Location | None = None,
        key: str = "",
        expected: str = "",
        found: str = "",
        hint: str = "",
        code: str | None = None,
        context: str = "",
    ):
        self.message = _cap(message, 300)
        self.location = location or Location()
        self.key = _cap(key)
        self.expected = _cap(expected, 300)
        self.found = _cap(found) if self.location.quote or not found else HIDDEN
        self.hint = hint
        self.context = context if self.location.quote else ""
        if code:
            self.code = code
        super().__init__(self.format())

    def format(self) -> str:
        parts = [f"{self.location} {self.code}"]
        if self.key:
            parts.append(f"{self.key}:")
        parts.append(self.message)
        text = " ".join(parts)
        if self.expected:
            text += f"; expected {self.expected}"
        if self.found:
            text += f"; found {self.found}"
        if self.hint:
            text += f" (hint: {self.hint})"
        return text

    def to_dict(self) -> dict:
        return {
            "code": self.code,
            "file": self.location.file,
            "line": self.location.line,
            "column": self.location.column,
            "key": self.key,
            "message": self.message,
            "expected": self.expected,
            "found": self.found,
            "hint": self.hint,
            "quote": self.location.quote,
        }


@dataclass
class SpecErrors(MpgError, ValueError):
    """Several spec errors found in one pass (all are reported, not only the first)."""

    errors: list[SpecError] = field(default_factory=list)
    code = "MPG100"

    def __str__(self) -> str:
        return "\n".join(e.format() for e in self.errors)


class ExprError(SpecError):
    """An expression in a spec does not parse or names something unknown."""

    code = "MPG200"


class UsageError(MpgError, ValueError):
    """The command line or API was called wrongly (missing path, unknown primitive name...)."""

    code = "MPG001"


def unknown_primitive(name: str, names) -> UsageError:
    """A UsageError for a primitive name that is not in `names`, with the nearest name when one is
    close (case aside: `lie` -> `Lie`)."""
    import difflib

    names = list(names)
    lower = {n.lower(): n for n in names}
    near = [lower[m] for m in difflib.get_close_matches(str(name).lower(), list(lower), n=1, cutoff=0.6)]
    hint = f"; did you mean {near[0]!r}?" if near else ""
    return UsageError(f"unknown primitive {name!r}{hint} (expected one of {', '.join(names)})")


class CompileError(MpgError, RuntimeError):
    """A valid spec could not be compiled to CasADi (e.g. singular linearisation for LQR)."""

    code = "MPG300"


# ----------------------------------------------------------------------------- output formatting helpers
def gh_escape_data(text) -> str:
    """The message of a GitHub workflow command: no CR or LF can end it and start another command."""
    return str(text).replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def gh_escape_property(text) -> str:
    """A property value of a GitHub workflow command (file=..., title=...): also ':' and ','."""
    return gh_escape_data(text).replace(":", "%3A").replace(",", "%2C")


def gh_command(command: str, message, **properties) -> str:
    """One workflow command line, e.g. gh_command('error', msg, file=f, line=3) -> '::error file=f,line=3::msg'."""
    props = ",".join(f"{k}={gh_escape_property(v)}" for k, v in properties.items() if v is not None)
    return f"::{command}{' ' + props if props else ''}::{gh_escape_data(message)}"


def gh_plain(text) -> str:
    """A plain output line that GitHub must not read as a workflow command: line breaks inside it are
    escaped and a leading '::' (after blanks, which the runner skips) is broken up."""
    text = str(text).replace("\r", "%0D").replace("\n", "%0A")
    stripped = text.lstrip()
    if stripped.startswith("::"):
        text = text[: len(text) - len(stripped)] + ": :" + stripped[2:]
    return text
