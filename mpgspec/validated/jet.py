"""First-order jets (value and gradient over the start state) and the smooth functions of the tape.

A Jet carries a value and its partial derivatives, each an arb ball or an arb_series; the Taylor
step evaluates the loop on jets of series to enclose the derivative of every Taylor coefficient
over a box of start states (Lohner's method needs the Jacobian of the Taylor map). The functions
below accept arb, arb_series and Jet alike.
"""
from __future__ import annotations

from flint import arb


class Jet:
    """v + sum_i d[i] dx_i."""

    __slots__ = ("v", "d")

    def __init__(self, v, d):
        self.v, self.d = v, d

    @classmethod
    def seed(cls, values, zero) -> list["Jet"]:
        """The jets of independent variables: value i with gradient e_i."""
        n = len(values)
        return [cls(v, [arb(1) if j == i else zero for j in range(n)]) for i, v in enumerate(values)]

    def __add__(self, o):
        if isinstance(o, Jet):
            return Jet(self.v + o.v, [a + b for a, b in zip(self.d, o.d)])
        return Jet(self.v + o, self.d)

    __radd__ = __add__

    def __sub__(self, o):
        if isinstance(o, Jet):
            return Jet(self.v - o.v, [a - b for a, b in zip(self.d, o.d)])
        return Jet(self.v - o, self.d)

    def __rsub__(self, o):
        return Jet(o - self.v, [-a for a in self.d])

    def __neg__(self):
        return Jet(-self.v, [-a for a in self.d])

    def __mul__(self, o):
        if isinstance(o, Jet):
            return Jet(self.v * o.v, [self.v * b + a * o.v for a, b in zip(self.d, o.d)])
        return Jet(self.v * o, [a * o for a in self.d])

    __rmul__ = __mul__

    def __truediv__(self, o):
        if isinstance(o, Jet):
            q = self.v / o.v
            return Jet(q, [(a - q * b) / o.v for a, b in zip(self.d, o.d)])
        return Jet(self.v / o, [a / o for a in self.d])

    def __rtruediv__(self, o):
        q = o / self.v
        return Jet(q, [-q * a / self.v for a in self.d])

    def chain(self, fv, dfv) -> "Jet":
        """f(self) from f(v) and f'(v)."""
        return Jet(fv, [dfv * a for a in self.d])


def neg(a):
    return -a


def twice(a):
    return a + a


def sq(a):
    return a * a


def inv(a):
    return 1 / a


def sqrt(a):
    if isinstance(a, Jet):
        r = a.v.sqrt()
        return a.chain(r, 1 / (r + r))
    return a.sqrt()


def sin(a):
    if isinstance(a, Jet):
        return a.chain(a.v.sin(), a.v.cos())
    return a.sin()


def cos(a):
    if isinstance(a, Jet):
        return a.chain(a.v.cos(), -a.v.sin())
    return a.cos()


def tan(a):
    if isinstance(a, Jet):
        t = a.v.tan()
        return a.chain(t, 1 + t * t)
    return a.tan()


def exp(a):
    if isinstance(a, Jet):
        e = a.v.exp()
        return a.chain(e, e)
    return a.exp()


def log(a):
    if isinstance(a, Jet):
        return a.chain(a.v.log(), 1 / a.v)
    return a.log()


def atan(a):
    if isinstance(a, Jet):
        return a.chain(a.v.atan(), 1 / (1 + a.v * a.v))
    return a.atan()


def pow(a, b):
    """a ** b; an exact small integer exponent by products (defined for negative bases)."""
    if isinstance(b, Jet):
        return exp(b * log(a))
    n = _small_int(b)
    if n is not None:
        return _ipow(a, n)
    if isinstance(a, Jet):
        p = a.v ** b
        return a.chain(p, b * a.v ** (b - 1))
    return a ** b


def _small_int(b) -> int | None:
    if isinstance(b, arb) and b.is_exact() and b.is_integer():
        n = int(float(b.mid()))
        return n if abs(n) <= 64 else None
    return None


def _ipow(a, n: int):
    if n < 0:
        return 1 / _ipow(a, -n)
    r, base = None, a
    while n:
        if n & 1:
            r = base if r is None else r * base
        n >>= 1
        if n:
            base = base * base
    return arb(1) if r is None else r
