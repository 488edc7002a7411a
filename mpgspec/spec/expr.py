"""Whitelisted expression language for spec values (guards, dynamics, costs, constants).

Spec text is parsed into a small immutable AST, never handed to Python's eval, so a spec can only
name variables and call the functions listed in FUNCTIONS. Backends (CasADi, plain floats) walk
the AST. This module has no CasADi dependency so specs can be validated without it.
"""
from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Union

from mpgspec.errors import ExprError, Location

# ---------------------------------------------------------------------------------------------
# AST (pos is the 0-based offset in the source text; it is ignored by == and hash)


@dataclass(frozen=True)
class Num:
    value: float
    pos: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Name:
    id: str
    pos: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Unary:
    op: str  # '-' or 'not'
    operand: Expr
    pos: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Binary:
    op: str  # + - * / ^ < <= > >= == != and or
    left: Expr
    right: Expr
    pos: int = field(default=0, compare=False)


@dataclass(frozen=True)
class Call:
    func: str
    args: tuple[Expr, ...]
    pos: int = field(default=0, compare=False)


Expr = Union[Num, Name, Unary, Binary, Call]

# name -> (min_args, max_args or None for unbounded)
FUNCTIONS: dict[str, tuple[int, int | None]] = {
    **{f: (1, 1) for f in (
        "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "exp", "log",
        "log10", "sqrt", "abs", "sign", "floor", "ceil", "sq",
    )},
    "atan2": (2, 2),
    "fmod": (2, 2),
    "hypot": (2, 2),
    "min": (2, None),
    "max": (2, None),
    "clip": (3, 3),
    "sat": (3, 3),
    "if_else": (3, 3),
    "piecewise": (3, None),  # odd count: c1, v1, c2, v2, ..., default
    "norm_2": (1, None),
    "norm_1": (1, None),
    "norm_inf": (1, None),
}

CONSTANTS: dict[str, float] = {"pi": math.pi, "e": math.e, "inf": math.inf}

COMPARISONS = frozenset({"<", "<=", ">", ">=", "==", "!="})
LOGIC = frozenset({"and", "or"})
KEYWORDS = frozenset({"and", "or", "not"})
RESERVED = frozenset({"t", "s"})
"""Names every primitive defines: its clock t and the time s since switch-in."""

MAX_DEPTH = 100
"""Deepest nesting of parentheses, calls, signs and powers the parser accepts (MPG207); long
chains such as a sum of thousands of terms are not nested and have no limit."""

# ---------------------------------------------------------------------------------------------
# Errors


def expr_error(code: str, message: str, offset: int, text: str, *, expected: str = "",
               found: str = "", hint: str = "") -> ExprError:
    """ExprError with .offset (0-based, into text) and a caret line under one-line text."""
    context = f"{text}\n{' ' * offset}^" if text and "\n" not in text else ""
    err = ExprError(message, expected=expected, found=found, hint=hint, code=code,
                    context=context)
    err.offset = offset
    return err


def relocate(err: ExprError, location: Location, key: str, *, shift: bool = True) -> ExprError:
    """Copy of err placed at location (the expression's start) under key.

    The column is advanced by err.offset when shift is set and the column is known; pass
    shift=False when location already points at the offending character.
    """
    offset = getattr(err, "offset", 0)
    column = location.column + offset if shift and location.column > 0 else location.column
    new = ExprError(err.message, location=Location(location.file, location.line, column, location.quote),
                    key=key, expected=err.expected, found=err.found, hint=err.hint,
                    code=err.code, context=err.context)
    new.offset = offset
    return new


def _unknown_name_hint(name: str, known: list[str], limit: int = 20) -> str:
    close = difflib.get_close_matches(name, known, n=3)
    shown = ", ".join(known[:limit]) + (", ..." if len(known) > limit else "")
    hint = f"did you mean {' or '.join(repr(c) for c in close)}? " if close else ""
    return hint + (f"known names: {shown}" if known else "no names are defined here")


def unknown_name_error(name: str, pos: int, known: list[str]) -> ExprError:
    """MPG204 for a name that is neither a variable nor a constant."""
    return expr_error("MPG204", f"unknown name '{name}'", pos, "", expected="a defined name",
                      found=name, hint=_unknown_name_hint(name, sorted(known)))


# ---------------------------------------------------------------------------------------------
# Tokenizer

_NUMBER = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_OPERATORS = ("**", "<=", ">=", "==", "!=", "&&", "||", "+", "-", "*", "/", "^", "<", ">",
              "!", "(", ")", ",")
_ALIASES = {"**": "^", "&&": "and", "||": "or", "!": "not"}


@dataclass(frozen=True)
class Token:
    kind: str  # 'num', 'name', 'op', 'end'
    text: str
    pos: int


def tokenize(text: str) -> Iterator[Token]:
    """Split text into tokens; operator aliases (** && || !) are normalised."""
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch.isspace():
            i += 1
            continue
        if "0" <= ch <= "9" or (ch == "." and i + 1 < n and "0" <= text[i + 1] <= "9"):  # ASCII digits only
            m = _NUMBER.match(text, i)
            assert m
            end = m.end()
            if end < n and (text[end].isalnum() or text[end] in "_."):
                bad = _NAME.match(text, i) or m
                raise expr_error("MPG201", "malformed number", i, text, expected="a number",
                                 found=repr(text[i:max(bad.end(), end + 1)]))
            yield Token("num", m.group(), i)
            i = end
            continue
        m = _NAME.match(text, i)
        if m:
            word = m.group()
            yield Token("op" if word in KEYWORDS else "name", word, i)
            i = m.end()
            continue
        for op in _OPERATORS:
            if text.startswith(op, i):
                yield Token("op", _ALIASES.get(op, op), i)
                i += len(op)
                break
        else:
            hint = "use '==' to compare" if ch == "=" else ""
            raise expr_error("MPG201", "unexpected character", i, text,
                             expected="a number, name, operator or parenthesis",
                             found=repr(ch), hint=hint)
    yield Token("end", "", n)


# ---------------------------------------------------------------------------------------------
# Parser (Pratt): binding powers, higher binds tighter

_INFIX = {
    "or": (1, 2), "and": (3, 4),
    **{op: (7, 8) for op in COMPARISONS},
    "+": (9, 10), "-": (9, 10),
    "*": (11, 12), "/": (11, 12),
    "^": (16, 15),  # right-associative, tighter than unary minus
}
_PREFIX = {"-": 13, "+": 13, "not": 5}


def _describe(tok: Token) -> str:
    return "end of expression" if tok.kind == "end" else repr(tok.text)


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.tokens = list(tokenize(text))
        self.i = 0
        self.depth = 0

    def peek(self) -> Token:
        return self.tokens[self.i]

    def next(self) -> Token:
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def fail(self, tok: Token, expected: str, message: str = "invalid expression",
             hint: str = "") -> ExprError:
        return expr_error("MPG201", message, tok.pos, self.text, expected=expected,
                          found=_describe(tok), hint=hint)

    def expect(self, op: str, opened: Token | None = None) -> Token:
        tok = self.next()
        if tok.kind != "op" or tok.text != op:
            hint = f"'(' opened at offset {opened.pos}" if opened is not None else ""
            raise self.fail(tok, repr(op), hint=hint)
        return tok

    def parse(self) -> Expr:
        if self.peek().kind == "end":
            raise expr_error("MPG201", "empty expression", 0, self.text,
                             expected="an expression", found="empty text")
        expr = self.expr(0)
        tok = self.peek()
        if tok.kind != "end":
            raise self.fail(tok, "an operator or end of expression")
        return expr

    def expr(self, min_bp: int) -> Expr:
        self.depth += 1
        try:
            return self._expr(min_bp)
        finally:
            self.depth -= 1

    def _expr(self, min_bp: int) -> Expr:
        if self.depth > MAX_DEPTH:
            tok = self.peek()
            raise expr_error("MPG207", f"expression nested too deeply (limit {MAX_DEPTH})", tok.pos, self.text,
                             expected=f"at most {MAX_DEPTH} levels of parentheses, calls, signs and powers",
                             found=f"more at offset {tok.pos}",
                             hint="split it into `let` constants or simplify it")
        lhs = self.prefix()
        chained = False
        while True:
            tok = self.peek()
            if tok.kind != "op" or tok.text not in _INFIX:
                break
            lbp, rbp = _INFIX[tok.text]
            if lbp < min_bp:
                break
            is_cmp = tok.text in COMPARISONS
            if is_cmp and chained:
                raise self.fail(tok, "'and' between comparisons",
                                "comparisons cannot be chained", hint="write a < b and b < c")
            self.next()
            lhs = Binary(tok.text, lhs, self.expr(rbp), tok.pos)
            chained = is_cmp
        return lhs

    def prefix(self) -> Expr:
        tok = self.next()
        if tok.kind == "num":
            return Num(float(tok.text), tok.pos)
        if tok.kind == "name":
            nxt = self.peek()
            if nxt.kind == "op" and nxt.text == "(":
                return self.call(tok)
            return Name(tok.text, tok.pos)
        if tok.kind == "op" and tok.text in _PREFIX:
            operand = self.expr(_PREFIX[tok.text])
            return operand if tok.text == "+" else Unary(tok.text, operand, tok.pos)
        if tok.kind == "op" and tok.text == "(":
            inner = self.expr(0)
            self.expect(")", tok)
            return inner
        raise self.fail(tok, "an operand")

    def call(self, name: Token) -> Call:
        if name.text not in FUNCTIONS:
            known = sorted(FUNCTIONS)
            close = difflib.get_close_matches(name.text, known, n=3)
            hint = (f"did you mean {' or '.join(repr(c) for c in close)}? " if close else "")
            raise expr_error("MPG202", f"unknown function '{name.text}'", name.pos, self.text,
                             expected="a whitelisted function", found=repr(name.text),
                             hint=hint + "functions: " + ", ".join(known))
        opened = self.next()
        args: list[Expr] = []
        if not (self.peek().kind == "op" and self.peek().text == ")"):
            args.append(self.expr(0))
            while self.peek().kind == "op" and self.peek().text == ",":
                self.next()
                args.append(self.expr(0))
        tok = self.peek()
        if not (tok.kind == "op" and tok.text == ")"):
            raise self.fail(tok, "',' or ')'", hint=f"'(' opened at offset {opened.pos}")
        self.next()
        _check_arity(name.text, len(args), name.pos, self.text)
        return Call(name.text, tuple(args), name.pos)


def arity_text(func: str) -> str:
    """Human description of the accepted argument count of func."""
    lo, hi = FUNCTIONS[func]
    if func == "piecewise":
        return "an odd number (>= 3) of arguments: c1, v1, ..., default"
    if hi == lo:
        return f"{lo} argument{'s' if lo != 1 else ''}"
    return f"at least {lo} argument{'s' if lo != 1 else ''}"


def _check_arity(func: str, count: int, pos: int, text: str) -> None:
    lo, hi = FUNCTIONS[func]
    ok = count >= lo and (hi is None or count <= hi)
    if func == "piecewise":
        ok = ok and count % 2 == 1
    if not ok:
        raise expr_error("MPG203", f"wrong number of arguments to '{func}'", pos, text,
                         expected=arity_text(func),
                         found=f"{count} argument{'s' if count != 1 else ''}")


def parse(text: str) -> Expr:
    """Parse expression text; raises ExprError (MPG201/202/203) with .offset set."""
    return _Parser(text).parse()


def parse_value(value: object) -> Expr:
    """Parse a YAML scalar: numbers become Num, strings are parsed, anything else is rejected.

    Booleans (YAML true/false) and NaN are not numbers here: both raise MPG201.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise expr_error("MPG201", "not an expression", 0, "",
                         expected="a number-valued expression", found=_describe_value(value))
    if isinstance(value, str):
        return parse(value)
    if isinstance(value, float) and math.isnan(value):
        raise expr_error("MPG201", "not a number (NaN)", 0, "", expected="a number-valued expression",
                         found=".nan")
    return Num(float(value), 0)


def not_a_bool(value: object) -> object:
    """Pydantic before-validator of expression and number fields: YAML true/false is no number."""
    if isinstance(value, bool):
        raise ValueError(f"{str(value).lower()} is a boolean, not a number; expected a number-valued expression")
    if isinstance(value, float) and math.isnan(value):
        raise ValueError("NaN is not a value; expected a number-valued expression")
    return value


def _describe_value(value: object) -> str:
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    return f"a {type(value).__name__}" if isinstance(value, (dict, list)) else repr(value)


# ---------------------------------------------------------------------------------------------
# Walkers (iterative: an expression may be a chain of thousands of terms)


def children(expr: Expr) -> tuple[Expr, ...]:
    """The direct subexpressions of expr, in source order."""
    if isinstance(expr, Unary):
        return (expr.operand,)
    if isinstance(expr, Binary):
        return (expr.left, expr.right)
    if isinstance(expr, Call):
        return expr.args
    return ()


def walk(expr: Expr) -> Iterator[Expr]:
    """All nodes of expr, parents before children (depth first, left to right)."""
    stack = [expr]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(children(node)))


def fold(expr: Expr, visit: Callable[[Expr, list], object]) -> object:
    """visit(node, values of its children) for every node, children first; no recursion."""
    out: list = []
    stack: list[tuple[Expr, bool]] = [(expr, False)]
    while stack:
        node, ready = stack.pop()
        kids = children(node)
        if kids and not ready:
            stack.append((node, True))
            stack.extend((k, False) for k in reversed(kids))
            continue
        if kids:
            vals = out[len(out) - len(kids):]
            del out[len(out) - len(kids):]
        else:
            vals = []
        out.append(visit(node, vals))
    return out[0]


def free_names(expr: Expr) -> set[str]:
    """Names referenced by expr (constants such as pi included if used)."""
    return {node.id for node in walk(expr) if isinstance(node, Name)}


# ---------------------------------------------------------------------------------------------
# Kinds: numbers and truth values (comparisons, and/or/not) are not interchangeable

_BOOL, _NUM = "truth value", "number"


def _what(expr: Expr) -> str:
    if isinstance(expr, Unary) and expr.op == "not":
        return "a negation ('not')"
    if isinstance(expr, Binary) and expr.op in LOGIC:
        return f"a logical '{expr.op}'"
    return "a comparison"


def _kind_error(node: Expr, where: str) -> ExprError:
    text = to_text(node)
    shown = text if len(text) <= 60 else text[:57] + "..."
    return expr_error("MPG206", f"{_what(node)} is not a number", node.pos, "",
                      expected="a number-valued expression", found=f"{shown!r} ({where})",
                      hint=f"comparisons and and/or/not belong in conditions: write if_else({shown}, 1, 0)"
                      if len(text) <= 60 else "comparisons and and/or/not belong in if_else/piecewise conditions")


def check_number(expr: Expr) -> None:
    """Raise ExprError MPG206 unless expr is number-valued throughout.

    Comparisons and and/or/not give truth values; these may only be conditions of if_else and
    piecewise or operands of and/or/not, never terms of arithmetic, function arguments, branch
    values or the value of the whole expression.
    """
    def need(node: Expr, kind: str, where: str) -> None:
        if kind == _BOOL:
            raise _kind_error(node, where)

    def visit(node: Expr, kinds: list) -> str:
        if isinstance(node, (Num, Name)):
            return _NUM
        if isinstance(node, Unary):
            if node.op == "not":
                return _BOOL
            need(node.operand, kinds[0], "negated with '-'")
            return _NUM
        if isinstance(node, Binary):
            if node.op in LOGIC:
                return _BOOL
            where = "compared" if node.op in COMPARISONS else f"an operand of '{node.op}'"
            need(node.left, kinds[0], where)
            need(node.right, kinds[1], where)
            return _BOOL if node.op in COMPARISONS else _NUM
        args = node.args
        if node.func == "if_else":
            values = [1, 2]
        elif node.func == "piecewise":
            values = list(range(1, len(args) - 1, 2)) + [len(args) - 1]
        else:
            values = range(len(args))
        for i in values:
            need(args[i], kinds[i], f"a value of {node.func}()" if node.func in ("if_else", "piecewise")
                 else f"an argument of {node.func}()")
        return _NUM

    top = fold(expr, visit)
    if top == _BOOL:
        raise _kind_error(expr, "the value of the whole expression")


# ---------------------------------------------------------------------------------------------
# Evaluation on floats (NaN propagates: a NaN operand gives NaN, also through min, max, clip,
# comparisons, and/or/not and the conditions of if_else and piecewise)

_nan = math.nan


def _isnan(x: float) -> bool:
    return x != x


def _truth(x: float) -> bool:
    return x != 0.0


def _sign(x: float) -> float:
    return _nan if _isnan(x) else float((x > 0) - (x < 0))


def _min(*a: float) -> float:
    return _nan if any(map(_isnan, a)) else min(a)


def _max(*a: float) -> float:
    return _nan if any(map(_isnan, a)) else max(a)


def _clip(x: float, lo: float, hi: float) -> float:
    return _min(_max(x, lo), hi)


_MATH: dict[str, Callable[..., float]] = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
    "atan": math.atan, "atan2": math.atan2, "sinh": math.sinh, "cosh": math.cosh,
    "tanh": math.tanh, "exp": math.exp, "log": math.log, "log10": math.log10,
    "sqrt": math.sqrt, "abs": abs, "sign": _sign, "floor": lambda x: float(math.floor(x)),
    "ceil": lambda x: float(math.ceil(x)), "fmod": math.fmod, "hypot": math.hypot,
    "sq": lambda x: x * x, "min": _min, "max": _max,
    "clip": _clip, "sat": _clip,
    "norm_2": lambda *a: math.sqrt(sum(x * x for x in a)),
    "norm_1": lambda *a: sum(abs(x) for x in a),
    "norm_inf": lambda *a: _max(*(abs(x) for x in a)),
}


def _compare(op: Callable[[float, float], bool]) -> Callable[[float, float], float]:
    return lambda a, b: _nan if _isnan(a) or _isnan(b) else float(op(a, b))


_BINARY: dict[str, Callable[[float, float], float]] = {
    "+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b,
    "/": lambda a, b: a / b, "^": math.pow,
    "<": _compare(lambda a, b: a < b), "<=": _compare(lambda a, b: a <= b),
    ">": _compare(lambda a, b: a > b), ">=": _compare(lambda a, b: a >= b),
    "==": _compare(lambda a, b: a == b), "!=": _compare(lambda a, b: a != b),
}


class _Failed:
    """A math error in a subexpression; it is raised only if the value is used (branch taken)."""

    __slots__ = ("error",)

    def __init__(self, error: ExprError):
        self.error = error


def evaluate(expr: Expr, env: Mapping[str, float]) -> float:
    """Numeric value of expr given name values (pi, e, inf are known unless overridden).

    Raises ExprError MPG204 for an unknown name and MPG205 for a math error (division by zero,
    sqrt of a negative number, overflow). if_else/piecewise/and/or only fail for the branch taken.
    """
    known = {**CONSTANTS, **env}
    for node in walk(expr):
        if isinstance(node, Name) and node.id not in known:
            raise unknown_name_error(node.id, node.pos, list(known))
    value = fold(expr, lambda node, vals: _eval_node(node, vals, known))
    if isinstance(value, _Failed):
        raise value.error
    return value


def _eval_node(node: Expr, vals: list, env: Mapping[str, float]):
    if isinstance(node, Num):
        return node.value
    if isinstance(node, Name):
        return float(env[node.id])
    if isinstance(node, Call) and node.func in ("if_else", "piecewise"):
        *pairs, default = vals
        for cond, value in zip(pairs[::2], pairs[1::2]):
            if isinstance(cond, _Failed) or _isnan(cond):
                return cond
            if _truth(cond):
                return value
        return default
    if isinstance(node, Binary) and node.op in LOGIC:
        left, right = vals
        if isinstance(left, _Failed):
            return left
        if _isnan(left) or (not isinstance(right, _Failed) and _isnan(right)):
            return _nan
        if _truth(left) == (node.op == "or"):  # decided by the left operand
            return float(node.op == "or")
        return right if isinstance(right, _Failed) else float(_truth(right))
    failed = next((v for v in vals if isinstance(v, _Failed)), None)
    if failed is not None:
        return failed
    try:
        if isinstance(node, Unary):
            (value,) = vals
            if node.op == "-":
                return -value
            return value if _isnan(value) else float(not _truth(value))
        if isinstance(node, Binary):
            return _BINARY[node.op](*vals)
        return float(_MATH[node.func](*vals))
    except (ValueError, ZeroDivisionError, OverflowError) as exc:
        return _Failed(expr_error("MPG205", "cannot evaluate expression", node.pos, "",
                                  expected="a finite real value", found=f"{to_text(node)} ({exc})"))


# ---------------------------------------------------------------------------------------------
# Printing

_LEVEL = {"or": 1, "and": 2, **{op: 4 for op in COMPARISONS}, "+": 5, "-": 5, "*": 6, "/": 6,
          "^": 8}
_NOT, _NEG, _ATOM = 3, 7, 9


def _level(expr: Expr) -> int:
    if isinstance(expr, Binary):
        return _LEVEL[expr.op]
    if isinstance(expr, Unary):
        return _NOT if expr.op == "not" else _NEG
    if isinstance(expr, Num) and (expr.value < 0 or math.copysign(1.0, expr.value) < 0):
        return _NEG
    return _ATOM


def _num_text(value: float) -> str:
    if math.isnan(value):
        return "(inf - inf)"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value)) if value or math.copysign(1.0, value) > 0 else "-0"
    return repr(value)


def to_text(expr: Expr) -> str:
    """Canonical text of expr; parse(to_text(e)) == e."""
    return fold(expr, _text_node)


def _text_node(expr: Expr, texts: list[str]) -> str:
    if isinstance(expr, Num):
        return _num_text(expr.value)
    if isinstance(expr, Name):
        return expr.id
    if isinstance(expr, Call):
        return f"{expr.func}({', '.join(texts)})"
    if isinstance(expr, Unary):
        inner = _wrap(texts[0], _level(expr.operand) < _level(expr))
        return f"not {inner}" if expr.op == "not" else f"-{inner}"
    level = _LEVEL[expr.op]
    if expr.op == "^":
        left = _wrap(texts[0], _level(expr.left) <= level)
        right = _wrap(texts[1], _level(expr.right) < _NEG)
    else:
        left = _wrap(texts[0], _level(expr.left) < level or (
            level == 4 and _level(expr.left) == 4))
        right = _wrap(texts[1], _level(expr.right) <= level)
    return f"{left} {expr.op} {right}"


def _wrap(text: str, paren: bool) -> str:
    return f"({text})" if paren else text
