"""The legs of a legged robot: named feet and, from the kinematic tree, the joints that move them.

A leg is the chain of actuated joints on the tree's path from the floating base to its foot
(RigidBodyModel.chain), so its configuration, velocity and input indices follow the URDF's tree
whatever order the file lists its joints in. Legs are named in the spec (`system.legs`) or
derived from the contact frames (the frame name without a trailing `_foot`/`_FOOT`).
"""
from __future__ import annotations

from dataclasses import dataclass

from ...errors import SpecError, SpecErrors

FOOT_SUFFIXES = ("_foot", "_FOOT")


@dataclass(frozen=True)
class Leg:
    """A named leg: its foot frame, its joints (base first) and their q, v and input indices."""

    name: str
    foot: str
    joints: tuple[str, ...]
    q: tuple[int, ...]
    v: tuple[int, ...]
    u: tuple[int, ...]


def leg_name(frame: str) -> str:
    """The default name of the leg whose foot is `frame`: FL_foot -> FL, LF_FOOT -> LF."""
    for suffix in FOOT_SUFFIXES:
        if frame.endswith(suffix) and len(frame) > len(suffix):
            return frame[:-len(suffix)]
    return frame


def leg_of(model, name: str, foot: str) -> Leg:
    """Leg `name` ending at `foot`, its joints read off the kinematic tree."""
    chain = model.chain(foot)
    return Leg(name, foot, tuple(j.name for j in chain), tuple(j.idx_q for j in chain),
               tuple(j.idx_v for j in chain), tuple(j.idx_v - model.n_base for j in chain))


def resolve_legs(system, model, locate) -> tuple[Leg, ...]:
    """The legs of a rigid-body spec in the order they are named (derived: the contact order);
    located SpecErrors for a foot that is not a contact or a foot two legs share."""
    if system.legs is None:
        return tuple(leg_of(model, leg_name(f), f) for f in model.contact_frames)
    errors, seen = [], {}
    for name, leg in system.legs.items():
        where = locate(("legs", name, "foot"))
        if leg.foot not in model.contact_frames:
            errors.append(SpecError("a leg's foot must be a contact frame", location=where,
                                    key=f"system.legs.{name}.foot", expected=f"one of {list(model.contact_frames)}",
                                    found=repr(leg.foot[:60]), code="MPG107",
                                    hint="add the frame to system.contacts or name another foot"))
        elif leg.foot in seen:
            errors.append(SpecError("two legs share a foot", location=where, key=f"system.legs.{name}.foot",
                                    expected="a different contact frame per leg",
                                    found=f"{leg.foot!r}, the foot of leg {seen[leg.foot]!r} too", code="MPG106"))
        seen.setdefault(leg.foot, name)
    if errors:
        raise SpecErrors(errors)
    return tuple(leg_of(model, name, leg.foot) for name, leg in system.legs.items())
