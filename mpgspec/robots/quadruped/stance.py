"""What the quadruped laws share: the trunk's symbols, the levelling moment, the split of a trunk
wrench over the stance feet, the nominal stance and its geometry, and the check that a system is
a point-foot quadruped (four legs from the kinematic tree, compile/rigidbody/legs.py)."""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...compile.rigidbody.linalg import dense_ldl_solve
from ...compile.rigidbody.liegroup import qdot, quat_to_rotation
from ...compile.rigidbody.spatial import skew
from ...compile.rigidbody.system import feet_on_ground
from ...errors import SpecError



@dataclass
class Trunk:
    """Symbols of the floating base that the centroidal laws share (functions of sys.x)."""

    mass: float
    grav: float
    R: ca.SX  # base rotation
    Ryaw: ca.SX  # the heading's rotation about z
    com: ca.SX
    cdot: ca.SX
    omega: ca.SX  # base angular velocity, world axes
    pos: dict  # foot -> world position
    vel: dict  # foot -> world velocity
    H: ca.SX  # nonlinear effects h(q, v)
    sub: object  # expression of (dyn.q, dyn.v) -> of the state


def trunk(sys) -> Trunk:
    m, dyn, env = sys.model, sys.dyn, sys.extra_env
    q, v = sys.x[:m.nq], sys.x[m.nq:m.nq + m.nv]
    sub = lambda e: ca.substitute(e, ca.vertcat(dyn.q, dyn.v), ca.vertcat(q, v))  # noqa: E731
    R = quat_to_rotation(q[3:7])
    yaw = ca.atan2(R[1, 0], R[0, 0])
    cy, sy = ca.cos(yaw), ca.sin(yaw)
    Ryaw = ca.vertcat(ca.horzcat(cy, -sy, 0), ca.horzcat(sy, cy, 0), ca.horzcat(0, 0, 1))
    com = ca.vertcat(*[env[f"com_{a}"] for a in "xyz"])
    feet = m.contact_frames
    return Trunk(mass=float(m.total_mass), grav=float(-m.gravity[2]), R=R, Ryaw=Ryaw, com=com,
                 cdot=ca.jtimes(com, q, qdot(m, q, v)), omega=ca.mtimes(R, v[3:6]),
                 pos={f: ca.vertcat(*[env[f"{f}_{a}"] for a in "xyz"]) for f in feet},
                 vel={f: ca.vertcat(*[env[f"{f}_v{a}"] for a in "xyz"]) for f in feet},
                 H=sub(dyn.nle_expr), sub=sub)


def limited(e, bound: float):
    """e scaled down to norm `bound` where it is longer (a saturation that keeps its direction);
    e itself for an infinite bound."""
    if not np.isfinite(bound):
        return e
    return e * ca.fmin(1, bound / ca.sqrt(ca.sumsqr(e) + 1e-12))


def level_trunk_moment(tk: Trunk, inertia: np.ndarray, k_tilt: float, d_tilt: float, d_yaw: float,
                       tilt_limit: float = float("inf")) -> ca.SX:
    """Moment about the CoM that levels the trunk (roll, pitch PD in the heading frame) and damps yaw.
    With a finite tilt_limit, the roll and pitch acceleration the PD asks is scaled down to that norm
    (direction kept): stiff tilt gains hold the orbit, a large error after a switch asks a bounded moment."""
    E = ca.mtimes(tk.Ryaw, tk.R.T)
    e_R = 0.5 * ca.vertcat(E[2, 1] - E[1, 2], E[0, 2] - E[2, 0], E[1, 0] - E[0, 1])
    I_G = ca.mtimes([tk.Ryaw, ca.DM(inertia), tk.Ryaw.T])  # the nominal inertia turned with the heading
    tilt = limited(ca.vertcat(k_tilt * e_R[0] - d_tilt * tk.omega[0], k_tilt * e_R[1] - d_tilt * tk.omega[1]),
                   tilt_limit)
    return ca.mtimes(I_G, ca.vertcat(tilt, -d_yaw * tk.omega[2]))


def split_wrench(tk: Trunk, flags: dict, feet, wrench: ca.SX, moment_weight: float, reg: float) -> ca.SX:
    """Ground forces on the feet with flag 1 whose wrench about the CoM is nearest `wrench`:
    argmin ||A f - w||_S^2 + reg ||f||^2 in closed form (the force on a foot with flag 0 is 0)."""
    cols = [flags[f] * ca.vertcat(ca.DM.eye(3), skew(tk.pos[f] - tk.com)) for f in feet]
    A = ca.horzcat(*cols)
    S = ca.DM(np.diag([1, 1, 1] + [moment_weight] * 3))
    K = ca.mtimes([A.T, S, A]) + reg * ca.DM.eye(3 * len(feet))
    return dense_ldl_solve(K, ca.mtimes([A.T, S, wrench]))


def leg_torques(sys, tk: Trunk, mode: dict, f_all: ca.SX, air: ca.SX, then=None) -> ca.SX:
    """u: on each leg the stance torque h_leg - J_leg^T f of its foot's share f of f_all (feet in the
    order of the contact frames) while the foot is in contact (mode 1), else `air` (torques on every
    joint, in the order of the joint angles); then(at, tau_leg), when given, replaces a leg's torque."""
    m = sys.model
    legs = {leg.foot: leg for leg in sys.legs}
    u = [None] * m.nu
    for i, f in enumerate(m.contact_frames):
        leg = legs[f]
        at = [k - 7 for k in leg.q]  # the leg's joints among the joint angles
        J = tk.sub(sys.dyn.contact_jacobian_expr([f]))[:, list(leg.v)]
        stance = tk.H[list(leg.v)] - ca.mtimes(J.T, f_all[3 * i:3 * i + 3])
        tau_leg = mode[f] * stance + (1 - mode[f]) * air[at]
        tau_leg = tau_leg if then is None else then(at, tau_leg)
        for k, j in enumerate(leg.u):
            u[j] = tau_leg[k]
    return ca.vertcat(*u)


def nominal_state(sys, pose: dict) -> np.ndarray:
    """The nominal stance at rest: the system's default state with the `pose` joint angles, feet on the ground."""
    x = sys.default_state()
    for j, a in pose.items():
        x[sys.state_names.index(j)] = float(a)
    return feet_on_ground(sys, x)


def nominal_geometry(sys, pose: dict) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Centroidal inertia and horizontal foot offsets from the CoM in the nominal stance (`pose`,
    feet on the ground)."""
    import pinocchio as pin

    m = sys.model
    x = nominal_state(sys, pose)
    pm = m.pin_model
    data = pm.createData()
    q = np.asarray(x[:m.nq], float)
    pin.ccrba(pm, data, q, np.zeros(m.nv))
    pin.framesForwardKinematics(pm, data, q)
    com = pin.centerOfMass(pm, data, q)
    offsets = {f: np.asarray(data.oMf[pm.getFrameId(f)].translation[:2] - com[:2]) for f in m.contact_frames}
    return np.array(data.Ig.inertia), offsets


def quadruped_legs(sys, ec, kind: str) -> tuple:
    """The four legs of a floating-base point-foot quadruped, else a SpecError at controller.type
    naming what the system has. Every actuated joint must be on one leg (the laws drive the legs only)."""
    model = getattr(sys, "model", None) if sys.is_rigid_body else None
    legs = tuple(getattr(sys, "legs", ()))
    found = (f"a {getattr(sys, 'kind', 'non-rigid')} system" if model is None else
             f"{'a floating' if model.floating_base else 'a fixed'} base with legs "
             f"{ {g.name: f'{g.foot} ({len(g.joints)} joints)' for g in legs} }")
    on_legs = sorted(k for g in legs for k in g.u)
    ok = model is not None and model.floating_base and len(legs) == 4 and all(g.joints for g in legs) \
        and on_legs == list(range(model.nu))
    if not ok:
        raise SpecError(f"the {kind} needs a floating-base quadruped: four legs whose joints are all the "
                        "actuated joints", location=ec.locate(("controller", "type")),
                        key=f"{ec.owner}: controller.type", expected="system kind rigid_body, floating_base, "
                        "four contacts (or system.legs naming four feet), each foot at the end of its own joints",
                        found=found[:400], code="MPG108")
    return legs
