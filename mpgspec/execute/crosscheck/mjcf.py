"""A MuJoCo model of a rigid-body system, built from the URDF its spec names.

Kept from the URDF: the kinematic tree, masses and inertias, joint limits. Replaced: every visual
and collision element (MuJoCo loads no .dae meshes). Added: a free joint on the root link (for a
floating base), one motor per actuated joint with the spec's torque limit, a sphere of
`foot_radius` at each contact frame, the box, cylinder and sphere collision shapes of the links
welded to the root (the trunk), and a floor `foot_radius` below z = 0 with the spec's friction,
so that a contact frame at z = 0, where mpgspec holds a foot, is a sphere touching the floor.
Robot geoms collide with the floor only. Joint damping and friction are zero and the armature is
pinocchio's, as in mpgspec's dynamics, unless the settings give another (a model error: the motors'
reflected inertia); the friction cone (elliptic or pyramidal) and the floor's friction are the
settings' (by default the spec's friction).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np

from .settings import CrossCheckSettings
from .state import StateMap

ROBOT, FLOOR = 2, 1
"""Collision bits: robot geoms (contype ROBOT, conaffinity FLOOR) touch the floor, not each other."""


@dataclass
class MujocoRobot:
    """The compiled MuJoCo model with the names and indices a replay needs."""

    model: object  # mujoco.MjModel
    state: StateMap
    feet: tuple[str, ...]  # contact frames, in the system's order
    foot_geoms: np.ndarray  # geom id of each foot sphere
    foot_sites: np.ndarray  # site id at each contact frame
    floor: int
    trunk_geoms: np.ndarray
    actuators: np.ndarray  # actuator id of each input, in the system's input order
    info: dict = field(default_factory=dict)


def _vec(text: str | None, n: int = 3) -> np.ndarray:
    return np.zeros(n) if not text else np.array([float(v) for v in text.split()])


def rpy_quat(rpy) -> np.ndarray:
    """URDF roll-pitch-yaw (R = Rz(y) Ry(p) Rx(r)) as a unit quaternion, w first."""
    r, p, y = (0.5 * float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def _root_links(robot: ET.Element) -> tuple[str, list[str]]:
    """The root link and the links welded to it by fixed joints (the trunk)."""
    children = {j.find("child").get("link") for j in robot.findall("joint")}
    root = next(lk.get("name") for lk in robot.findall("link") if lk.get("name") not in children)
    welded, todo = [root], [root]
    while todo:
        parent = todo.pop()
        for j in robot.findall("joint"):
            if j.get("type") == "fixed" and j.find("parent").get("link") == parent:
                welded.append(j.find("child").get("link"))
                todo.append(welded[-1])
    return root, welded


def _strip(robot: ET.Element) -> dict[str, list[tuple]]:
    """Remove visual and collision elements; return the box, cylinder and sphere collision shapes by link."""
    shapes: dict[str, list[tuple]] = {}
    for link in robot.findall("link"):
        for c in link.findall("collision"):
            o, g = c.find("origin"), c.find("geometry")
            pos = _vec(o.get("xyz") if o is not None else None)
            quat = rpy_quat(_vec(o.get("rpy") if o is not None else None))
            for kind in ("box", "cylinder", "sphere"):
                e = g.find(kind) if g is not None else None
                if e is None:
                    continue
                if kind == "box":
                    size = _vec(e.get("size")) / 2
                elif kind == "cylinder":
                    size = np.array([float(e.get("radius")), float(e.get("length")) / 2, 0.0])
                else:
                    size = np.array([float(e.get("radius")), 0.0, 0.0])
                shapes.setdefault(link.get("name"), []).append((kind, size, pos, quat))
        for tag in ("visual", "collision"):
            for e in link.findall(tag):
                link.remove(e)
    return shapes


def build_robot(system, settings: CrossCheckSettings) -> MujocoRobot:
    """Compile the MuJoCo model of a rigid-body CompiledSystem (see the module docstring)."""
    import mujoco

    m = system.model
    robot = ET.fromstring(m.urdf.read_text(encoding="utf-8"))
    for old in robot.findall("mujoco"):
        robot.remove(old)
    shapes = _strip(robot)
    root, welded = _root_links(robot)
    ext = ET.SubElement(robot, "mujoco")
    ET.SubElement(ext, "compiler", {"discardvisual": "true", "fusestatic": "true", "inertiafromgeom": "false",
                                    "angle": "radian", "alignfree": "false", "balanceinertia": "false"})
    spec = mujoco.MjSpec.from_string(ET.tostring(robot, encoding="unicode"))
    child_of = {j.get("name"): j.find("child").get("link") for j in robot.findall("joint")}
    opt = spec.option
    opt.timestep = settings.timestep
    opt.gravity = np.asarray(m.gravity, float)
    opt.integrator = {"euler": mujoco.mjtIntegrator.mjINT_EULER, "rk4": mujoco.mjtIntegrator.mjINT_RK4,
                      "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST}[settings.integrator]
    opt.cone = {"elliptic": mujoco.mjtCone.mjCONE_ELLIPTIC, "pyramidal": mujoco.mjtCone.mjCONE_PYRAMIDAL}[settings.cone]
    opt.impratio = settings.impratio
    opt.noslip_iterations = settings.noslip_iterations
    mu = float(system.friction if settings.friction is None else settings.friction)
    r = settings.foot_radius
    contact = {"contype": ROBOT, "conaffinity": FLOOR, "condim": 3, "friction": [mu, 0.0, 0.0],
               "solref": [settings.timeconst, settings.dampratio], "mass": 0.0}
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 1], pos=[0, 0, -r],
                            **{**contact, "contype": FLOOR, "conaffinity": ROBOT})
    if m.floating_base:
        spec.body(root).add_freejoint(name="root")
    kinds = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
             "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}
    trunk = []
    for link in welded:
        for k, (kind, size, pos, quat) in enumerate(shapes.get(link, [])):
            trunk.append(f"trunk_{link}_{k}")
            spec.body(link).add_geom(name=trunk[-1], type=kinds[kind], size=size, pos=pos, quat=quat, **contact)
    for f in m.contact_frames:
        fr = m.frame(f)
        link = root if fr.joint < 0 or m.joints[fr.joint].kind == "free" else child_of[m.joints[fr.joint].name]
        body = spec.body(link)
        body.add_geom(name=f"foot_{f}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r, 0, 0], pos=fr.translation,
                      **contact)
        body.add_site(name=f"frame_{f}", pos=fr.translation, quat=_mat_quat(fr.rotation))
    armature = dict(zip(m.joint_names, m.armature[m.n_base:]))
    for j in m.joint_names:
        sj = spec.joint(j)
        sj.damping = np.zeros_like(sj.damping) if np.ndim(sj.damping) else 0.0  # a polynomial since MuJoCo 4
        sj.frictionloss, sj.armature = 0.0, float(armature[j] if settings.armature is None else settings.armature)
    for i, j in enumerate(m.joint_names):
        lo, hi = float(system.u_lo[i]), float(system.u_hi[i])
        act = spec.add_actuator(name=f"motor_{j}", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.gainprm[0] = settings.torque_scale  # the torque delivered per torque commanded
        if np.isfinite(lo) and np.isfinite(hi):
            act.ctrlrange, act.ctrllimited = [lo, hi], mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange, act.forcelimited = [lo, hi], mujoco.mjtLimited.mjLIMITED_TRUE
            spec.joint(j).actfrcrange = [lo, hi]
            spec.joint(j).actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
    model = spec.compile()
    ids = lambda kind, names: np.array([mujoco.mj_name2id(model, kind, n) for n in names], int)  # noqa: E731
    OBJ = mujoco.mjtObj
    state = StateMap.of(system, model)
    info = {"mujoco": mujoco.__version__, "urdf": m.urdf.name, "root": root, "mass": float(model.body_mass.sum()),
            "mass_mpgspec": float(m.total_mass), "bodies": int(model.nbody), "geoms": int(model.ngeom),
            "trunk_geoms": trunk, "floor_z": -r}
    return MujocoRobot(model, state, tuple(m.contact_frames), ids(OBJ.mjOBJ_GEOM, [f"foot_{f}" for f in m.contact_frames]),
                       ids(OBJ.mjOBJ_SITE, [f"frame_{f}" for f in m.contact_frames]),
                       mujoco.mj_name2id(model, OBJ.mjOBJ_GEOM, "floor"), ids(OBJ.mjOBJ_GEOM, trunk),
                       ids(OBJ.mjOBJ_ACTUATOR, [f"motor_{j}" for j in m.joint_names]), info)


def _mat_quat(R) -> np.ndarray:
    """Rotation matrix as a unit quaternion, w first."""
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(np.asarray(R, float)).ravel())
    return q
