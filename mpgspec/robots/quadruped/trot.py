"""A trot for point-foot quadrupeds: stance wrench split, Raibert swing placement, clock-driven phases.

The gait runs on the primitive's clock t within one period T = 2 (T_sw + T_ds): both diagonal
pairs stand for T_ds, then pair B (the second of `pairs`; the A1's FR, RL) swings for T_sw while
pair A (the first; FL, RR) stands, then both stand for T_ds, then pair A swings. The law receives the contact mode (which feet the plant holds,
as symbols of the clock) and uses the Jacobians of exactly those feet.

- Stance feet share the trunk wrench that drives the CoM velocity to the command, the CoM height
  to h_d and the trunk level (roll and pitch), with the yaw rate damped; x, y and yaw are not
  tracked, so the orbit can be moved and turned on flat ground (three neutral Floquet directions).
  Forces f = argmin ||A f - w||_S^2 + reg ||f||^2 in closed form, then f_z >= f_min and
  |f_xy| <= cone_fraction mu f_z per foot (mu: the controller's design `friction`, which may sit below
  the range the ground may have, else the system's); leg torques tau = h_leg - J_leg^T f.
- Swing feet follow a Cartesian PD (tau = h_leg + J_leg^T (Kp (p_d - p) + Kd (v_d - v))) on a
  path from the lift-off point to the Raibert target c + cdot (T_sw - tau) + cdot T_st / 2 +
  k_v (cdot - v_cmd) (a smoothstep done at placement_fraction of the swing) and a height profile up to the apex
  and down to touchdown_height at the scheduled touchdown with a set downward speed (a foot that
  arrives early stays above the ground: no swing foot may be below it). With lift_fraction, the
  horizontal pull ramps in over that share of the swing (the target starts at the foot itself): the foot
  lifts before it moves over, so a leg whose torque saturates does not drag a lifting foot along or into
  the ground. With swing_feedforward, the path's acceleration (its targets held) goes through the leg's
  inertia (tau += M_leg J_leg^-1 a_d): the foot follows its path on low gains, and low gains are what
  a law reading its state late or noisy tolerates (the A1's at 12000 N/m oscillate at about 190 Hz under
  2 ms of latency).
- With accel_limit, the CoM velocity error the stance wrench acts on saturates at accel_limit / k_v
  (direction kept): a step in the speed command (a switch between walks) becomes a ramp, and the
  horizontal force the feet must carry stays bounded.

Step-to-step correction comes from where the next pair lands: with two point feet on a diagonal,
no torque changes the angular momentum about the line through them, so a clock-driven joint PD
alone has no stable trot.

Each leg's torques go to its own joints, read off the kinematic tree (compile/rigidbody/legs.py).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...compile.contacts import Schedule, wrap_clock
from ...compile.laws.base import cubic_profile
from ...errors import SpecError
from .stance import level_trunk_moment, limited, nominal_geometry, nominal_state, split_wrench, trunk


@dataclass(frozen=True)
class TrotGains:
    """Gait timing, targets and gains (SI units)."""

    speed: float = 0.0  # commanded forward speed in the heading frame (a number, or a symbol)
    swing: float = 0.16  # T_sw
    double_support: float = 0.02  # T_ds
    height: float = float("nan")  # CoM height h_d (gains_of: the spec's, else the stance's)
    apex: float = 0.07  # swing foot apex
    touchdown_speed: float = 0.3  # downward foot speed at the scheduled touchdown
    touchdown_height: float = 0.0  # swing foot height asked at the scheduled touchdown
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
    cone_fraction: float = 0.9  # share of the friction cone a stance force may use
    placement_fraction: float = 0.8  # share of the swing after which the foot is over its target
    accel_limit: float = float("inf")  # largest horizontal CoM acceleration the stance wrench asks (m/s^2)
    height_accel_limit: float = float("inf")  # largest vertical CoM acceleration the height stiffness asks (m/s^2)
    tilt_accel_limit: float = float("inf")  # largest roll/pitch acceleration the tilt PD asks (rad/s^2)
    lift_fraction: float = 0.0  # share of the swing over which the swing foot's horizontal pull ramps in
    swing_feedforward: bool = False  # the path's acceleration through the leg's inertia
    friction: float = float("nan")  # friction coefficient the stance forces are designed for (nan: the system's)
    pair_a: tuple[str, ...] = ()  # feet that stand during the first swing
    pair_b: tuple[str, ...] = ()  # feet that swing first

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
        return Schedule(((ds, feet), (h, self.pair_a), (h + ds, feet), (2 * h, self.pair_b)), self.period, feet)


def _smoothstep(sig):
    s = ca.fmin(ca.fmax(sig, 0), 1)
    return 3 * s**2 - 2 * s**3, ca.if_else(ca.logic_and(sig > 0, sig < 1), 6 * s * (1 - s), 0)


def _smootherstep(sig):
    """(s, ds/dsig, d2s/dsig2) of the quintic 10 sig^3 - 15 sig^4 + 6 sig^5 on [0, 1], held outside: its
    rate and acceleration are 0 at both ends."""
    s = ca.fmin(ca.fmax(sig, 0), 1)
    inside = ca.logic_and(sig > 0, sig < 1)
    return (10 * s**3 - 15 * s**4 + 6 * s**5, ca.if_else(inside, 30 * s**2 * (1 - s) ** 2, 0),
            ca.if_else(inside, 60 * s * (1 - s) * (1 - 2 * s), 0))


def quintic_profile(s, duration: float, p0: float, v0: float, pf: float, vf: float):
    """(position, velocity, acceleration) of the quintic from (p0, v0) at s = 0 to (pf, vf) at s = duration
    with zero acceleration at both ends; held (at pf, vf, 0) outside [0, duration]."""
    th = duration
    dp = pf - p0 - v0 * th
    dv = vf - v0
    c3 = (10 * dp - 4 * dv * th) / th**3
    c4 = (-15 * dp + 7 * dv * th) / th**4
    c5 = (6 * dp - 3 * dv * th) / th**5
    sc = ca.fmin(ca.fmax(s, 0), th)
    pos = p0 + v0 * sc + c3 * sc**3 + c4 * sc**4 + c5 * sc**5
    vel = v0 + 3 * c3 * sc**2 + 4 * c4 * sc**3 + 5 * c5 * sc**4
    acc = 6 * c3 * sc + 12 * c4 * sc**2 + 20 * c5 * sc**3
    after = s > th
    return ca.if_else(after, pf, pos), ca.if_else(after, vf, vel), ca.if_else(after, 0, acc)


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
    force = tk.mass * ca.vertcat(g.kv * limited(v_cmd - cdot[:2], g.accel_limit / g.kv),
                                 tk.grav + g.kz * limited(g.height - com[2], g.height_accel_limit / max(g.kz, 1e-12))
                                 - g.dz * cdot[2])
    wrench = ca.vertcat(force, level_trunk_moment(tk, inertia, g.k_tilt, g.d_tilt, g.d_yaw, g.tilt_accel_limit))
    f_all = split_wrench(tk, flags, feet, wrench, g.moment_weight, g.regularization)
    dyn = sys.dyn
    mu = float(sys.friction) if np.isnan(g.friction) else g.friction
    half, period = g.half, g.period
    tc = wrap_clock(t, period)
    tau_swing = {g.pair_b: tc - g.double_support, g.pair_a: tc - half - g.double_support}
    if g.swing_feedforward:  # minimum-jerk pieces: the path's acceleration is continuous, 0 at both ends and the apex
        z_up = lambda s: quintic_profile(s, g.swing / 2, 0.0, 0.0, g.apex, 0.0)  # noqa: E731
        z_dn = lambda s: quintic_profile(s, g.swing / 2, g.apex, 0.0, g.touchdown_height, -g.touchdown_speed)  # noqa: E731
        step = _smootherstep
    else:
        z_up = lambda s: cubic_profile(s, g.swing / 2, ca.DM(0), ca.DM(0), ca.DM(g.apex), ca.DM(0))  # noqa: E731
        z_dn = lambda s: cubic_profile(s, g.swing / 2, ca.DM(g.apex), ca.DM(0), ca.DM(g.touchdown_height),
                                        ca.DM(-g.touchdown_speed))  # noqa: E731
        step = _smoothstep
    M = sub(dyn.M_expr) if g.swing_feedforward else None
    legs = {leg.foot: leg for leg in sys.legs}
    u = [None] * m.nu
    for i, f in enumerate(feet):
        leg = legs[f]
        J = sub(dyn.contact_jacobian_expr([f]))[:, list(leg.v)]
        h_leg = H[list(leg.v)]
        # stance
        fi = f_all[3 * i:3 * i + 3]
        fz = ca.fmax(fi[2], g.f_min)
        fxy = fi[:2]
        cap = g.cone_fraction * mu * fz
        scale = ca.fmin(1, cap / ca.sqrt(ca.sumsqr(fxy) + 1e-12))
        f_st = ca.vertcat(scale * fxy, fz)
        tau_st = h_leg - ca.mtimes(J.T, f_st)
        # swing
        tau = tau_swing[g.pair_a if f in g.pair_a else g.pair_b]
        tau = ca.fmin(ca.fmax(tau, 0), g.swing)
        d = ca.mtimes(Ryaw[:2, :2], ca.DM(offsets[f]))
        p_lo = com[:2] + d - cdot[:2] * (g.stance / 2 + tau)
        p_td = com[:2] + d + cdot[:2] * (g.swing - tau + g.stance / 2) + g.raibert * (cdot[:2] - v_cmd)
        path = step(tau / (g.placement_fraction * g.swing))  # (s, ds, d2s) of the horizontal path
        s, ds = path[0], path[1]
        p_xy = p_lo + s * (p_td - p_lo)
        v_xy = ds / (g.placement_fraction * g.swing) * (p_td - p_lo)
        if g.lift_fraction > 0:  # lift first: the horizontal pull towards the path ramps in from 0
            w, _dw = _smoothstep(tau / (g.lift_fraction * g.swing))
            p_xy, v_xy = pos[f][:2] + w * (p_xy - pos[f][:2]), w * v_xy
        rise, fall = z_up(tau), z_dn(tau - g.swing / 2)
        zu, vu, zd, vd = rise[0], rise[1], fall[0], fall[1]
        up = tau < g.swing / 2
        p_d = ca.vertcat(p_xy, ca.if_else(up, zu, zd))
        v_d = ca.vertcat(v_xy, ca.if_else(up, vu, vd))
        tau_sw = h_leg + ca.mtimes(J.T, g.kp_swing * (p_d - pos[f]) + g.kd_swing * (v_d - vel[f]))
        if M is not None:  # the path's acceleration (its targets held) through the leg's own inertia
            a_xy = path[2] / (g.placement_fraction * g.swing) ** 2 * (p_td - p_lo)
            if g.lift_fraction > 0:
                a_xy = w * a_xy
            a_z = ca.if_else(up, rise[2], fall[2])
            tau_sw = tau_sw + ca.mtimes(M[list(leg.v), list(leg.v)], ca.solve(J, ca.vertcat(a_xy, a_z)))
        c = flags[f]
        if M is None:
            tau_leg = c * tau_st + (1 - c) * tau_sw
        else:  # a held leg's torque never reads the swing branch (whose J^-1 is not finite where the leg is straight)
            tau_leg = ca.if_else(c > 0.5, tau_st, tau_sw)
        for k, j in enumerate(leg.u):
            u[j] = tau_leg[k]
    return ca.vertcat(*u)


def trot_law(c, ctx) -> ca.SX:
    """The trot's u(x, t) for a compiled primitive (the command and gains come from trot_setup)."""
    check_pose(c, ctx.sys, ctx.ec)
    info = ctx.info["trot"]
    g = gains_of(c, info["command"], ctx.sys, ctx.ec)
    inertia, offsets = nominal_geometry(ctx.sys, dict(c.pose))
    info["period"] = g.period
    return trot_torque(ctx.sys, g, ctx.t, ctx.plan.mode(ctx.sys.model.contact_frames, ctx.t), inertia, offsets)


def check_pose(c, sys, ec) -> None:
    """A located SpecError (MPG106) for a joint of the trot's pose that the system does not have."""
    joints = list(sys.model.joint_names)
    unknown = [j for j in c.pose if j not in sys.state_names]
    if unknown:
        raise SpecError("unknown joint in the trot's pose", location=ec.locate(("controller", "pose", unknown[0])),
                        key=f"{ec.owner}: controller.pose", expected=f"joint names of the system: {joints}"[:400],
                        found=repr(unknown[0][:60]), code="MPG106")


def stance_height(sys, pose: dict) -> float:
    """The CoM height of the nominal stance (`pose`, feet on the ground): the trot's default h_d."""
    x0 = nominal_state(sys, pose)
    return float(ca.Function("com_z", [sys.x], [sys.extra_env["com_z"]])(x0))


def min_normal_force(c, sys) -> float:
    """f_min as given, else f_min_fraction of the robot's weight."""
    if c.f_min is not None:
        return float(c.f_min)
    return float(c.f_min_fraction) * float(sys.model.total_mass) * float(-sys.model.gravity[2])


def gains_of(c, speed: float, sys, ec=None) -> TrotGains:
    """The trot's gains from its spec, with the defaults the robot sets (h_d, f_min, the pairs)."""
    from .pairs import trot_pairs

    speed = speed if isinstance(speed, (ca.SX, ca.MX)) else float(speed)  # float() of a symbol would be NaN
    pair_a, pair_b = trot_pairs(c, sys, ec)
    height = stance_height(sys, dict(c.pose)) if c.height is None else float(c.height)
    return TrotGains(speed=speed, swing=float(c.swing), double_support=float(c.double_support),
                     height=height, apex=float(c.apex), touchdown_speed=float(c.touchdown_speed),
                     touchdown_height=float(c.touchdown_height),
                     kv=float(c.kv), raibert=float(c.raibert), kp_swing=float(c.kp_swing),
                     kd_swing=float(c.kd_swing), k_tilt=float(c.k_tilt), d_tilt=float(c.d_tilt),
                     kz=float(c.kz), dz=float(c.dz), d_yaw=float(c.d_yaw), f_min=min_normal_force(c, sys),
                     regularization=float(c.regularization), moment_weight=float(c.moment_weight),
                     cone_fraction=float(c.cone_fraction), placement_fraction=float(c.placement_fraction),
                     accel_limit=float("inf") if c.accel_limit is None else float(c.accel_limit),
                     height_accel_limit=float("inf") if c.height_accel_limit is None else float(c.height_accel_limit),
                     tilt_accel_limit=float("inf") if c.tilt_accel_limit is None else float(c.tilt_accel_limit),
                     lift_fraction=float(c.lift_fraction), swing_feedforward=bool(c.swing_feedforward),
                     friction=float("nan") if c.friction is None else float(c.friction),
                     pair_a=pair_a, pair_b=pair_b)
