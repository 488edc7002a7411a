"""A rigid-body spec compiled to the CompiledSystem interface, with one open loop per contact set.

Expressions of a rigid-body primitive may name, besides the states: for every contact frame F,
F_x, F_y, F_z (world position), F_vx, F_vy, F_vz (velocity J v) and, for feet in the primitive's
contact set, F_fx, F_fy, F_fz (ground force lambda on the foot, world axes, F_fz > 0 pushing
up); com_x, com_y, com_z; and `mass`.
"""
from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import casadi as ca
import numpy as np

from ...errors import SpecError
from ...spec.models import ContactEvent
from ..contacts import ContactPlan, Fixed
from ..events import NEVER, clock_name, clock_rate
from ..system import CompiledSystem, OpenLoop
from .constrained import Baumgarte, ContactDynamics
from .dynamics import RigidBodyDynamics
from .frames import center_of_mass
from .legs import Leg, resolve_legs
from .linalg import dense_ldl_solve
from .liegroup import normalize_quaternion, qdot, quat_to_rotation
from .model import RigidBodyModel, find_urdf
from .projection import ContactProjection

BASE_Q = ["base_x", "base_y", "base_z", "base_qx", "base_qy", "base_qz", "base_qw"]
BASE_V = ["base_vx", "base_vy", "base_vz", "base_wx", "base_wy", "base_wz"]


RIDGE = 1e-9
"""Ridge of static_torque's normal equations where the feet in contact hold the base (three or more)."""
FEW_FEET_RIDGE = 1e-6
"""Ridge of static_torque's normal equations with one or two feet in contact: the base's rows are
then rank-deficient (two point contacts cannot resist a turn about the line through them), so the
matrix is singular and a ridge of 1e-9 divides its rounding by 1e-9: the torque came out with
about 4e-5 N m of noise (A1, two feet), enough for an input-saturation guard sitting at its bound
to change sign under a state change of 1e-16 (a guard that chatters, never resolved). With 1e-6
the noise is about 3e-8 N m and the torque moves by about 7e-5 N m."""


@dataclass
class RigidBodyCompiledSystem(CompiledSystem):
    """CompiledSystem of a floating-base robot; xdot depends on the primitive's contact set."""

    dyn: RigidBodyDynamics | None = None
    friction: float = 0.7
    baumgarte: Baumgarte | None = None
    events: bool = False  # contact flags in the state, touchdown / lift-off / impact (hybrid.py)
    legs: tuple[Leg, ...] = ()  # named feet and their joints from the tree (legs.py)
    _loops: dict = field(default_factory=dict)

    kind = "rigid_body"

    @property
    def model(self) -> RigidBodyModel:
        return self.dyn.model

    def default_state(self, contacts: tuple[str, ...] | None = None) -> np.ndarray:
        """Zero, with a unit quaternion and (with contact events) the flags of `contacts` set and the
        event clocks at NEVER."""
        x = np.zeros(self.nx)
        x[self.state_names.index("base_qw")] = 1.0
        if self.events:
            on = self.model.contact_frames if contacts is None else contacts
            for f in on:
                x[self.state_names.index(f"contact_{f}")] = 1.0
            x[self.event_clocks] = NEVER
        return x

    @property
    def event_clocks(self) -> list[int]:
        """State indices of the event clocks (compile/events.py), after the contact flags."""
        n = self.model.nq + self.model.nv + len(self.model.contact_frames)
        return list(range(n, self.nx)) if self.events else []

    def open_loop(self, contacts: list[str] | None) -> OpenLoop:
        """Constrained dynamics for `contacts` (None: all contact frames), with lambda in env."""
        key = tuple(self.model.contact_frames if contacts is None else contacts)
        if key in self._loops:
            return self._loops[key]
        if self.events:
            loop = self._hybrid_loop(key)
            self._loops[key] = loop
            return loop
        cd = ContactDynamics(self.dyn, key, self.baumgarte)
        a, lam = cd.solution
        sub_in = [self.dyn.q, self.dyn.v, cd.u]
        nq = self.model.nq
        xq, xv = self.x[:nq], self.x[nq:]
        a, lam = ca.substitute([a, lam], sub_in, [xq, xv, self.u])
        xdot = ca.vertcat(qdot(self.model, xq, xv), a)
        env = dict(self.extra_env)
        for k, f in enumerate(key):
            for j, ax in enumerate("xyz"):
                env[f"{f}_f{ax}"] = lam[3 * k + j]
        loop = OpenLoop(xdot, env)
        self._loops[key] = loop
        return loop

    def _hybrid_loop(self, key: tuple[str, ...]) -> OpenLoop:
        """The contact set follows the flags in the state; `key` only names the initial set."""
        m = self.model
        flags = self.x[m.nq + m.nv:]
        return self.scheduled_loop({f: flags[i] for i, f in enumerate(m.contact_frames)})

    def contact_flag(self, frame: str) -> ca.SX | None:
        return self.x[self.state_names.index(f"contact_{frame}")] if self.events else None

    def static_torque(self, contacts: tuple[str, ...]) -> ca.SX:
        """Joint torques that hold the current pose against gravity with the feet in `contacts`.

        The least-norm solution of H(q, 0) = B u + J^T lam, weighting tangential contact forces
        100x and normal forces 0.01x against torques, so the ground carries the weight through
        near-vertical forces: an equality-constrained inverse-dynamics QP solved in closed form.
        With contact events only the feet of `contacts` whose flag is set carry weight, and with
        none on the ground the torque is 0 (in free fall no torque holds a pose).
        """
        m, nq = self.model, self.model.nq
        xq = self.x[:nq]
        g = ca.substitute(self.dyn.nle_expr, ca.vertcat(self.dyn.q, self.dyn.v), ca.vertcat(xq, ca.DM.zeros(m.nv)))
        B = ca.DM(m.actuation_matrix)
        ridge = FEW_FEET_RIDGE if 0 < len(contacts) <= 2 else RIDGE
        if contacts:
            J = ca.substitute(self.dyn.contact_jacobian_expr(contacts), self.dyn.q, xq)
            if self.events:
                flags = [self.contact_flag(f) for f in contacts]
                held = sum(flags)
                J = ca.mtimes(ca.diag(ca.vertcat(*[fl for fl in flags for _ in range(3)])), J)
                g = g * ca.if_else(held > 0.5, 1, 0)
                ridge = ca.if_else(held > 2.5, RIDGE, FEW_FEET_RIDGE)  # none held: g = 0, the torque 0
            A = ca.horzcat(B, J.T)
            w = [1.0] * m.nu + [100.0, 100.0, 0.01] * len(contacts)
        else:
            A, w = B, [1.0] * m.nu
        Winv = ca.DM(np.diag(1.0 / np.asarray(w)))
        AW = ca.mtimes(A, Winv)
        y = dense_ldl_solve(ca.mtimes(AW, A.T) + ridge * ca.DM.eye(A.shape[0]), g)
        return ca.mtimes(AW.T, y)[: m.nu]

    def project(self, x: ca.SX, u: ca.SX | None = None, s=ca.inf, k=None, w=None) -> ca.SX:
        """After each step (ending s after switch-in): renormalise the base quaternion; with contact
        events, run them and record the first touchdown and takeoff on the event clocks (on the
        plant perturbed by k and w of masked_contact_dynamics, when given)."""
        nq = self.model.nq
        x = ca.vertcat(normalize_quaternion(self.model, x[:nq]), x[nq:])
        if self.events and u is not None:
            from .hybrid import contact_events

            x = contact_events(self, x, u, s, k, w)
        return x

    def contact_mode(self, x: np.ndarray, default: tuple[str, ...] | list[str] | None = None) -> tuple[str, ...]:
        """Feet in contact at state x: with contact events the feet whose flag is set, else `default`
        (None: every contact frame)."""
        if self.events:
            return tuple(f for f in self.model.contact_frames if x[self.state_names.index(f"contact_{f}")] > 0.5)
        return tuple(self.model.contact_frames if default is None else default)

    @cached_property
    def _manifold_kinematics(self) -> ca.Function:
        """q -> [foot heights; vec(J); vec(G)]: all contact frames, stacked contact Jacobian J and
        G = d q / d v, in one output (one conversion per call)."""
        dyn = self.dyn
        z = dyn.contact_positions_expr[2, :].T
        J = dyn.contact_jacobian_expr(self.model.contact_frames)
        G = ca.jacobian(qdot(self.model, dyn.q, dyn.v), dyn.v)
        return ca.Function("manifold_kinematics", [dyn.q], [ca.vertcat(z, ca.vec(J), ca.vec(G))])

    @cached_property
    def _projection(self) -> ContactProjection:
        return ContactProjection(self)

    def project_to_contacts(self, x: np.ndarray, contacts: tuple[str, ...] | list[str], W: np.ndarray | None = None,
                            tol: float = 1e-12, max_iter: int = 50) -> np.ndarray:
        """The state near x on the contact manifold of `contacts`, close in the metric W.

        States the constrained dynamics hold: a unit base quaternion and height 0 for every foot in
        `contacts` (Gauss-Newton steps q (+) dv on the configuration manifold, each the least-norm
        step that zeroes the linearised heights), and velocities in the null space of the contacts'
        Jacobian (orthogonal projection), so those feet do not move. Both norms are W's blocks
        plus 1e-3 of their largest entry times the identity, so directions W leaves free (e.g. yaw
        on flat ground) are used only where weighted ones do not help. With contact events the
        flags are set to `contacts`.
        """
        return self._projection(np.ravel(x)[None], contacts, W, tol, max_iter)[0]

    def project_to_contacts_many(self, X: np.ndarray, contacts: tuple[str, ...] | list[str],
                                 W: np.ndarray | None = None, tol: float = 1e-12, max_iter: int = 50) -> np.ndarray:
        """project_to_contacts of every row of X (n, nx) at once (projection.py): the same points,
        each after the same Gauss-Newton steps it would take alone."""
        return self._projection(X, contacts, W, tol, max_iter)

    def base_frames(self) -> list[str]:
        """Frames rigidly attached to the floating base (where a push on the trunk may act)."""
        return [f.name for f in self.model.frames if self.model.n_base and f.joint == 0]

    def push_wrench(self, frame: str, q, F):
        """J_f^T F: the generalized force of a world-frame force F at `frame` (attached to the base).
        With the base twist in the base frame it is [R^T F; p x R^T F; 0] for the frame at p."""
        m = self.model
        f_base = ca.mtimes(quat_to_rotation(q[3:7]).T, F)
        return ca.vertcat(f_base, ca.cross(ca.DM(m.frame(frame).translation), f_base), ca.DM.zeros(m.nv - 6))

    def uncertain_plant(self, plan: ContactPlan | tuple[str, ...], frame: str) -> ca.Function:
        """(x, u, k, F, t) -> (xdot, lam, c): the dynamics with every link's mass and inertia scaled
        by k and a world-frame force F at `frame` (attached to the base), at clock t.

        k M a + k H = B u + J_f^T F + J^T lam is M a + H = (B u + J_f^T F) / k + J^T (lam / k): the
        nominal dynamics under the generalized force divided by k, with the ground forces k times the
        nominal solution's. The feet held are those of the primitive's contact plan (a tuple of feet:
        held throughout): its feet (lam and c over them, c = 1), or with a contact schedule (clock t)
        or contact events (flags in x) every contact frame, c saying which is held (lam 0 for the others).
        """
        from .hybrid import masked_contact_dynamics

        plan = plan if isinstance(plan, ContactPlan) else Fixed(tuple(plan))
        m = self.model
        k, F, t = ca.SX.sym("k"), ca.SX.sym("F", 3), ca.SX.sym("t")
        xq, xv = self.x[:m.nq], self.x[m.nq:m.nq + m.nv]
        if not plan.by_clock and not self.events:
            cd = ContactDynamics(self.dyn, plan.feet, self.baumgarte)
            a, lam = cd.solve((cd.tau_expr + self.push_wrench(frame, self.dyn.q, F)) / k)
            a, lam = ca.substitute([a, lam], [self.dyn.q, self.dyn.v, cd.u], [xq, xv, self.u])
            xdot = ca.vertcat(qdot(m, xq, xv), a, ca.DM.zeros(self.nx - m.nq - m.nv))
            c, lam = ca.DM.ones(len(plan.feet)), k * lam
        else:
            feet = m.contact_frames
            if plan.by_clock:
                mode = plan.mode(feet, t)
                c = ca.vertcat(*[mode[f] for f in feet])
            else:
                c = self.x[m.nq + m.nv:m.nq + m.nv + len(feet)]
            a, lam = masked_contact_dynamics(self, xq, xv, self.u, c, k, self.push_wrench(frame, xq, F))
            xdot = ca.vertcat(qdot(m, xq, xv), a, ca.DM.zeros(self.nx - m.nq - m.nv - len(self.event_clocks)),
                              *[clock_rate(self.x[i]) for i in self.event_clocks])
        return ca.Function("uncertain_plant", [self.x, self.u, k, F, t], [xdot, lam, c],
                           ["x", "u", "k", "F", "t"], ["xdot", "lam", "c"])

    def ground_setpoint(self, x_star: ca.SX, t: ca.SX) -> ca.SX:
        """x*(t) with base_z shifted (by its value at t = 0) so that the lowest contact frame touches z = 0."""
        x_fixed = feet_on_ground(self, np.array(ca.Function("x0", [t], [x_star])(0.0)).ravel())
        i = self.state_names.index("base_z")
        return ca.vertcat(x_star[:i], x_fixed[i], x_star[i + 1:])

    def _when_in_contact(self, frame: str, h: ca.SX, mode: dict | None = None, flags: bool = True) -> ca.SX:
        """A contact condition binds only while the foot is held: by the scheduled mode, or with
        contact events (`flags`) while the foot's flag is set."""
        c = mode[frame] if mode is not None else (self.contact_flag(frame) if flags else None)
        return h if c is None else ca.if_else(c > 0.5, h, 1e3)

    def scheduled_loop(self, mode: dict) -> OpenLoop:
        """Constrained dynamics holding the feet whose mode is 1 (mode: foot -> 0/1 symbols, of the
        clock from a contact plan, or the contact flags of the state); lambda of every contact frame
        in env."""
        from .hybrid import masked_contact_dynamics

        m = self.model
        xq, xv = self.x[:m.nq], self.x[m.nq:m.nq + m.nv]
        c = ca.vertcat(*[mode[f] for f in m.contact_frames])
        a, lam = masked_contact_dynamics(self, xq, xv, self.u, c)
        xdot = ca.vertcat(qdot(m, xq, xv), a, ca.DM.zeros(self.nx - m.nq - m.nv - len(self.event_clocks)),
                          *[clock_rate(self.x[i]) for i in self.event_clocks])
        env = dict(self.extra_env)
        for k, f in enumerate(m.contact_frames):
            for j, ax in enumerate("xyz"):
                env[f"{f}_f{ax}"] = lam[3 * k + j]
        return OpenLoop(xdot, env)

    def builtin_safe_set(self, name: str, loop: OpenLoop, plan: ContactPlan, t: ca.SX,
                         tol: float = 1e-3) -> list[tuple[str, ca.SX]]:
        """The paper's common safe sets as lists of (name, h) with h >= 0 safe, for the feet of the
        primitive's contact plan, with the ground forces of its open loop.

        When the clock sets the contact set (a contact schedule, of clock t), the contact conditions
        of every foot bind while the plan holds it."""
        m = self.model
        contacts = plan.feet
        mode = plan.mode(m.contact_frames, t) if plan.by_clock else None
        env = self.extra_env
        out = []
        if name == "joint_limits":  # C_{q, qdot}
            lo, hi = m.position_limits
            vmax = m.velocity_limits
            nq0, nv0 = 7 if m.n_base else 0, m.n_base
            for i, j in enumerate(m.joint_names):
                q = self.x[nq0 + i]
                v = self.x[m.nq + nv0 + i]
                out += [(f"q_min[{j}]", q - lo[i]), (f"q_max[{j}]", hi[i] - q),
                        (f"qdot_max[{j}]", vmax[i] - ca.fabs(v))]
        elif name == "ground_contact":  # C_ground: feet on the ground and not moving
            # with contact events, every foot of the set must be down whatever its flag says (a foot
            # that has lifted off, or not yet touched down, is outside C_ground)
            for f in contacts:
                out += [(f"on_ground[{f}]", self._when_in_contact(f, tol - ca.fabs(env[f"{f}_z"]), mode, False)),
                        (f"foot_still[{f}]", self._when_in_contact(
                            f, tol - ca.norm_2(ca.vertcat(*[env[f"{f}_v{a}"] for a in "xyz"])), mode, False))]
        elif name == "no_slip":  # lambda in the friction cone, lambda_z >= 0
            forces = loop.env
            for f in contacts:
                normal, cone = no_slip(*(forces[f"{f}_f{a}"] for a in "xyz"), self.friction)
                out += [(f"normal_force[{f}]", self._when_in_contact(f, normal, mode)),
                        (f"friction_cone[{f}]", self._when_in_contact(f, cone, mode))]
        elif name == "touchdown_gap":  # a scheduled touchdown finds the foot on the ground
            out += touchdown_gaps(plan, env)
        elif name == "aerial":  # C_aerial: no foot below the ground
            for f in m.contact_frames:  # a held foot sits at 0 up to the contact drift (tol); a free one must not sink
                held = mode[f] if mode is not None else self.contact_flag(f)  # None: the fixed contact set decides
                if held is None:
                    allow = tol if f in contacts else AIRBORNE_TOLERANCE
                else:
                    allow = ca.if_else(held > 0.5, tol, AIRBORNE_TOLERANCE)
                out.append((f"above_ground[{f}]", env[f"{f}_z"] + allow))
        else:
            raise KeyError(name)
        return out


AIRBORNE_TOLERANCE = 1e-5
"""How far (m) a foot that is not held may be below the ground in `aerial`: 10 um, the depth a soft
contact (MuJoCo's) still holds a foot at the instant it is released, and far above the rounding of a
located touchdown; a held foot gets the contact drift's tolerance (1 mm)."""
TOUCHDOWN_GAP = 0.003
"""Largest height (m) a foot may have over the last step before its scheduled touchdown."""
TOUCHDOWN_WIDTH = 0.001
"""Width (s) of a touchdown_gap window: one oracle step at the usual dt = 0.001 s."""


def touchdown_gaps(plan: ContactPlan, env: dict, gap: float = TOUCHDOWN_GAP,
                   width: float = TOUCHDOWN_WIDTH) -> list[tuple[str, ca.SX, tuple[float, float]]]:
    """(name, gap - foot_z, window) for every foot that joins the held set at a switching time T of a
    contact schedule, active on [T - width, T]: the windows users once computed from the gait timing.
    Raises KeyError (the block does not apply) unless the clock sets the contact set."""
    phases = getattr(plan, "phases", None)
    if not getattr(plan, "by_clock", False) or not phases:
        raise KeyError("touchdown_gap")
    out = []
    for k, (until, held) in enumerate(phases):
        if k + 1 == len(phases) and plan.period is None:
            break  # the last phase of an unwrapped schedule lasts
        after = phases[(k + 1) % len(phases)][1]
        for f in plan.feet:
            if f in after and f not in held:
                T = float(until)
                out.append((f"touchdown_gap[{f}]", gap - env[f"{f}_z"], (T - width, T)))
    return out


def no_slip(fx, fy, fz, mu) -> tuple:
    """(lambda_z, mu lambda_z - ||lambda_t||): the ground force pushes and stays in the friction cone."""
    return fz, mu * fz - ca.sqrt(fx**2 + fy**2 + 1e-12)


def _urdf_path(spec, urdf: str) -> Path:
    """The URDF a rigid-body spec names, confined like every path of a spec (mpgspec.spec.paths).

    `share:<package>/<path>` must stay inside the package's data folder (cmeel.prefix/share/
    <package>); any other path is relative to the project file and must stay inside the project
    folder or a folder passed in allow_paths. Raises a located SpecError otherwise.
    """
    from ...spec.paths import confine, confine_share, project_root, resolve_roots

    where = spec.system_locate(("urdf",))
    roots = getattr(spec, "roots", ()) or resolve_roots(project_root(spec.path))
    if urdf.startswith("share:"):
        path = confine_share(urdf, roots, where=where, key="system.urdf")
        if not path.is_file():  # the package is not installed: say where it was looked for
            find_urdf(urdf[len("share:"):])
        return path
    return confine(urdf, Path(spec.path).parent, roots, where=where, key="system.urdf")


def _read_model(path: Path, spec) -> RigidBodyModel:
    """The URDF's model; for a URDF outside the project folder the parser's own messages (they name
    the file's joints and links) are discarded."""
    from ...spec.paths import in_project
    from ...streams import native_stderr_discarded

    s = spec.system
    quiet = not in_project(path, getattr(spec, "roots", ()))
    with native_stderr_discarded() if quiet else nullcontext():
        return RigidBodyModel(path, s.contacts, floating_base=s.floating_base)


def _model_problem(err: Exception, path: Path | None, spec) -> str:
    """What went wrong loading the URDF: the parser's message (which may quote the file) only for
    a URDF in the project folder; contact frames missing (names from the spec) always."""
    from ...spec.paths import shown

    text = str(err)[:300]
    if isinstance(err, KeyError) or path is None:
        return text
    return shown(text, path, getattr(spec, "roots", ()))


def compile_rigid_body(spec) -> RigidBodyCompiledSystem:
    """Load the URDF with pinocchio and build symbols, env and limits."""
    from ...spec.paths import ReadProblem, clip_repr, read_text_bounded

    s = spec.system
    where = spec.system_locate(("urdf",))
    path = None
    try:
        path = _urdf_path(spec, s.urdf)
        read_text_bounded(path)  # a regular UTF-8 file of bounded size before pinocchio parses it
        model = _read_model(path, spec)
    except SpecError:
        raise
    except ReadProblem as p:
        raise SpecError(f"cannot load the robot model: {p.message}", location=where, key="system.urdf",
                        expected=p.expected, found=f"{clip_repr(s.urdf)} ({p.found})" if p.found
                        else clip_repr(s.urdf), code="MPG109") from None
    except (FileNotFoundError, OSError, ValueError, KeyError) as err:
        raise SpecError("cannot load the robot model", location=where, key="system.urdf",
                        expected="a readable URDF with the named contact frames",
                        found=f"{clip_repr(s.urdf)} ({_model_problem(err, path, spec)})", code="MPG109") from None
    legs = resolve_legs(s, model, spec.system_locate)
    dyn = RigidBodyDynamics(model)
    qn = (BASE_Q if model.n_base else []) + list(model.joint_names)
    vn = (BASE_V if model.n_base else []) + [f"{j}_dot" for j in model.joint_names]
    cn = [f"contact_{f}" for f in model.contact_frames] if s.contact_events else []
    if s.contact_events:  # the event clocks of compile/events.py
        cn += [clock_name(e) for e in ContactEvent]
    x = ca.SX.sym("x", model.nq + model.nv + len(cn))
    u = ca.SX.sym("u", model.nu)
    xq, xv = x[:model.nq], x[model.nq:model.nq + model.nv]
    tree = dyn.state(xq, xv)
    env: dict[str, object] = {"mass": float(model.total_mass)}
    for f in model.contact_frames:
        p = tree.frame_position(f)
        vel = dyn.contact_velocity_expr([f])
        vel = ca.substitute(vel, ca.vertcat(dyn.q, dyn.v), ca.vertcat(xq, xv))
        for j, ax in enumerate("xyz"):
            env[f"{f}_{ax}"] = p[j]
            env[f"{f}_v{ax}"] = vel[j]
    com = center_of_mass(tree)
    for j, ax in enumerate("xyz"):
        env[f"com_{ax}"] = com[j]
    lim = s.torque_limit
    hi = model.effort_limits if lim is None else np.broadcast_to(np.asarray(lim, float), (model.nu,)).copy()
    sysc = RigidBodyCompiledSystem(
        name=s.name, state_names=qn + vn + cn, input_names=[f"tau_{j}" for j in model.joint_names],
        parameters=dict(s.parameters), x=x, u=u, xdot=ca.SX(0, 1), u_lo=-hi, u_hi=hi,
        wrap=np.zeros(x.shape[0]), extra_env=env, dyn=dyn, friction=s.friction,
        baumgarte=Baumgarte(s.baumgarte.alpha, s.baumgarte.beta), events=s.contact_events, legs=legs,
    )
    sysc.xdot = sysc.open_loop(None).xdot
    return sysc


def feet_on_ground(sys: RigidBodyCompiledSystem, x: np.ndarray) -> np.ndarray:
    """Shift base_z so that the lowest contact frame touches z = 0."""
    x = np.array(x, float)
    fk = ca.Function("fk", [sys.x], [ca.vertcat(*[sys.extra_env[f"{f}_z"] for f in sys.model.contact_frames])])
    x[sys.state_names.index("base_z")] -= float(np.min(np.array(fk(x))))
    return x
