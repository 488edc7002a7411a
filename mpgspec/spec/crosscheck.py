"""Spec model of the cross-check: the goal sequence's runs replayed in an independent simulator."""
from __future__ import annotations

from typing import Literal

from pydantic import Field, ValidationInfo, field_validator

from .base import Strict
from .system import Number


def whole_periods(latency: float, rate: float) -> bool:
    """Whether a latency is a whole number (0 or more) of control periods 1/rate."""
    n = latency * rate
    return abs(n - round(n)) <= 1e-6 * max(1.0, n)


def whole_steps(rate: float, timestep: float) -> bool:
    """Whether a control period 1/rate is a whole number (at least 1) of simulator steps."""
    n = 1.0 / (rate * timestep)
    return n >= 1 - 1e-9 and abs(n - round(n)) <= 1e-6 * max(1.0, n)


class ContactModel(Strict):
    """MuJoCo's soft contact between the feet and the floor (solref, friction cone, friction)."""

    timeconst: Number = Field(default=5e-4, gt=0, description="time constant of the contact's spring-damper "
                              "(MuJoCo solref[0]), seconds; at least twice the timestep")
    dampratio: Number = Field(default=1.0, gt=0, description="damping ratio of the contact (MuJoCo solref[1])")
    impratio: Number = Field(default=1.0, ge=1, description="ratio of frictional to normal impedance (elliptic "
                             "cones); above 1 the friction is stiffer")
    noslip_iterations: int = Field(default=0, ge=0, le=100, description="iterations of MuJoCo's NoSlip "
                                   "post-processing (0: off)")
    cone: Literal["elliptic", "pyramidal"] = Field(default="elliptic", description="MuJoCo's friction cone: "
                                                   "elliptic (the exact Coulomb cone) or pyramidal (its "
                                                   "linearisation)")
    friction: Number | None = Field(default=None, gt=0, le=5, description="the floor's friction coefficient "
                                    "(default: the system's friction, the one mpgspec's safe set assumes)")


class VariantContact(Strict):
    """A variant's contact parameters: each given one replaces the cross-check's."""

    timeconst: Number | None = Field(default=None, gt=0, description="as contact.timeconst")
    dampratio: Number | None = Field(default=None, gt=0, description="as contact.dampratio")
    impratio: Number | None = Field(default=None, ge=1, description="as contact.impratio")
    noslip_iterations: int | None = Field(default=None, ge=0, le=100, description="as contact.noslip_iterations")
    cone: Literal["elliptic", "pyramidal"] | None = Field(default=None, description="as contact.cone")
    friction: Number | None = Field(default=None, gt=0, le=5, description="as contact.friction")


class Variant(Strict):
    """The graph executor run once more on the simulator's state with some of the cross-check's settings
    replaced: another contact model, control rate, integrator, model or sensing error. What a variant does
    not name is as the cross-check's."""

    name: str | None = Field(default=None, min_length=1, max_length=80, description="how the report names it "
                             "(default: the settings it replaces)")
    control_rate: Number | None = Field(default=None, gt=0, description="as control_rate")
    timestep: Number | None = Field(default=None, gt=0, description="as timestep")
    integrator: Literal["euler", "implicitfast", "rk4"] | None = Field(default=None, description="as integrator")
    foot_radius: Number | None = Field(default=None, gt=0, description="as foot_radius")
    armature: Number | None = Field(default=None, ge=0, le=10, description="as armature")
    torque_scale: Number | None = Field(default=None, gt=0, le=2, description="as torque_scale")
    latency: Number | None = Field(default=None, ge=0, le=0.1, description="as latency")
    velocity_noise: Number | None = Field(default=None, ge=0, le=10, description="as velocity_noise")
    contact: VariantContact | None = Field(default=None, description="contact parameters it replaces")


class CrossCheck(Strict):
    """Replay the sequence's runs (their switches and switch clocks) in an independent simulator with the
    same compiled control laws, and compare its safety verdict and trajectory with mpgspec's."""

    simulator: Literal["mujoco"] = Field(default="mujoco", description="the simulator (needs the xcheck extra)")
    control_rate: Number = Field(default=1000.0, gt=0, description="control updates per second (Hz); the input "
                                 "is held between updates")
    timestep: Number = Field(default=1e-4, gt=0, description="the simulator's integration step, seconds; "
                             "1/control_rate must be a whole number of steps")
    integrator: Literal["euler", "implicitfast", "rk4"] = Field(default="implicitfast",
                                                                description="MuJoCo's integrator")
    foot_radius: Number = Field(default=5e-4, gt=0, description="radius of the sphere at each contact frame, "
                                "metres; the floor lies this far below z = 0, so a foot at z = 0 touches it")
    settle: Number = Field(default=0.2, ge=0, le=10, description="seconds the start primitive's law holds the "
                           "start state (clock frozen) before t = 0, so the soft contacts carry the weight")
    contact: ContactModel = Field(default_factory=ContactModel, description="contact parameters")
    armature: Number | None = Field(default=None, ge=0, le=10, description="rotor armature (the motors' "
                                    "reflected inertia) of every actuated joint in the simulator, kg m^2; "
                                    "default: the model's, as in mpgspec's dynamics (the URDF's, usually none)")
    torque_scale: Number = Field(default=1.0, gt=0, le=2, description="the motors deliver this multiple of the "
                                 "commanded torque, within the torque limit (an actuation error: 0.9 and 1.1 "
                                 "for +-10 %)")
    latency: Number = Field(default=0.0, ge=0, le=0.1, description="seconds between a state and the control "
                            "update that reads it (a whole number of control periods): the law sees the "
                            "state this old")
    velocity_noise: Number = Field(default=0.0, ge=0, le=10, description="the base's linear velocity as the law "
                                   "sees it is off by up to this much (m/s) in each axis, uniformly at random at "
                                   "every control update (a seeded draw: a replay is repeatable)")
    runs: list[Literal["naive", "graph"]] = Field(default=["naive", "graph"], min_length=1,
                                                  description="which sequence runs to replay")
    require_agreement: bool = Field(default=False, description="fail the project when the simulator's safety "
                                    "verdict of a replayed run differs from mpgspec's, or a variant's executor "
                                    "run is unsafe or misses a goal")
    variants: list[Variant] = Field(default_factory=list, max_length=16, description="the graph executor run "
                                    "again on the simulator's state under other contact models, control rates, "
                                    "integrators, model and sensing errors: does the verified plan transfer "
                                    "beyond one simulator setting?")

    @field_validator("timestep")
    @classmethod
    def _whole_steps(cls, v, info: ValidationInfo):
        rate = info.data.get("control_rate")
        if rate is not None and not whole_steps(rate, v):
            raise ValueError(f"1/control_rate ({1 / rate:g} s) must be a whole number of timesteps ({v:g} s)")
        return v

    @field_validator("latency")
    @classmethod
    def _whole_periods(cls, v, info: ValidationInfo):
        rate = info.data.get("control_rate")
        if rate is not None and not whole_periods(v, rate):
            raise ValueError(f"latency ({v:g} s) must be a whole number of control periods ({1 / rate:g} s)")
        return v

    @field_validator("variants")
    @classmethod
    def _distinct_names(cls, v):
        names = [x.name for x in v if x.name is not None]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"variant names must differ; {', '.join(twice)} names more than one")
        return v

    @field_validator("contact")
    @classmethod
    def _stiff_enough(cls, v, info: ValidationInfo):
        dt = info.data.get("timestep")
        if dt is not None and v.timeconst < 2 * dt:
            raise ValueError(f"contact.timeconst ({v.timeconst:g} s) must be at least twice the timestep ({dt:g} s); "
                             "MuJoCo would raise it silently")
        return v
