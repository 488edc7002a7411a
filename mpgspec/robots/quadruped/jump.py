"""The paper's Jump for point-foot quadrupeds: a cubic CoM profile to a takeoff velocity (eq. 7),
tracked through the stance feet (eq. 9), then the legs tucked.

On the clock t of the primitive:

- t < T_t (push): the CoM height follows the cubic from the stance height h_0 at rest to
  h_0 + rise at the takeoff speed v_t; horizontal CoM velocity is driven to zero and the trunk
  kept level. The wrench m (zddot_d + k_z e + d_z edot + g) (with the levelling moment) is split
  over the feet in contact, as in the trot, and mapped to torques tau = h_leg - J_leg^T f: the
  task-space PD of eq. (9) through the feet's Jacobians (a floating base moves its CoM through the
  ground forces). A foot out of contact holds the stance pose by joint PD.
- t >= T_t (tuck): joint PD to the tuck pose. The feet's normal forces turn negative, so they lift
  off by contact events and the robot flies on the takeoff velocity.

The law reads only the state and the clock, not x*(t): Jump's setpoint table is this loop's own
flow from Stand (mpgspec gait), so x*(t) solves the closed loop (Definition 1).
"""
from __future__ import annotations

import casadi as ca

from ...compile.laws.base import cubic_profile
from ...errors import SpecError
from .stance import (leg_torques, level_trunk_moment, nominal_geometry, nominal_state, quadruped_legs,
                     split_wrench, trunk)


def jump_torque(sys, c, mode: dict, t: ca.SX) -> ca.SX:
    """u(x, t) of the jump; mode[f] is 1 while foot f is in contact (its flag with contact events)."""
    m = sys.model
    feet = m.contact_frames
    tk = trunk(sys)
    inertia, _ = nominal_geometry(sys, dict(c.pose))
    x0 = nominal_state(sys, dict(c.pose))
    h0 = float(ca.Function("com_z", [sys.x], [tk.com[2]])(x0))
    z_d, vz_d = cubic_profile(t, float(c.takeoff_time), ca.DM(h0), ca.DM(0), ca.DM(h0 + float(c.rise)),
                              ca.DM(float(c.takeoff_velocity)))
    az_d = ca.jacobian(vz_d, t)
    force = tk.mass * ca.vertcat(-float(c.kv) * tk.cdot[:2],
                                 tk.grav + az_d + float(c.kz) * (z_d - tk.com[2]) + float(c.dz) * (vz_d - tk.cdot[2]))
    wrench = ca.vertcat(force, level_trunk_moment(tk, inertia, float(c.k_tilt), float(c.d_tilt), float(c.d_yaw)))
    f_all = split_wrench(tk, mode, feet, wrench, float(c.moment_weight), float(c.regularization))
    q, v = sys.x[7:m.nq], sys.x[m.nq + 6:m.nq + m.nv]
    stance_q, tuck_q = ca.DM(x0[7:m.nq]), ca.DM(nominal_state(sys, dict(c.tuck))[7:m.nq])  # joint angles
    kp, kd = float(c.kp_joint), float(c.kd_joint)
    hold = kp * (stance_q - q) - kd * v
    tuck = kp * (tuck_q - q) - kd * v

    def after_takeoff(at, push):  # the legs tuck from T_t on
        return ca.if_else(t < float(c.takeoff_time), push, tuck[at])

    return leg_torques(sys, tk, mode, f_all, hold, then=after_takeoff)


def jump_law(c, ctx) -> ca.SX:
    """Jump's u(x, t) for a compiled primitive: the contact flags in the state (contact events), else
    the primitive's contact set."""
    quadruped_legs(ctx.sys, ctx.ec, "jump")
    for key in ("pose", "tuck"):
        unknown = [j for j in getattr(c, key) if j not in ctx.sys.state_names[7:ctx.sys.model.nq]]
        if unknown:
            raise SpecError(f"unknown joint in the jump's {key}", location=ctx.ec.locate(("controller", key, unknown[0])),
                            key=f"{ctx.ec.owner}: controller.{key}", expected="joint names of the system",
                            found=repr(unknown[0][:60]), code="MPG106")
    sys = ctx.sys
    feet = sys.model.contact_frames
    mode = {f: sys.contact_flag(f) for f in feet} if sys.events else ctx.plan.mode(feet, ctx.t)
    ctx.info["jump"] = {"takeoff_time": float(c.takeoff_time), "takeoff_velocity": float(c.takeoff_velocity),
                        "rise": float(c.rise)}
    return jump_torque(sys, c, mode, ctx.t)

