"""Spec models of the quadruped controller kinds trot, jump and land (no CasADi here: the spec layer
reads them through the entry points `mpgspec.controllers`)."""
from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import Field

from ...spec.base import Strict
from ...spec.system import Expr, Number, Text


Pair = Annotated[list[Text], Field(min_length=2, max_length=2)]


_TRUNK = {
    "k_tilt": dict(default=300.0, ge=0, description="trunk roll/pitch stiffness (1/s^2)"),
    "d_tilt": dict(default=30.0, ge=0, description="trunk roll/pitch damping (1/s)"),
    "d_yaw": dict(default=10.0, ge=0, description="yaw-rate damping (1/s)"),
    "moment_weight": dict(default=10.0, gt=0, description="weight of the moment against the force in the stance "
                          "feet's wrench split"),
    "regularization": dict(default=1e-4, gt=0, description="force regularization of the wrench split (the "
                           "least-squares weight on ||f||^2)"),
}
"""The trunk-wrench fields the trot, the jump and the landing share (levelling the trunk, splitting the wrench)."""


def _trunk(name: str):
    """A fresh Field of the shared trunk-wrench field `name`."""
    return Field(**_TRUNK[name])


# The docstrings are the schema's descriptions (`mpgspec schema`), kept as published.
class TrotController(Strict):
    """A trot for point-foot quadrupeds (compile/rigidbody/trot.py): stance feet share the trunk wrench,
    swing feet land at the Raibert point; the contact schedule follows from the timing."""

    type: Literal["trot"]
    schedules_contacts: ClassVar[bool] = True  # the clock sets the contact mode (the trot's timing)
    speed: Expr = Field(description="commanded mean forward speed (m/s), usually the primitive's argument")
    gait: Text | None = Field(default=None, description="gait table written by `mpgspec gait` (its header "
                                                        "holds the calibrated command); `{<argument>}` is replaced")
    pose: dict[Text, Number] = Field(default_factory=dict, description="joint angles of the nominal stance (others 0): "
                                                                      "its CoM offsets and inertia shape the law")
    swing: Number = Field(default=0.16, gt=0, description="swing time T_sw (s)")
    double_support: Number = Field(default=0.02, gt=0, description="time with all four feet down T_ds (s)")
    pairs: Annotated[list[Pair], Field(min_length=2, max_length=2)] | None = Field(
        default=None, description="the two diagonal pairs by leg name (system.legs), e.g. [[LF, RH], [RF, LH]]: "
        "the first pair stands while the second swings first. Default [[FL, RR], [FR, RL]] when the robot "
        "has legs of those names (the A1), else required")
    height: Number | None = Field(default=None, gt=0, description="CoM height h_d (m); default: the CoM height "
                                  "of the nominal stance (pose) with the feet on the ground")
    apex: Number = Field(default=0.07, gt=0, description="swing foot apex (m)")
    touchdown_speed: Number = Field(default=0.3, ge=0, description="downward foot speed at touchdown (m/s)")
    touchdown_height: Number = Field(default=0.0, ge=0, le=0.003, description="swing foot height asked at the "
                                     "scheduled touchdown (m): a foot that tracks its descent a little early "
                                     "still arrives above the ground (`aerial` allows no swing foot below it)")
    kv: Number = Field(default=10.0, ge=0, description="CoM velocity gain (1/s)")
    raibert: Number = Field(default=0.08, ge=0, description="foot placement gain on the velocity error (s)")
    kp_swing: Number = Field(default=12000.0, gt=0, description="swing foot stiffness (N/m)")
    kd_swing: Number = Field(default=200.0, ge=0, description="swing foot damping (N s/m)")
    k_tilt: Number = _trunk("k_tilt")
    d_tilt: Number = _trunk("d_tilt")
    d_yaw: Number = _trunk("d_yaw")
    kz: Number = Field(default=100.0, ge=0, description="CoM height stiffness (1/s^2)")
    dz: Number = Field(default=20.0, ge=0, description="CoM height damping (1/s)")
    f_min: Number | None = Field(default=None, ge=0, description="least normal force asked of a stance foot (N); "
                                 "default: f_min_fraction of the robot's weight")
    f_min_fraction: Number = Field(default=0.075, ge=0, lt=0.25, description="f_min as a fraction of the robot's "
                                   "weight when f_min is not given (0.075: about 10 N on a 13.7 kg robot, 30 % of "
                                   "a foot's share in four-foot support)")
    cone_fraction: Number = Field(default=0.9, gt=0, le=1, description="share of the friction cone mu f_z a "
                                  "stance foot's tangential force may use")
    friction: Number | None = Field(default=None, gt=0, description="friction coefficient mu the stance forces are "
                                    "designed for: below the lowest the ground may have (the uncertainty range), "
                                    "so the feet keep a margin there; default: the system's friction")
    placement_fraction: Number = Field(default=0.8, gt=0, le=1, description="share of the swing after which the "
                                       "foot is over its Raibert target")
    moment_weight: Number = _trunk("moment_weight")
    regularization: Number = _trunk("regularization")
    accel_limit: Number | None = Field(default=None, gt=0, description="largest horizontal CoM acceleration "
                                       "(m/s^2) the stance wrench asks: the velocity error saturates at "
                                       "accel_limit / kv, so a step in the speed command (a switch between walks) "
                                       "is a ramp; default: no limit")
    height_accel_limit: Number | None = Field(default=None, gt=0, description="largest vertical CoM acceleration "
                                              "(m/s^2) the height stiffness asks: the height error saturates at "
                                              "height_accel_limit / kz, so a stiff height law (which holds the "
                                              "height under a mass or torque error) rises from a lower stance "
                                              "(a switch in from a crouch) at a bounded force; default: no limit")
    tilt_accel_limit: Number | None = Field(default=None, gt=0, description="largest roll and pitch acceleration "
                                            "(rad/s^2) the trunk's tilt PD asks (its norm, direction kept): stiff "
                                            "tilt gains hold the orbit under a model error while the large tilt "
                                            "error after a switch asks the feet a bounded moment; default: no limit")
    lift_fraction: Number = Field(default=0.0, ge=0, lt=1, description="share of the swing over which the swing "
                                  "foot's horizontal pull ramps in from 0: the foot lifts before it moves over; "
                                  "0: the path's pull from lift-off")
    swing_feedforward: bool = Field(default=False, description="add the swing path's acceleration through the "
                                    "leg's inertia (tau += M_leg J_leg^-1 a_d): the foot follows its path with "
                                    "low swing gains, which a law that reads its state late or noisy needs")


class JumpController(Strict):
    """The paper's Jump for point-foot quadrupeds (compile/rigidbody/jump.py): a cubic CoM profile to
    the takeoff velocity tracked through the stance feet until T_t, then the legs tucked."""

    type: Literal["jump"]
    reads_setpoint: ClassVar[bool] = False  # x*(t) may be the loop's own flow (`mpgspec gait`)
    takeoff_time: Number = Field(default=0.15, gt=0, description="T_t: end of the push (s on the clock)")
    takeoff_velocity: Number = Field(default=1.0, gt=0, description="upward CoM speed at T_t (m/s)")
    rise: Number = Field(default=0.06, gt=0, description="CoM rise over the push (m)")
    pose: dict[Text, Number] = Field(default_factory=dict, description="joint angles of the stance the push "
                                     "starts from (others 0): its CoM height is h_0")
    tuck: dict[Text, Number] = Field(default_factory=dict, description="joint angles the legs fold to after T_t")
    kz: Number = Field(default=400.0, ge=0, description="CoM height stiffness (1/s^2)")
    dz: Number = Field(default=40.0, ge=0, description="CoM height damping (1/s)")
    kv: Number = Field(default=10.0, ge=0, description="horizontal CoM velocity gain (1/s)")
    k_tilt: Number = _trunk("k_tilt")
    d_tilt: Number = _trunk("d_tilt")
    d_yaw: Number = _trunk("d_yaw")
    kp_joint: Number = Field(default=60.0, ge=0, description="joint stiffness of the tuck (N m/rad)")
    kd_joint: Number = Field(default=2.0, ge=0, description="joint damping of the tuck (N m s/rad)")
    moment_weight: Number = _trunk("moment_weight")
    regularization: Number = _trunk("regularization")


class TouchdownGains(Strict):
    """The landing's gains at the first touchdown (each omitted: the landing's own)."""

    kz: Number | None = Field(default=None, ge=0, description="CoM height stiffness (1/s^2)")
    dz: Number | None = Field(default=None, ge=0, description="CoM height damping (1/s)")
    kp_xy: Number | None = Field(default=None, ge=0, description="horizontal CoM stiffness (1/s^2)")


class LandController(Strict):
    """A landing for point-foot quadrupeds (robots/quadruped/land.py): in the air the legs hold a crouch by
    joint PD; the feet in contact share the trunk wrench that holds the CoM at the crouch's height and over
    the feet, levels the trunk and damps its motion (as the jump's push, at rest)."""

    type: Literal["land"]
    reads_setpoint: ClassVar[bool] = False  # x*(t) may be the loop's own flow (`mpgspec gait`)
    pose: dict[Text, Number] = Field(default_factory=dict, description="joint angles of the crouch the legs "
                                     "hold in the air (others 0): its CoM height with the feet on the ground "
                                     "is the height held after touchdown")
    height: Number | None = Field(default=None, gt=0, description="CoM height held on the ground (m); default: "
                                  "the crouch's")
    kz: Number = Field(default=400.0, ge=0, description="CoM height stiffness (1/s^2)")
    dz: Number = Field(default=20.0, ge=0, description="CoM height damping (1/s)")
    touchdown: TouchdownGains | None = Field(default=None, description="the gains at the first touchdown, ramped "
                                             "to kz, dz, kp_xy (linearly over `stiffen` seconds from `stiffen_after` "
                                             "on the touchdown's event clock): soft while the landing is absorbed (a "
                                             "stiff law bounces the feet off), stiff at rest (so a mass or torque "
                                             "error moves the rest little); default: the same gains throughout")
    stiffen_after: Number = Field(default=0.0, ge=0, description="seconds after the first touchdown before the "
                                  "gains start to ramp")
    stiffen: Number = Field(default=0.3, gt=0, description="seconds over which the gains ramp")
    kp_xy: Number = Field(default=20.0, ge=0, description="horizontal CoM stiffness (1/s^2) towards its place over "
                          "the feet in the crouch")
    kv: Number = Field(default=10.0, ge=0, description="horizontal CoM velocity gain (1/s)")
    k_tilt: Number = _trunk("k_tilt")
    d_tilt: Number = _trunk("d_tilt")
    d_yaw: Number = _trunk("d_yaw")
    k_yaw: Number = Field(default=100.0, ge=0, description="yaw stiffness (1/s^2) towards the heading of the feet on "
                          "the ground")
    kp_joint: Number = Field(default=20.0, ge=0, description="joint stiffness of a leg in the air (N m/rad)")
    kd_joint: Number = Field(default=3.0, ge=0, description="joint damping of a leg in the air (N m s/rad)")
    torque_limit: Number | None = Field(default=None, gt=0, description="largest joint torque (N m) the law asks of "
                                        "a leg in contact: the trunk's vertical force is scaled towards 0 where "
                                        "it would ask more (the landing speed is then taken out at bounded torques, not "
                                        "at a damping peak at the touchdown; the rest of the wrench is not scaled); "
                                        "default: no limit")
    moment_weight: Number = _trunk("moment_weight")
    regularization: Number = _trunk("regularization")
