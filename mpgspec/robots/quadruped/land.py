"""A landing for point-foot quadrupeds: the jump's stance law held at rest, with the legs in the air held
in a crouch.

On the contact flags of the state (contact events):

- a foot out of contact holds the crouch (`pose`) by joint PD, so the legs reach down before the
  touchdowns;
- the feet in contact share the trunk wrench m (g + k_z (h - z) - d_z zdot) upwards, with the
  CoM pulled over the feet as it stands in the crouch (k_xy), its horizontal velocity damped, the
  trunk levelled and turned to the heading of the feet (k_yaw: a push in the air lands it turned),
  as the jump's push and the trot's stance, mapped to torques tau = h_leg - J_leg^T f through each
  foot's Jacobian;
- with `touchdown` gains, k_z, d_z and k_xy are those until `stiffen_after` seconds after the first
  touchdown (on its event clock), then ramp to the law's over `stiffen` seconds: soft while the
  landing is absorbed (stiff, the feet bounce off), stiff at rest;
- with `torque_limit`, the trunk's vertical force is scaled down where it would ask a stance joint more
  than the limit: the landing speed is taken out at bounded torques (the damping on it asked 78 N m of a
  rear calf at the A1's first touchdown, the rear feet alone down for 31 ms).

Unlike the paper's joint PD about a crouch (which, with four feet down, pushes them against each other
and holds the height only as stiffly as its joint gains), the force split has no internal force, and
the height is held by a CoM law: a heavier robot or weaker motors move the rest little. The law reads
only the state, not x*(t): Land's setpoint is this loop's own flow from Jump (mpgspec gait).
"""
from __future__ import annotations

import casadi as ca

from ...compile.events import clock_name, happened
from ...errors import SpecError
from .stance import (leg_torques, level_trunk_moment, nominal_geometry, nominal_state, quadruped_legs,
                     split_wrench, trunk)


def land_torque(sys, c, mode: dict, s) -> ca.SX:
    """u(x, s) of the landing (s: time since switch-in); mode[f] is 1 while foot f is in contact."""
    m = sys.model
    feet = m.contact_frames
    tk = trunk(sys)
    inertia, offsets = nominal_geometry(sys, dict(c.pose))
    x0 = nominal_state(sys, dict(c.pose))
    h = float(c.height) if c.height is not None else float(ca.Function("com_z", [sys.x], [tk.com[2]])(x0))
    centre = sum(tk.pos[f][:2] for f in feet) / len(feet)  # the feet's centroid: where they stand, or will
    offset = ca.Function("offset", [sys.x], [tk.com[:2] - centre])(x0)  # the crouch's CoM over it, heading x
    goal = centre + ca.mtimes(tk.Ryaw[:2, :2], offset)
    kz, dz, kxy = _gains(sys, c, s)
    force = tk.mass * ca.vertcat(kxy * (goal - tk.com[:2]) - float(c.kv) * tk.cdot[:2],
                                 tk.grav + kz * (h - tk.com[2]) - dz * tk.cdot[2])
    moment = level_trunk_moment(tk, inertia, float(c.k_tilt), float(c.d_tilt), float(c.d_yaw))
    turn = _heading(tk, offsets) - ca.atan2(tk.Ryaw[1, 0], tk.Ryaw[0, 0])
    turn = turn - ca.Function("turn", [sys.x], [turn])(x0)  # the crouch's own, 0 when it is symmetric
    moment[2] += float(inertia[2, 2]) * float(c.k_yaw) * ca.atan2(ca.sin(turn), ca.cos(turn))
    wrench = ca.vertcat(force, moment)
    q, v = sys.x[7:m.nq], sys.x[m.nq + 6:m.nq + m.nv]
    hold = float(c.kp_joint) * (ca.DM(x0[7:m.nq]) - q) - float(c.kd_joint) * v
    if c.torque_limit is None:
        f_all = split_wrench(tk, mode, feet, wrench, float(c.moment_weight), float(c.regularization))
        return leg_torques(sys, tk, mode, f_all, hold)
    return _torque_limited(sys, tk, mode, feet, wrench, hold, c)


def land_law(c, ctx) -> ca.SX:
    """Land's u(x) for a compiled primitive: the contact flags in the state (contact events), else the
    primitive's contact set."""
    quadruped_legs(ctx.sys, ctx.ec, "landing")
    unknown = [j for j in c.pose if j not in ctx.sys.state_names[7:ctx.sys.model.nq]]
    if unknown:
        raise SpecError("unknown joint in the landing's pose", location=ctx.ec.locate(("controller", "pose", unknown[0])),
                        key=f"{ctx.ec.owner}: controller.pose", expected="joint names of the system",
                        found=repr(unknown[0][:60]), code="MPG106")
    sys = ctx.sys
    if c.touchdown is not None and not sys.events:
        raise SpecError("the landing's touchdown gains ramp on the first touchdown's event clock",
                        location=ctx.ec.locate(("controller", "touchdown")), key=f"{ctx.ec.owner}: controller.touchdown",
                        expected="system.contact_events: true", found="a system without contact events",
                        code="MPG108")
    feet = sys.model.contact_frames
    mode = {f: sys.contact_flag(f) for f in feet} if sys.events else ctx.plan.mode(feet, ctx.t)
    return land_torque(sys, c, mode, ctx.s)


def _torque_limited(sys, tk, mode: dict, feet, wrench: ca.SX, hold: ca.SX, c) -> ca.SX:
    """u with the trunk's vertical force f_z scaled down where it would ask a stance joint more than
    c.torque_limit: the split is linear in the wrench, so u = a + f_z b (a: the rest of the wrench, the
    legs' nonlinear effects and the legs in the air; b: per unit f_z), and f_z is kept in the interval where
    every stance joint asks at most the limit, |a_j + f_z b_j| <= limit, its ends taken no further than 0
    (where a_j alone exceeds the limit, f_z = 0 leaves a_j: only the vertical force is scaled, and the
    motors' bound still applies)."""
    nj = sys.model.nq - 7
    rhs = ca.horzcat(ca.vertcat(wrench[:2], 0, wrench[3:]), ca.DM([0, 0, 1, 0, 0, 0]))
    f2 = split_wrench(tk, mode, feet, rhs, float(c.moment_weight), float(c.regularization))
    a = leg_torques(sys, tk, mode, f2[:, 0], hold)
    b = leg_torques(sys, tk, mode, f2[:, 1], ca.SX.zeros(nj)) - leg_torques(sys, tk, mode, ca.SX.zeros(f2.shape[0]),
                                                                              ca.SX.zeros(nj))
    lim, fz = float(c.torque_limit), wrench[2]
    for j in range(sys.model.nu):  # the interval's upper end
        room = ca.if_else(b[j] > 0, (lim - a[j]) / ca.fmax(b[j], 1e-9), (lim + a[j]) / ca.fmax(-b[j], 1e-9))
        fz = ca.if_else(ca.fabs(b[j]) > 1e-9, ca.fmin(fz, ca.fmax(room, 0)), fz)
    for j in range(sys.model.nu):  # and its lower end (a pull the rest of the wrench asks)
        room = ca.if_else(b[j] > 0, (lim + a[j]) / ca.fmax(b[j], 1e-9), (lim - a[j]) / ca.fmax(-b[j], 1e-9))
        fz = ca.if_else(ca.fabs(b[j]) > 1e-9, ca.fmax(fz, -ca.fmax(room, 0)), fz)
    return a + fz * b


def _heading(tk, offsets: dict) -> ca.SX:
    """Yaw of the feet's polygon: from the midpoint of the feet behind the CoM in the nominal crouch
    (`offsets`, heading x) to that of the feet ahead of it."""
    front = [f for f, o in offsets.items() if o[0] > 0]
    rear = [f for f, o in offsets.items() if o[0] <= 0]
    d = sum(tk.pos[f] for f in front) / len(front) - sum(tk.pos[f] for f in rear) / len(rear)
    return ca.atan2(d[1], d[0])


def _gains(sys, c, s) -> tuple:
    """(k_z, d_z, k_xy): those of `touchdown` until the first touchdown, then a linear ramp to the law's
    over `stiffen` seconds from `stiffen_after` on its event clock; the law's throughout without it."""
    final = (float(c.kz), float(c.dz), float(c.kp_xy))
    if c.touchdown is None:
        return final
    start = [f if g is None else float(g) for f, g in zip(final, (c.touchdown.kz, c.touchdown.dz, c.touchdown.kp_xy))]
    tau = sys.x[sys.state_names.index(clock_name("first_touchdown"))]
    w = ca.if_else(happened(tau, s), ca.fmin(ca.fmax(tau - float(c.stiffen_after), 0) / float(c.stiffen), 1), 0)
    return tuple(g0 + (g1 - g0) * w for g0, g1 in zip(start, final))
