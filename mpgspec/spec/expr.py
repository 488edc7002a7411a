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
KEYWORDS = frozenset({"and", "or", "not"})

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
    new = ExprError(err.message, location=Location(location.file, location.line, column),
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
        if ch.isdigit() or (ch == "." and i + 1 < n and text[i + 1].isdigit()):
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
    """Parse a YAML scalar: numbers become Num, strings are parsed, anything else is rejected."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise expr_error("MPG201", "not an expression", 0, "",
                         expected="a number or an expression", found=_describe_value(value))
    if isinstance(value, str):
        return parse(value)
    return Num(float(value), 0)


def _describe_value(value: object) -> str:
    if value is None:
        return "nothing (null)"
    if isinstance(value, bool):
        return str(value).lower()
    return f"a {type(value).__name__}" if isinstance(value, (dict, list)) else repr(value)


# ---------------------------------------------------------------------------------------------
# Walkers


def walk(expr: Expr) -> Iterator[Expr]:
    """All nodes of expr, parents before children."""
    yield expr
    if isinstance(expr, Unary):
        yield from walk(expr.operand)
    elif isinstance(expr, Binary):
        yield from walk(expr.left)
        yield from walk(expr.right)
    elif isinstance(expr, Call):
        for arg in expr.args:
            yield from walk(arg)


def free_names(expr: Expr) -> set[str]:
    """Names referenced by expr (constants such as pi included if used)."""
    return {node.id for node in walk(expr) if isinstance(node, Name)}


def _truth(x: float) -> bool:
    return x != 0.0


def _sign(x: float) -> float:
    return float((x > 0) - (x < 0))


def _clip(x: float, lo: float, hi: float) -> float:
    return min(max(x, lo), hi)


_MATH: dict[str, Callable[..., float]] = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
    "atan": math.atan, "atan2": math.atan2, "sinh": math.sinh, "cosh": math.cosh,
    "tanh": math.tanh, "exp": math.exp, "log": math.log, "log10": math.log10,
    "sqrt": math.sqrt, "abs": abs, "sign": _sign, "floor": lambda x: float(math.floor(x)),
    "ceil": lambda x: float(math.ceil(x)), "fmod": math.fmod, "hypot": math.hypot,
    "sq": lambda x: x * x, "min": lambda *a: min(a), "max": lambda *a: max(a),
    "clip": _clip, "sat": _clip,
    "norm_2": lambda *a: math.sqrt(sum(x * x for x in a)),
    "norm_1": lambda *a: sum(abs(x) for x in a),
    "norm_inf": lambda *a: max(abs(x) for x in a),
}

_BINARY: dict[str, Callable[[float, float], float]] = {
    "+": lambda a, b: a + b, "-": lambda a, b: a - b, "*": lambda a, b: a * b,
    "/": lambda a, b: a / b, "^": math.pow,
    "<": lambda a, b: float(a < b), "<=": lambda a, b: float(a <= b),
    ">": lambda a, b: float(a > b), ">=": lambda a, b: float(a >= b),
    "==": lambda a, b: float(a == b), "!=": lambda a, b: float(a != b),
}


def evaluate(expr: Expr, env: Mapping[str, float]) -> float:
    """Numeric value of expr given name values (pi, e, inf are known unless overridden).

    Raises ExprError MPG204 for an unknown name and MPG205 for a math error (division by zero,
    sqrt of a negative number, overflow). if_else/piecewise/and/or only evaluate the branch taken.
    """
    known = {**CONSTANTS, **env}
    for node in walk(expr):
        if isinstance(node, Name) and node.id not in known:
            raise unknown_name_error(node.id, node.pos, list(known))
    return _eval(expr, known)


def _eval(expr: Expr, env: Mapping[str, float]) -> float:
    if isinstance(expr, Num):
        return expr.value
    if isinstance(expr, Name):
        return float(env[expr.id])
    try:
        if isinstance(expr, Unary):
            value = _eval(expr.operand, env)
            return -value if expr.op == "-" else float(not _truth(value))
        if isinstance(expr, Binary):
            left = _eval(expr.left, env)
            if expr.op == "and":
                return float(_truth(left) and _truth(_eval(expr.right, env)))
            if expr.op == "or":
                return float(_truth(left) or _truth(_eval(expr.right, env)))
            return _BINARY[expr.op](left, _eval(expr.right, env))
        if expr.func == "if_else":
            cond, a, b = expr.args
            return _eval(a if _truth(_eval(cond, env)) else b, env)
        if expr.func == "piecewise":
            *pairs, default = expr.args
            for cond, value in zip(pairs[::2], pairs[1::2]):
                if _truth(_eval(cond, env)):
                    return _eval(value, env)
            return _eval(default, env)
        return float(_MATH[expr.func](*(_eval(a, env) for a in expr.args)))
    except (ValueError, ZeroDivisionError, OverflowError) as exc:
        raise expr_error("MPG205", "cannot evaluate expression", expr.pos, "",
                         expected="a finite real value",
                         found=f"{to_text(expr)} ({exc})") from None


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
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value)) if value or math.copysign(1.0, value) > 0 else "-0"
    return repr(value)


def to_text(expr: Expr) -> str:
    """Canonical text of expr; parse(to_text(e)) == e."""
    if isinstance(expr, Num):
        return _num_text(expr.value)
    if isinstance(expr, Name):
        return expr.id
    if isinstance(expr, Call):
        return f"{expr.func}({', '.join(to_text(a) for a in expr.args)})"
    if isinstance(expr, Unary):
        inner = _wrap(expr.operand, _level(expr.operand) < _level(expr))
        return f"not {inner}" if expr.op == "not" else f"-{inner}"
    level = _LEVEL[expr.op]
    if expr.op == "^":
        left = _wrap(expr.left, _level(expr.left) <= level)
        right = _wrap(expr.right, _level(expr.right) < _NEG)
    else:
        left = _wrap(expr.left, _level(expr.left) < level or (
            level == 4 and _level(expr.left) == 4))
        right = _wrap(expr.right, _level(expr.right) <= level)
    return f"{left} {expr.op} {right}"


def _wrap(expr: Expr, paren: bool) -> str:
    text = to_text(expr)
    return f"({text})" if paren else text
