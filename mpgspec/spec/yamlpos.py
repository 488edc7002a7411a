"""Load YAML specs as plain data while remembering where every key and item came from.

Errors in a spec must point at file:line:column, so the document is composed into PyYAML nodes
and converted by hand, recording positions per path. Scalars follow the YAML 1.2 core schema
(true/false only, 1e-3 is a float, 1:30 and 012 are not sexagesimal/octal), which avoids the
YAML 1.1 surprises of `on: ...` becoming True or `dt: 1e-3` staying a string.

Specs come from pull requests, so the loader is bounded: files larger than MAX_FILE_BYTES and
values longer than MAX_SCALAR characters are refused, nesting is limited to MAX_DEPTH levels,
and aliases and merge keys (`<<`) may expand to at most MAX_EXPANSION nodes (a billion-laughs
document fails fast). Error messages echo at most MAX_ECHO characters of a line or value, and
nothing of a file outside the project folder (`quote=False`: no lines, values or quoted names).
"""
from __future__ import annotations

import dataclasses
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from mpgspec.errors import Location, SpecError, UsageError

from .paths import MAX_ECHO, MAX_FILE_BYTES, ReadProblem, clip, clip_repr, read_text_bounded

PathKey = tuple[str | int, ...]

_TAG = "tag:yaml.org,2002:"

MAX_DEPTH = 100
"""Deepest nesting of lists and mappings in a spec (also after expanding aliases)."""

MAX_SCALAR = 100_000
"""Longest single value (a string, number or key) in characters."""

MAX_EXPANSION = 50_000
"""Most nodes that aliases and merge keys may add to a document by expansion."""


class _Loader(yaml.SafeLoader):
    """SafeLoader composer with YAML 1.2 core-schema implicit resolvers and a nesting limit."""

    yaml_implicit_resolvers: dict = {}

    def __init__(self, stream):
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                mark = self.peek_event().start_mark
                raise yaml.composer.ComposerError(
                    None, None, f"nesting deeper than {MAX_DEPTH} levels", mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


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
    if len(node.value) > MAX_SCALAR:
        raise _node_error(node, "value is too long", expected=f"at most {MAX_SCALAR} characters",
                          found=f"{len(node.value)} characters")
    try:
        return _resolve_scalar(node)
    except SpecError:
        raise
    except ValueError:
        kind = node.tag.removeprefix(_TAG)
        raise _node_error(node, f"invalid !!{kind} value", expected=f"a valid {kind}",
                          found=clip_repr(node.value)) from None


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
    return SpecError(message, location=Location(node.start_mark.name, line, column), key=clip(key),
                     expected=expected, found=clip(found), hint=hint, code=code)


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
    quote: bool = True
    """False for a file outside the project folder: its locations say so (Location.quote)."""

    def __contains__(self, path: PathKey) -> bool:
        return tuple(path) in self.entries

    def _deepest(self, path: PathKey) -> tuple[PathKey, _Entry | None]:
        path = tuple(path)
        for n in range(len(path), -1, -1):
            entry = self.entries.get(path[:n])
            if entry is not None:
                return path[:n], entry
        return (), None

    def _loc(self, pos: tuple[int, int] = (0, 0)) -> Location:
        return Location(self.file, *pos, quote=self.quote)

    def locate(self, path: PathKey) -> Location:
        """Where the key at path starts; for a missing path, its deepest existing ancestor."""
        _, entry = self._deepest(path)
        return self._loc(entry.key) if entry else self._loc()

    def locate_value(self, path: PathKey) -> Location:
        """Where the value at path starts; for a missing path, as locate()."""
        found, entry = self._deepest(path)
        if entry is None:
            return self._loc()
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
                return self._loc((line, column + inner + offset))
        if node.style == "|" and self.text:
            before = node.value[:offset]
            row = before.count("\n")
            first = start.line + 1  # 0-based; content starts on the line after the indicator
            content = [ln for ln in self.text.splitlines()[first:] if ln.strip()]
            indent = len(content[0]) - len(content[0].lstrip(" ")) if content else 0
            return self._loc((first + row + 1, indent + len(before) - (before.rfind("\n") + 1) + 1))
        return self._loc(entry.value)


def load_yaml(path_or_text: str | Path, filename: str | None = None) -> tuple[Any, PositionMap]:
    """Parse YAML into plain data plus a PositionMap.

    A Path, or a one-line str naming an existing file or ending in .yaml/.yml, is read from
    disk (at most MAX_FILE_BYTES, a regular UTF-8 file); any other str is YAML text. filename
    labels locations (default: the path or '<string>'). Raises SpecError MPG100 for invalid YAML
    or an unreadable file and MPG101 for duplicate keys, UsageError for a missing file.
    """
    text, name = _read(path_or_text, filename)
    return parse_yaml(text, name)


def parse_yaml(text: str, name: str = "<string>", quote: bool = True) -> tuple[Any, PositionMap]:
    """load_yaml for text already read; `name` labels locations. quote=False for a file outside
    the project folder: errors and locations then carry nothing of its text (`hidden`)."""
    try:
        return _parse(text, name, quote)
    except SpecError as err:
        if quote:
            raise
        raise hidden(err) from None


def hidden(err: SpecError) -> SpecError:
    """err as it may be shown for a file outside the project folder: its message up to the first
    quoted piece of the file, no key (a path of the file's keys), found and context hidden."""
    message = _QUOTE.split(err.message, maxsplit=1)[0].rstrip(" :(,")
    return SpecError(message or "invalid YAML", location=dataclasses.replace(err.location, quote=False),
                     expected=err.expected, found=err.found, hint="" if _QUOTE.search(err.hint) else err.hint,
                     code=err.code)


_QUOTE = re.compile(r"""['"]""")


def _parse(text: str, name: str, quote: bool) -> tuple[Any, PositionMap]:
    if len(text) > MAX_FILE_BYTES:
        raise SpecError("YAML text is too large", location=Location(name), code="MPG100",
                        expected=f"at most {MAX_FILE_BYTES} characters", found=f"{len(text)} characters")
    positions = PositionMap(file=name, text=text, quote=quote)
    stream = io.StringIO(text)
    stream.name = name  # PyYAML labels marks with the stream's name
    try:
        root = yaml.compose(stream, Loader=_Loader)
    except yaml.MarkedYAMLError as exc:
        raise _syntax_error(exc, name, text) from None
    except yaml.reader.ReaderError as exc:
        line, column = _line_col(text, exc.position)
        raise SpecError(f"invalid YAML: unacceptable character #x{exc.character:04x}"
                        if isinstance(exc.character, int) else "invalid YAML: unacceptable character",
                        location=Location(name, line, column), code="MPG100",
                        expected="printable text") from None
    except yaml.YAMLError as exc:
        raise SpecError(f"invalid YAML: {clip(str(exc))}", location=Location(name), code="MPG100") from None
    except RecursionError:
        raise SpecError("invalid YAML: nesting too deep", location=Location(name), code="MPG100",
                        expected=f"at most {MAX_DEPTH} levels") from None
    if root is None:
        return None, positions
    budget = _Budget()
    try:
        data = _convert(root, (), positions, _pos(root), set(), budget)
    except RecursionError:
        raise SpecError("invalid YAML: nesting too deep", location=Location(name), code="MPG100",
                        expected=f"at most {MAX_DEPTH} levels") from None
    return data, positions


def _line_col(text: str, index: int) -> tuple[int, int]:
    if not isinstance(index, int) or index < 0:
        return 0, 0
    before = text[:index]
    return before.count("\n") + 1, index - (before.rfind("\n") + 1) + 1


def _read(path_or_text: str | Path, filename: str | None) -> tuple[str, str]:
    is_path = isinstance(path_or_text, Path) or (
        "\n" not in path_or_text and len(path_or_text) < 4096
        and (path_or_text.endswith((".yaml", ".yml")) or _is_file(path_or_text)))
    if not is_path:
        return str(path_or_text), filename or "<string>"
    path = Path(path_or_text)
    name = filename or str(path)
    try:
        return read_text_bounded(path, allow_empty=True), name
    except ReadProblem as p:
        if p.missing:
            raise UsageError(f"{path}: no such file") from None
        raise SpecError(p.message, location=Location(name, p.line, p.column), code="MPG100",
                        expected=p.expected, found=p.found) from None


def _is_file(text: str) -> bool:
    try:
        return Path(text).is_file()
    except (OSError, ValueError):
        return False


def _syntax_error(exc: yaml.MarkedYAMLError, name: str, text: str) -> SpecError:
    mark = exc.problem_mark or exc.context_mark
    line, column = (mark.line + 1, mark.column + 1) if mark else (0, 0)
    problem = exc.problem or "invalid YAML"
    if exc.context and exc.context_mark and exc.context_mark is not mark:
        problem += f" ({exc.context} at line {exc.context_mark.line + 1})"
    hint = "indent with spaces, not tabs" if "'\\t'" in problem else ""
    return SpecError(f"invalid YAML: {clip(problem)}", location=Location(name, line, column),
                     hint=hint, code="MPG100",
                     context=format_context_text(text, line, column) if line else "")


class _Budget:
    """Counts the nodes that aliases and merge keys add by expansion (a billion-laughs guard)."""

    def __init__(self, limit: int = MAX_EXPANSION):
        self.limit = limit
        self.seen: set[int] = set()
        self.used = 0
        self._sizes: dict[int, int] = {}

    def size(self, root: Node) -> int:
        """Nodes in the expansion of root (capped just above the limit), computed without
        expanding: each distinct node is visited once."""
        memo, cap = self._sizes, self.limit + 1
        if id(root) in memo:
            return memo[id(root)]
        stack, open_ = [(root, False)], set()
        while stack:
            node, done = stack.pop()
            nid = id(node)
            if nid in memo:
                continue
            kids = _children(node)
            if done:
                memo[nid] = min(cap, 1 + sum(memo.get(id(k), 0) for k in kids))
                open_.discard(nid)
                continue
            if nid in open_:  # a recursive alias: reported by _convert
                continue
            open_.add(nid)
            stack.append((node, True))
            stack.extend((k, False) for k in kids if id(k) not in memo and id(k) not in open_)
        return memo[id(root)]

    def charge(self, n: int, node: Node, path: PathKey) -> None:
        self.used += n
        if self.used > self.limit:
            raise _node_error(node, "aliases and merge keys expand to too many nodes",
                              key=format_path(path), code="MPG100",
                              expected=f"at most {self.limit} nodes added by aliases and '<<'",
                              hint="write the repeated parts out, or use fewer nested aliases")


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _convert(node: Node, path: PathKey, positions: PositionMap, key_pos: tuple[int, int],
             active: set[int], budget: _Budget, expanding: bool = False) -> Any:
    if len(path) > MAX_DEPTH:
        raise _node_error(node, f"nesting deeper than {MAX_DEPTH} levels (through aliases)",
                          key=format_path(path[:10]) + "...", expected=f"at most {MAX_DEPTH} levels")
    if expanding:
        pass  # inside an expansion already charged as a whole
    elif id(node) in budget.seen:  # a second use of an anchored node: an alias expands it again
        budget.charge(budget.size(node), node, path)  # the whole subtree, before converting it
        expanding = True
    else:
        budget.seen.add(id(node))
    positions.entries[path] = _Entry(key_pos, _pos(node), node)
    if isinstance(node, ScalarNode):
        return _scalar(node)
    if id(node) in active:
        raise _node_error(node, "recursive YAML alias", key=format_path(path))
    active = active | {id(node)}
    if isinstance(node, SequenceNode):
        if node.tag != _TAG + "seq":
            raise _node_error(node, f"unsupported YAML tag {node.tag!r}", expected="a list")
        return [_convert(item, (*path, i), positions, _pos(item), active, budget, expanding)
                for i, item in enumerate(node.value)]
    if node.tag != _TAG + "map":
        raise _node_error(node, f"unsupported YAML tag {node.tag!r}", expected="a mapping")
    _check_duplicates(node, path)
    result: dict = {}
    for key_node, value_node in _merged_pairs(node, path, budget, frozenset()):
        if not isinstance(key_node, ScalarNode):
            raise _node_error(key_node, "mapping keys must be plain values",
                              key=format_path(path), found="a list or mapping as key")
        key = _scalar(key_node)
        result[key] = _convert(value_node, (*path, key), positions, _pos(key_node), active, budget,
                               expanding)
    return result


def _kind(node: Node) -> str:
    return ("a scalar" if isinstance(node, ScalarNode) else "a list" if isinstance(node, SequenceNode)
            else "a mapping")


def _merged_pairs(node: MappingNode, path: PathKey, budget: _Budget,
                  active: frozenset[int]) -> list[tuple[Node, Node]]:
    """The key/value pairs of a mapping with '<<' merge keys resolved (YAML merge key spec).

    Explicit keys win over merged ones, and earlier merged mappings over later ones. Unlike
    PyYAML's flatten_mapping, the node is not changed, duplicate merged keys are dropped, and
    every merged pair is charged to the expansion budget.
    """
    explicit, sources = [], []
    for key_node, value_node in node.value:
        if not (isinstance(key_node, ScalarNode) and key_node.tag == _TAG + "merge"):
            explicit.append((key_node, value_node))
            continue
        items = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
        for src in items:
            if not isinstance(src, MappingNode) or src.tag != _TAG + "map":
                raise _node_error(key_node, "a merge key '<<' needs a mapping", key=format_path((*path, "<<")),
                                  expected="a mapping (an alias like *base) or a list of mappings",
                                  found=_kind(src) if isinstance(src, (ScalarNode, SequenceNode))
                                  else f"tag {src.tag!r}")
            if id(src) in active or src is node:
                raise _node_error(key_node, "recursive merge key '<<'", key=format_path((*path, "<<")))
            sources.append(src)
    if not sources:
        return explicit
    budget.charge(1, node, path)
    taken = {_pair_key(k) for k, _ in explicit}
    merged = []
    for src in sources:
        for key_node, value_node in _merged_pairs(src, path, budget, active | {id(node)}):
            budget.charge(1, src, path)
            k = _pair_key(key_node)
            if k not in taken:
                taken.add(k)
                merged.append((key_node, value_node))
    return merged + explicit


def _pair_key(key_node: Node):
    if isinstance(key_node, ScalarNode):
        try:
            return ("scalar", _scalar(key_node))
        except SpecError:
            return ("node", id(key_node))
    return ("node", id(key_node))


def _check_duplicates(node: MappingNode, path: PathKey) -> None:
    first: dict[Any, Node] = {}
    for key_node, _ in node.value:
        if not isinstance(key_node, ScalarNode) or key_node.tag == _TAG + "merge":
            continue
        key = _scalar(key_node)
        if key in first:
            line = first[key].start_mark.line + 1
            raise _node_error(key_node, f"duplicate key {clip_repr(key, 60)}", code="MPG101",
                              key=format_path((*path, key)), expected="each key once",
                              found=f"{clip_repr(key)} again", hint=f"first defined at line {line}")
        first[key] = key_node


def _clip_line(line: str, column: int, limit: int = MAX_ECHO) -> tuple[str, int]:
    """At most `limit` characters of a source line (around `column` when it lies further right)
    and the column of the caret in what is shown."""
    if len(line) <= limit:
        return line, column
    if column <= limit - 20:
        return line[: limit - 1] + "…", column
    start = max(0, min(column - 1 - limit // 2, len(line) - (limit - 2)))
    shown = "…" + line[start:start + limit - 2] + ("…" if start + limit - 2 < len(line) else "")
    return shown, column - start + 1


def format_context_text(text: str, line: int, column: int = 0, radius: int = 2) -> str:
    """Source lines around 1-based line, the line marked with '>' and a caret under column.

    Lines longer than MAX_ECHO characters are cut (with an ellipsis), so an error never echoes
    more than a few hundred characters of a file.
    """
    lines = text.splitlines()
    if not 1 <= line <= len(lines) + 1:
        return ""
    if line == len(lines) + 1:  # errors at end of input point just past the last line
        lines.append("")
    lo, hi = max(1, line - radius), min(len(lines), line + radius)
    width = len(str(hi))
    out = []
    for n in range(lo, hi + 1):
        shown, caret = _clip_line(lines[n - 1], column if n == line else 0)
        out.append(f"{'>' if n == line else ' '} {n:>{width}} | {shown}".rstrip())
        if n == line and column > 0:
            out.append(f"  {' ' * width} | {' ' * (caret - 1)}^")
    return "\n".join(out)


def format_context(path: str | Path, line: int, radius: int = 2, column: int = 0) -> str:
    """format_context_text for a file on disk; '' if it cannot be read (or is not a regular,
    UTF-8 file of at most MAX_FILE_BYTES)."""
    try:
        text = read_text_bounded(path, allow_empty=True)
    except (ReadProblem, OSError, ValueError):
        return ""
    return format_context_text(text, line, column, radius)
