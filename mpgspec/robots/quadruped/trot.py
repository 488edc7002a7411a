"""A trot for point-foot quadrupeds: stance wrench split, Raibert swing placement, clock-driven phases.

The gait runs on the primitive's clock t within one period T = 2 (T_sw + T_ds): both diagonal
pairs stand for T_ds, then pair B (FR, RL) swings for T_sw while pair A (FL, RR) stands, then both
stand for T_ds, then pair A swings. The law receives the contact mode (which feet the plant holds,
as symbols of the clock) and uses the Jacobians of exactly those feet.

- Stance feet share the trunk wrench that drives the CoM velocity to the command, the CoM height
  to h_d and the trunk level (roll and pitch), with the yaw rate damped; x, y and yaw are not
  tracked, so the orbit can be moved and turned on flat ground (three neutral Floquet directions).
  Forces f = argmin ||A f - w||_S^2 + reg ||f||^2 in closed form, then f_z >= f_min and
  |f_xy| <= 0.9 mu f_z per foot; leg torques tau = h_leg - J_leg^T f.
- Swing feet follow a Cartesian PD (tau = h_leg + J_leg^T (Kp (p_d - p) + Kd (v_d - v))) on a
  path from the lift-off point to the Raibert target c + cdot (T_sw - tau) + cdot T_st / 2 +
  k_v (cdot - v_cmd) (a smoothstep done at 80 % of the swing) and a height profile up to the apex
  and down to the ground at the scheduled touchdown with a set downward speed.

Step-to-step correction comes from where the next pair lands: with two point feet on a diagonal,
no torque changes the angular momentum about the line through them, so a clock-driven joint PD
alone has no stable trot.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...compile.contacts import Schedule, wrap_clock
from ...compile.laws.base import cubic_profile
from ...errors import SpecError
from .stance import PAIR_A, PAIR_B, level_trunk_moment, nominal_geometry, split_wrench, trunk


@dataclass(frozen=True)
class TrotGains:
    """Gait timing, targets and gains (SI units)."""

    speed: float = 0.0  # commanded forward speed in the heading frame (a number, or a symbol)
    swing: float = 0.16  # T_sw
    double_support: float = 0.02  # T_ds
    height: float = 0.2586  # CoM height h_d
    apex: float = 0.07  # swing foot apex
    touchdown_speed: float = 0.3  # downward foot speed at the scheduled touchdown
    kv: float = 10.0  # CoM velocity gain (1/s)
    kz: float = 100.0  # height stiffness (1/s^2)
    dz: float = 20.0  # height damping (1/s)
    k_tilt: float = 300.0  # roll/pitch stiffness (1/s^2)
    d_tilt: float = 30.0  # roll/pitch damping (1/s)
    d_yaw: float = 10.0  # yaw-rate damping (1/s)
    raibert: float = 0.08  # placement gain on the velocity error (s)
    kp_swing: float = 12000.0
    kd_swing: float = 200.0
    f_min: float = 10.0  # least normal force asked of a stance foot (N)
    regularization: float = 1e-4
    moment_weight: float = 10.0

    @property
    def half(self) -> float:
        return self.swing + self.double_support

    @property
    def period(self) -> float:
        return 2 * self.half

    @property
    def stance(self) -> float:
        return self.swing + 2 * self.double_support

    def schedule(self, feet: tuple[str, ...]) -> Schedule:
        """The contact plan over one period: all `feet`, pair A, all, pair B."""
        h, ds = self.half, self.double_support
        return Schedule(((ds, feet), (h, PAIR_A), (h + ds, feet), (2 * h, PAIR_B)), self.period, feet)


def _smoothstep(sig):
    s = ca.fmin(ca.fmax(sig, 0), 1)
    return 3 * s**2 - 2 * s**3, ca.if_else(ca.logic_and(sig > 0, sig < 1), 6 * s * (1 - s), 0)


def trot_torque(sys, g: TrotGains, t: ca.SX, mode: dict[str, ca.SX], inertia: np.ndarray,
                offsets: dict[str, np.ndarray]) -> ca.SX:
    """u(x, t) of the trot on a RigidBodyCompiledSystem; mode[f] is 1 while foot f is held.

    `inertia` is the centroidal inertia at the nominal pose (3 x 3), `offsets` the nominal
    horizontal foot position relative to the CoM in the heading frame, per foot.
    """
    m = sys.model
    feet = m.contact_frames
    flags = mode
    tk = trunk(sys)
    com, cdot, Ryaw = tk.com, tk.cdot, tk.Ryaw
    pos, vel, H, sub = tk.pos, tk.vel, tk.H, tk.sub
    v_cmd = ca.mtimes(Ryaw[:2, :2], ca.vertcat(g.speed, 0.0))  # g.speed may be a symbol (gait calibration)
    # trunk wrench about the CoM
    force = tk.mass * ca.vertcat(g.kv * (v_cmd - cdot[:2]),
                                 tk.grav + g.kz * (g.height - com[2]) - g.dz * cdot[2])
    wrench = ca.vertcat(force, level_trunk_moment(tk, inertia, g.k_tilt, g.d_tilt, g.d_yaw))
    f_all = split_wrench(tk, flags, feet, wrench, g.moment_weight, g.regularization)
    dyn = sys.dyn
    mu = float(sys.friction)
    half, period = g.half, g.period
    tc = wrap_clock(t, period)
    tau_swing = {PAIR_B: tc - g.double_support, PAIR_A: tc - half - g.double_support}
    z_up = lambda s: cubic_profile(s, g.swing / 2, ca.DM(0), ca.DM(0), ca.DM(g.apex), ca.DM(0))  # noqa: E731
    z_dn = lambda s: cubic_profile(s, g.swing / 2, ca.DM(g.apex), ca.DM(0), ca.DM(0), ca.DM(-g.touchdown_speed))  # noqa: E731
    u = []
    for i, f in enumerate(feet):
        leg = slice(6 + 3 * i, 9 + 3 * i)  # the leg of foot i (joint order follows the feet)
        J = sub(dyn.contact_jacobian_expr([f]))[:, leg]
        h_leg = H[leg]
        # stance
        fi = f_all[3 * i:3 * i + 3]
        fz = ca.fmax(fi[2], g.f_min)
        fxy = fi[:2]
        cap = 0.9 * mu * fz
        scale = ca.fmin(1, cap / ca.sqrt(ca.sumsqr(fxy) + 1e-12))
        f_st = ca.vertcat(scale * fxy, fz)
        tau_st = h_leg - ca.mtimes(J.T, f_st)
        # swing
        tau = tau_swing[PAIR_A if f in PAIR_A else PAIR_B]
        tau = ca.fmin(ca.fmax(tau, 0), g.swing)
        d = ca.mtimes(Ryaw[:2, :2], ca.DM(offsets[f]))
        p_lo = com[:2] + d - cdot[:2] * (g.stance / 2 + tau)
        p_td = com[:2] + d + cdot[:2] * (g.swing - tau + g.stance / 2) + g.raibert * (cdot[:2] - v_cmd)
        s, ds = _smoothstep(tau / (0.8 * g.swing))
        p_xy = p_lo + s * (p_td - p_lo)
        v_xy = ds / (0.8 * g.swing) * (p_td - p_lo)
        zu, vu = z_up(tau)
        zd, vd = z_dn(tau - g.swing / 2)
        up = tau < g.swing / 2
        p_d = ca.vertcat(p_xy, ca.if_else(up, zu, zd))
        v_d = ca.vertcat(v_xy, ca.if_else(up, vu, vd))
        tau_sw = h_leg + ca.mtimes(J.T, g.kp_swing * (p_d - pos[f]) + g.kd_swing * (v_d - vel[f]))
        c = flags[f]
        u.append(c * tau_st + (1 - c) * tau_sw)
    return ca.vertcat(*u)


def trot_law(c, ctx) -> ca.SX:
    """The trot's u(x, t) for a compiled primitive (the command and gains come from trot_setup)."""
    unknown = [j for j in c.pose if j not in ctx.sys.state_names]
    if unknown:
        raise SpecError("unknown joint in the trot's pose", location=ctx.ec.locate(("controller", "pose", unknown[0])),
                        key=f"{ctx.ec.owner}: controller.pose", expected="joint names of the system",
                        found=repr(unknown[0][:60]), code="MPG106")
    info = ctx.info["trot"]
    g = gains_of(c, info["command"])
    inertia, offsets = nominal_geometry(ctx.sys, dict(c.pose))
    info["period"] = g.period
    return trot_torque(ctx.sys, g, ctx.t, ctx.plan.mode(ctx.sys.model.contact_frames, ctx.t), inertia, offsets)


def gains_of(c, speed: float) -> TrotGains:
    speed = speed if isinstance(speed, (ca.SX, ca.MX)) else float(speed)  # float() of a symbol would be NaN
    return TrotGains(speed=speed, swing=float(c.swing), double_support=float(c.double_support),
                     height=float(c.height), apex=float(c.apex), touchdown_speed=float(c.touchdown_speed),
                     kv=float(c.kv), raibert=float(c.raibert), kp_swing=float(c.kp_swing),
                     kd_swing=float(c.kd_swing), k_tilt=float(c.k_tilt), d_tilt=float(c.d_tilt))
