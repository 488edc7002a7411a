"""Settings of a cross-check replay, from the project's `crosscheck` block or defaults."""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace


@dataclass(frozen=True)
class CrossCheckSettings:
    """How runs are replayed: MuJoCo steps of `timestep`, the control law evaluated `control_rate`
    times per second and held in between, the feet spheres of `foot_radius` on a floor that far
    below z = 0, contacts of time constant `timeconst` with a `cone` friction cone of coefficient
    `friction` (None: the system's), rotor armature `armature` on every actuated joint (None: the
    model's), motors that deliver `torque_scale` times the commanded torque, a law that sees the state
    `latency` seconds late and the base's velocity off by up to `velocity_noise` (see
    mpgspec.spec.crosscheck)."""

    simulator: str = "mujoco"
    control_rate: float = 1000.0
    timestep: float = 1e-4
    integrator: str = "implicitfast"
    foot_radius: float = 5e-4
    settle: float = 0.2
    timeconst: float = 5e-4
    dampratio: float = 1.0
    impratio: float = 1.0
    noslip_iterations: int = 0
    cone: str = "elliptic"
    friction: float | None = None
    armature: float | None = None
    torque_scale: float = 1.0
    latency: float = 0.0
    velocity_noise: float = 0.0
    runs: tuple[str, ...] = ("naive", "graph")
    require_agreement: bool = False

    @classmethod
    def from_spec(cls, cfg) -> "CrossCheckSettings":
        """From a validated mpgspec.spec.crosscheck.CrossCheck."""
        c = cfg.contact
        return cls(simulator=cfg.simulator, control_rate=float(cfg.control_rate), timestep=float(cfg.timestep),
                   integrator=cfg.integrator, foot_radius=float(cfg.foot_radius), settle=float(cfg.settle),
                   timeconst=float(c.timeconst), dampratio=float(c.dampratio), impratio=float(c.impratio),
                   noslip_iterations=int(c.noslip_iterations), cone=c.cone,
                   friction=None if c.friction is None else float(c.friction),
                   armature=None if cfg.armature is None else float(cfg.armature),
                   torque_scale=float(cfg.torque_scale), latency=float(cfg.latency),
                   velocity_noise=float(cfg.velocity_noise), runs=tuple(cfg.runs),
                   require_agreement=bool(cfg.require_agreement))

    @property
    def delay(self) -> int:
        """Control periods between a state and the update that reads it."""
        return int(round(self.latency * self.control_rate))

    @property
    def sensed(self) -> bool:
        """Whether the law sees another state than the simulator's (latency or velocity noise)."""
        return self.delay > 0 or self.velocity_noise > 0

    @property
    def substeps(self) -> int:
        """Simulator steps per control period."""
        return max(1, round(1.0 / (self.control_rate * self.timestep)))

    def replace(self, **kw) -> "CrossCheckSettings":
        return replace(self, **kw)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["runs"] = list(self.runs)
        return d


def settings_of(spec, force: bool = False) -> CrossCheckSettings | None:
    """The cross-check a project asks for (its `crosscheck` block; with `force`, defaults when it has
    none), or None. Raises a located SpecError when it cannot run: no sequence, not a rigid-body
    system, or MuJoCo not installed."""
    import importlib.util

    from ...errors import SpecError

    cfg = spec.project.crosscheck
    if cfg is None and not force:
        return None
    where = spec.locate(("crosscheck",)) if cfg is not None else spec.locate(())
    key = "crosscheck"
    if spec.project.sequence is None:
        raise SpecError("the cross-check replays the goal sequence's runs, and the project has none", location=where,
                        key=key, expected="a `sequence` block", found="no sequence", code="MPG108")
    if getattr(spec.system, "kind", None) != "rigid_body":
        raise SpecError("the cross-check replays rigid-body robots only", location=where, key=key,
                        expected="system kind rigid_body", found=f"kind {getattr(spec.system, 'kind', '?')}",
                        code="MPG108")
    if importlib.util.find_spec("mujoco") is None:
        raise SpecError("the cross-check needs the mujoco package", location=where, key=key,
                        expected="mujoco installed", found="not installed", code="MPG121",
                        hint='pip install "mpgspec[xcheck]"')
    st = CrossCheckSettings.from_spec(cfg) if cfg is not None else CrossCheckSettings()
    if st.velocity_noise > 0 and not getattr(spec.system, "floating_base", True):
        raise _no_base(spec.locate(("crosscheck", "velocity_noise")), "crosscheck.velocity_noise", st.velocity_noise)
    return st


def _no_base(where, key: str, noise: float):
    from ...errors import SpecError

    return SpecError("velocity noise acts on the floating base's velocity, and the robot's base is fixed",
                     location=where, key=key, expected="velocity_noise 0 (or a floating_base system)",
                     found=f"velocity_noise {noise:g} with floating_base: false", code="MPG108",
                     hint="noise on a fixed-base robot's sensing is not modelled: leave velocity_noise out")


def variants_of(spec, base: CrossCheckSettings) -> list[tuple[str, CrossCheckSettings, dict]]:
    """(name, settings, the settings it replaces) of each of the project's cross-check variants: the
    base settings with what the variant names replaced, for the graph executor's run only. Raises a located
    SpecError for a variant MuJoCo cannot run (a control period that is not a whole number of steps,
    a contact softer than two steps can resolve, nothing replaced)."""
    from ...errors import SpecError
    from ...spec.crosscheck import Variant, whole_periods, whole_steps

    replaceable = [k for k in Variant.model_fields if k not in ("name", "contact")]  # what a variant can name

    cfg = spec.project.crosscheck
    out = []
    for i, v in enumerate(cfg.variants if cfg is not None else []):
        changed = v.model_dump(exclude={"name", "contact"}, exclude_none=True)
        changed |= v.contact.model_dump(exclude_none=True) if v.contact is not None else {}
        where, key = spec.locate(("crosscheck", "variants", i)), f"crosscheck.variants[{i}]"
        if not changed:
            raise SpecError("a cross-check variant replaces none of the cross-check's settings", location=where,
                            key=key, expected=", ".join(replaceable) + " or contact",
                            found="only a name" if v.name else "nothing", code="MPG103")
        st = base.replace(runs=("graph",), **{k: (x if k in ("integrator", "noslip_iterations", "cone")
                                                  else float(x)) for k, x in changed.items()})
        if not whole_steps(st.control_rate, st.timestep):
            raise SpecError("a variant's control period must be a whole number of timesteps", location=where,
                            key=key, expected=f"1/control_rate a multiple of the timestep ({st.timestep:g} s)",
                            found=f"1/control_rate = {1 / st.control_rate:g} s", code="MPG104")
        if not whole_periods(st.latency, st.control_rate):
            raise SpecError("a variant's latency must be a whole number of control periods", location=where, key=key,
                            expected=f"latency a multiple of 1/control_rate ({1 / st.control_rate:g} s)",
                            found=f"latency = {st.latency:g} s", code="MPG104")
        if st.velocity_noise > 0 and not getattr(spec.system, "floating_base", True):
            raise _no_base(where, key, st.velocity_noise)
        if st.timeconst < 2 * st.timestep:
            raise SpecError("a variant's contact is softer than MuJoCo resolves", location=where, key=key,
                            expected=f"contact.timeconst at least twice the timestep ({2 * st.timestep:g} s)",
                            found=f"{st.timeconst:g} s", code="MPG104")
        name = v.name or ", ".join(f"{k} {x:g}" if isinstance(x, float) else f"{k} {x}" for k, x in changed.items())
        out.append((name, st, changed))
    return out
