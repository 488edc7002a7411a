"""Load YAML specs as plain data while remembering where every key and item came from.

Errors in a spec must point at file:line:column, so the document is composed into PyYAML nodes
and converted by hand, recording positions per path. Scalars follow the YAML 1.2 core schema
(true/false only, 1e-3 is a float, 1:30 and 012 are not sexagesimal/octal), which avoids the
YAML 1.1 surprises of `on: ...` becoming True or `dt: 1e-3` staying a string.
"""
from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from mpgspec.errors import Location, SpecError, UsageError

PathKey = tuple[str | int, ...]

_TAG = "tag:yaml.org,2002:"


class _Loader(yaml.SafeLoader):
    """SafeLoader composer with YAML 1.2 core-schema implicit resolvers."""

    yaml_implicit_resolvers: dict = {}


_Loader.add_implicit_resolver(
    _TAG + "null", re.compile(r"^(?:~|null|Null|NULL|)$"), ["~", "n", "N", ""])
_Loader.add_implicit_resolver(
    _TAG + "bool", re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))
_Loader.add_implicit_resolver(
    _TAG + "int", re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$"),
    list("-+0123456789"))
_Loader.add_implicit_resolver(
    _TAG + "float",
    re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?"
               r"|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"),
    list("-+.0123456789"))
_Loader.add_implicit_resolver(_TAG + "merge", re.compile(r"^<<$"), ["<"])


def _scalar(node: ScalarNode) -> Any:
    try:
        return _resolve_scalar(node)
    except SpecError:
        raise
    except ValueError:
        kind = node.tag.removeprefix(_TAG)
        raise _node_error(node, f"invalid !!{kind} value", expected=f"a valid {kind}",
                          found=repr(node.value)) from None


def _resolve_scalar(node: ScalarNode) -> Any:
    tag, text = node.tag, node.value
    if tag == _TAG + "str":
        return text
    if tag == _TAG + "null":
        return None
    if tag == _TAG + "bool":
        return text.lower() == "true"
    if tag == _TAG + "int":
        low = text.lower()
        return int(low, 16) if low.startswith("0x") else int(low, 8) if low.startswith(
            "0o") else int(text)
    if tag == _TAG + "float":
        low = text.lower()
        if low.endswith("inf"):
            return -math.inf if low.startswith("-") else math.inf
        return math.nan if low == ".nan" else float(text)
    raise _node_error(node, f"unsupported YAML tag {node.tag!r}",
                      expected="a plain value (string, number, true/false, null)")


def _pos(node: Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


def _node_error(node: Node, message: str, *, code: str = "MPG100", key: str = "",
                expected: str = "", found: str = "", hint: str = "") -> SpecError:
    line, column = _pos(node)
    return SpecError(message, location=Location(node.start_mark.name, line, column), key=key,
                     expected=expected, found=found, hint=hint, code=code)


def format_path(path: PathKey) -> str:
    """Dotted display form of a data path: ('a', 0, 'b') -> 'a[0].b'."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


@dataclass(frozen=True)
class _Entry:
    key: tuple[int, int]  # where the key (or sequence item) starts
    value: tuple[int, int]  # where the value node starts
    node: Node = field(repr=False, compare=False)


@dataclass
class PositionMap:
    """Source positions of every key and value in a loaded document, by data path."""

    file: str = "<string>"
    text: str = field(default="", repr=False)
    entries: dict[PathKey, _Entry] = field(default_factory=dict, repr=False)

    def __contains__(self, path: PathKey) -> bool:
        return tuple(path) in self.entries

    def _deepest(self, path: PathKey) -> tuple[PathKey, _Entry | None]:
        path = tuple(path)
        for n in range(len(path), -1, -1):
            entry = self.entries.get(path[:n])
            if entry is not None:
                return path[:n], entry
        return (), None

    def _loc(self, pos: tuple[int, int]) -> Location:
        return Location(self.file, *pos)

    def locate(self, path: PathKey) -> Location:
        """Where the key at path starts; for a missing path, its deepest existing ancestor."""
        _, entry = self._deepest(path)
        return self._loc(entry.key) if entry else Location(self.file)

    def locate_value(self, path: PathKey) -> Location:
        """Where the value at path starts; for a missing path, as locate()."""
        found, entry = self._deepest(path)
        if entry is None:
            return Location(self.file)
        return self._loc(entry.value if found == tuple(path) else entry.key)

    def locate_in_value(self, path: PathKey, offset: int) -> Location:
        """Location of character `offset` of the string value at path.

        Exact for one-line plain and quoted scalars without escapes and for literal blocks (|);
        otherwise the start of the value.
        """
        found, entry = self._deepest(path)
        if entry is None or found != tuple(path) or not isinstance(entry.node, ScalarNode):
            return self.locate_value(path)
        node, (line, column) = entry.node, entry.value
        start, end = node.start_mark, node.end_mark
        if node.style in (None, "'", '"') and start.line == end.line:
            inner = 0 if node.style is None else 1
            raw = self.text[start.index + inner:end.index - inner] if self.text else ""
            if raw == node.value and 0 <= offset <= len(node.value):
                return Location(self.file, line, column + inner + offset)
        if node.style == "|" and self.text:
            before = node.value[:offset]
            row = before.count("\n")
            first = start.line + 1  # 0-based; content starts on the line after the indicator
            content = [ln for ln in self.text.splitlines()[first:] if ln.strip()]
            indent = len(content[0]) - len(content[0].lstrip(" ")) if content else 0
            return Location(self.file, first + row + 1, indent + len(before) - (
                before.rfind("\n") + 1) + 1)
        return self._loc(entry.value)


def load_yaml(path_or_text: str | Path, filename: str | None = None) -> tuple[Any, PositionMap]:
    """Parse YAML into plain data plus a PositionMap.

    A Path, or a one-line str naming an existing file or ending in .yaml/.yml, is read from
    disk; any other str is YAML text. filename labels locations (default: the path or
    '<string>'). Raises SpecError MPG100 for invalid YAML and MPG101 for duplicate keys,
    UsageError for a missing file.
    """
    text, name = _read(path_or_text, filename)
    positions = PositionMap(file=name, text=text)
    stream = io.StringIO(text)
    stream.name = name  # PyYAML labels marks with the stream's name
    try:
        root = yaml.compose(stream, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        raise _syntax_error(exc, name, text) from None
    except yaml.YAMLError as exc:
        raise SpecError(f"invalid YAML: {exc}", location=Location(name), code="MPG100") from None
    if root is None:
        return None, positions
    data = _convert(root, (), positions, _pos(root), set())
    return data, positions


def _read(path_or_text: str | Path, filename: str | None) -> tuple[str, str]:
    is_path = isinstance(path_or_text, Path) or (
        "\n" not in path_or_text
        and (path_or_text.endswith((".yaml", ".yml")) or Path(path_or_text).is_file()))
    if not is_path:
        return str(path_or_text), filename or "<string>"
    path = Path(path_or_text)
    name = filename or str(path)
    try:
        return path.read_text(encoding="utf-8"), name
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{path}: is a directory, expected a YAML file") from None
    except UnicodeDecodeError as exc:
        raise SpecError("file is not UTF-8 text", location=Location(name), code="MPG100",
                        found=f"byte {exc.object[exc.start]:#04x} at offset {exc.start}"
                        ) from None


def _syntax_error(exc: yaml.MarkedYAMLError, name: str, text: str) -> SpecError:
    mark = exc.problem_mark or exc.context_mark
    line, column = (mark.line + 1, mark.column + 1) if mark else (0, 0)
    problem = exc.problem or "invalid YAML"
    if exc.context and exc.context_mark and exc.context_mark is not mark:
        problem += f" ({exc.context} at line {exc.context_mark.line + 1})"
    hint = "indent with spaces, not tabs" if "'\\t'" in problem else ""
    return SpecError(f"invalid YAML: {problem}", location=Location(name, line, column),
                     hint=hint, code="MPG100",
                     context=format_context_text(text, line, column) if line else "")


def _convert(node: Node, path: PathKey, positions: PositionMap, key_pos: tuple[int, int],
             active: set[int]) -> Any:
    positions.entries[path] = _Entry(key_pos, _pos(node), node)
    if isinstance(node, ScalarNode):
        return _scalar(node)
    if id(node) in active:
        raise _node_error(node, "recursive YAML alias", key=format_path(path))
    active = active | {id(node)}
    if isinstance(node, SequenceNode):
        if node.tag != _TAG + "seq":
            raise _node_error(node, f"unsupported YAML tag {node.tag!r}", expected="a list")
        return [_convert(item, (*path, i), positions, _pos(item), active)
                for i, item in enumerate(node.value)]
    if node.tag != _TAG + "map":
        raise _node_error(node, f"unsupported YAML tag {node.tag!r}", expected="a mapping")
    _check_duplicates(node, path)
    _Loader("").flatten_mapping(node)  # resolve '<<' merge keys; explicit keys win
    result: dict = {}
    for key_node, value_node in node.value:
        if not isinstance(key_node, ScalarNode):
            raise _node_error(key_node, "mapping keys must be plain values",
                              key=format_path(path), found="a list or mapping as key")
        key = _scalar(key_node)
        result[key] = _convert(value_node, (*path, key), positions, _pos(key_node), active)
    return result


def _check_duplicates(node: MappingNode, path: PathKey) -> None:
    first: dict[Any, Node] = {}
    for key_node, _ in node.value:
        if not isinstance(key_node, ScalarNode) or key_node.tag == _TAG + "merge":
            continue
        key = _scalar(key_node)
        if key in first:
            line = first[key].start_mark.line + 1
            raise _node_error(key_node, f"duplicate key {key!r}", code="MPG101",
                              key=format_path((*path, key)), expected="each key once",
                              found=f"{key!r} again", hint=f"first defined at line {line}")
        first[key] = key_node


def format_context_text(text: str, line: int, column: int = 0, radius: int = 2) -> str:
    """Source lines around 1-based line, the line marked with '>' and a caret under column."""
    lines = text.splitlines()
    if not 1 <= line <= len(lines) + 1:
        return ""
    if line == len(lines) + 1:  # errors at end of input point just past the last line
        lines.append("")
    lo, hi = max(1, line - radius), min(len(lines), line + radius)
    width = len(str(hi))
    out = []
    for n in range(lo, hi + 1):
        out.append(f"{'>' if n == line else ' '} {n:>{width}} | {lines[n - 1]}".rstrip())
        if n == line and column > 0:
            out.append(f"  {' ' * width} | {' ' * (column - 1)}^")
    return "\n".join(out)


def format_context(path: str | Path, line: int, radius: int = 2, column: int = 0) -> str:
    """format_context_text for a file on disk; '' if it cannot be read."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return ""
    return format_context_text(text, line, column, radius)
