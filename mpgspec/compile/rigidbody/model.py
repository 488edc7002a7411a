"""Kinematic tree of a URDF robot, read once from pinocchio into plain numpy data.

The symbolic algorithms never touch pinocchio objects: everything they need (tree topology,
joint axes, placements, inertias, frames) is copied here so the CasADi graphs depend only on
numbers, and pinocchio stays available as the numerical reference (``pin_model``).
"""
from __future__ import annotations

import os
import sysconfig
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def find_urdf(package_relative: str) -> Path:
    """Locate a file shipped by a cmeel wheel, e.g. ``find_urdf("example-robot-data/robots/a1_description/urdf/a1.urdf")``.

    cmeel packages (example-robot-data, ...) install data under ``<site>/cmeel.prefix/share``
    rather than in an importable module, so the path is resolved against each site directory.
    """
    roots = {sysconfig.get_paths()[k] for k in ("purelib", "platlib")}
    tried = []
    for root in sorted(roots):
        path = Path(root) / "cmeel.prefix" / "share" / package_relative
        tried.append(str(path))
        if path.is_file():
            return path
    raise FileNotFoundError(f"{package_relative!r} not found; tried: {', '.join(tried)}")


@dataclass(frozen=True)
class Joint:
    """One joint of the tree with the body it carries (inertia about the body CoM)."""

    name: str
    kind: str  # "free", "revolute" or "prismatic"
    parent: int  # index in RigidBodyModel.joints, -1 for the world
    axis: np.ndarray  # unit axis of 1-dof joints (zeros for "free")
    idx_q: int
    idx_v: int
    nq: int
    nv: int
    rotation: np.ndarray  # placement of the joint frame in the parent joint frame
    translation: np.ndarray
    mass: float
    lever: np.ndarray  # CoM in the joint frame
    inertia: np.ndarray  # rotational inertia about the CoM


@dataclass(frozen=True)
class Frame:
    """An operational frame rigidly attached to a joint (-1: attached to the world)."""

    name: str
    joint: int
    rotation: np.ndarray
    translation: np.ndarray


def _joint_kind(jm) -> tuple[str, np.ndarray]:
    short = jm.shortname()
    if short == "JointModelFreeFlyer":
        return "free", np.zeros(3)
    for prefix, kind in (("JointModelR", "revolute"), ("JointModelP", "prismatic")):
        if short in (prefix + "X", prefix + "Y", prefix + "Z"):
            return kind, np.array(_AXES[short[-1]])
    if short in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        axis = np.asarray(jm.extract().axis, dtype=float)
        kind = "revolute" if "Revolute" in short else "prismatic"
        return kind, axis / np.linalg.norm(axis)
    raise NotImplementedError(f"joint type {short} is not supported")


class RigidBodyModel:
    """A URDF robot as a tree of joints (free-flyer root optional) plus named contact frames."""

    def __init__(self, urdf: str | os.PathLike, contact_frames: Sequence[str] = (),
                 floating_base: bool = True) -> None:
        self.urdf = Path(urdf)
        args = (pin.JointModelFreeFlyer(),) if floating_base else ()
        model = pin.buildModelFromUrdf(str(self.urdf), *args)
        self.pin_model = model
        self.joints: tuple[Joint, ...] = tuple(self._read_joint(model, i)
                                               for i in range(1, model.njoints))
        self.frames: tuple[Frame, ...] = tuple(
            Frame(f.name, int(f.parentJoint) - 1, np.array(f.placement.rotation),
                  np.array(f.placement.translation)) for f in model.frames)
        self._frame_index = {f.name: k for k, f in enumerate(self.frames)}
        missing = [n for n in contact_frames if n not in self._frame_index]
        if missing:
            raise KeyError(f"unknown contact frames {missing}")
        self.contact_frames: tuple[str, ...] = tuple(contact_frames)
        self.floating_base = bool(self.joints) and self.joints[0].kind == "free"
        self.gravity = np.array(model.gravity.linear)
        self.armature = np.array(model.armature, dtype=float)

    @staticmethod
    def _read_joint(model: pin.Model, i: int) -> Joint:
        jm = model.joints[i]
        kind, axis = _joint_kind(jm)
        placement, body = model.jointPlacements[i], model.inertias[i]
        return Joint(
            name=model.names[i], kind=kind, parent=int(model.parents[i]) - 1, axis=axis,
            idx_q=jm.idx_q, idx_v=jm.idx_v, nq=jm.nq, nv=jm.nv,
            rotation=np.array(placement.rotation), translation=np.array(placement.translation),
            mass=float(body.mass), lever=np.array(body.lever), inertia=np.array(body.inertia))

    @property
    def nq(self) -> int:
        return self.pin_model.nq

    @property
    def nv(self) -> int:
        return self.pin_model.nv

    @property
    def n_base(self) -> int:
        """Unactuated velocity coordinates (6 for a floating base)."""
        return 6 if self.floating_base else 0

    @property
    def nu(self) -> int:
        return self.nv - self.n_base

    @property
    def joint_names(self) -> tuple[str, ...]:
        """Actuated joint names in velocity order."""
        return tuple(j.name for j in self.joints if j.kind != "free")

    @property
    def total_mass(self) -> float:
        return float(sum(j.mass for j in self.joints))

    @property
    def actuation_matrix(self) -> np.ndarray:
        """B = [0; I]: the actuated joints are the last nu velocity coordinates."""
        return np.vstack([np.zeros((self.n_base, self.nu)), np.eye(self.nu)])

    def _actuated(self, values: np.ndarray, base: int) -> np.ndarray:
        return np.array(values[base:], dtype=float)

    @property
    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) position limits of the actuated joints."""
        m, nqb = self.pin_model, self.nq - self.nu
        return self._actuated(m.lowerPositionLimit, nqb), self._actuated(m.upperPositionLimit, nqb)

    @property
    def velocity_limits(self) -> np.ndarray:
        """Symmetric velocity bound of the actuated joints."""
        return self._actuated(self.pin_model.velocityLimit, self.n_base)

    @property
    def effort_limits(self) -> np.ndarray:
        """Symmetric torque bound of the actuated joints."""
        return self._actuated(self.pin_model.effortLimit, self.n_base)

    def frame_index(self, name: str) -> int:
        return self._frame_index[name]

    def frame(self, name: str) -> Frame:
        return self.frames[self._frame_index[name]]

    def chain(self, frame: str) -> tuple[Joint, ...]:
        """The actuated joints on the path from the base (or the world) to `frame`, base first: a
        leg's joints when `frame` is its foot (the tree's order, whatever the URDF lists first)."""
        out, j = [], self.frame(frame).joint
        while j >= 0 and self.joints[j].kind != "free":
            out.append(self.joints[j])
            j = self.joints[j].parent
        return tuple(reversed(out))

    def neutral(self) -> np.ndarray:
        """Neutral configuration (identity quaternion, zero joint angles)."""
        return np.array(pin.neutral(self.pin_model))

    def random_configuration(self, rng: np.random.Generator) -> np.ndarray:
        """Random q: unit quaternion, position in [-1, 1]^3, joints uniform within limits."""
        lo, hi = self.position_limits
        q = self.neutral()
        if self.floating_base:
            q[:3] = rng.uniform(-1.0, 1.0, 3)
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        q[self.nq - self.nu:] = rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi))
        return q
