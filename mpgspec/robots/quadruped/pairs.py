"""The trot's diagonal pairs, named by leg (`controller.pairs`), resolved to feet.

The first pair stands while the second swings first (after the first four-foot support). Without
`pairs`, the A1-style names [[FL, RR], [FR, RL]] are the default when the robot has legs of those
names; any other robot must name its pairs.
"""
from __future__ import annotations

from ...errors import SpecError
from .stance import quadruped_legs

DEFAULT_PAIRS = (("FL", "RR"), ("FR", "RL"))
"""The default pairs, for robots whose legs are named FL, FR, RL, RR (the A1's feet FL_foot, ...)."""


def _locate(ec, *path):
    return ec.locate(("controller", *path)) if ec is not None else None


def trot_pairs(c, sys, ec=None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(feet of the first pair, feet of the second pair) of the trot `c` on `sys`; located SpecErrors
    (ec: the primitive's error context) for an unknown leg, a leg named twice or no pairs on a robot
    without A1-style leg names."""
    legs = quadruped_legs(sys, ec, "trot") if ec is not None else tuple(sys.legs)
    feet = {g.name: g.foot for g in legs}
    owner = f"{ec.owner}: " if ec is not None else ""
    if c.pairs is None:
        if not all(n in feet for pair in DEFAULT_PAIRS for n in pair):
            raise SpecError("the trot's diagonal pairs are not named", location=_locate(ec, "type"),
                            key=f"{owner}controller.pairs", expected="pairs: [[<leg>, <leg>], [<leg>, <leg>]] "
                            "(the default [[FL, RR], [FR, RL]] needs legs of those names)",
                            found=f"legs {sorted(feet)}", code="MPG108",
                            hint="name the diagonal pairs, e.g. pairs: [[LF, RH], [RF, LH]]")
        names = DEFAULT_PAIRS
    else:
        names = tuple(tuple(p) for p in c.pairs)
    seen = set()
    for i, pair in enumerate(names):
        for k, name in enumerate(pair):
            if name not in feet:
                raise SpecError("unknown leg in the trot's pairs", location=_locate(ec, "pairs", i, k),
                                key=f"{owner}controller.pairs", expected=f"one of the legs {sorted(feet)}",
                                found=repr(str(name)[:60]), code="MPG107")
            if name in seen:
                raise SpecError("a leg is named twice in the trot's pairs", location=_locate(ec, "pairs", i, k),
                                key=f"{owner}controller.pairs", expected="each of the four legs once",
                                found=repr(name), code="MPG106")
            seen.add(name)
    return tuple(feet[n] for n in names[0]), tuple(feet[n] for n in names[1])
