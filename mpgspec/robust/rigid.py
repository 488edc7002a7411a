"""Robust rollouts of a rigid-body primitive: mass scale, friction and a push on the base.

The plant is the system's uncertain_plant (every link's mass and inertia times k, a world-frame
force F at a base frame); the controller is the primitive's own, on the nominal model, solved at
its control rate and held in between when it is sampled (the ID-QP), as the oracle runs it. The
no-slip safety functions are evaluated with the plant's ground forces and the friction coefficient
mu of the scenario; every other safety function as compiled.
"""
from __future__ import annotations

import casadi as ca

from ..compile.primitive import CompiledPrimitive, saturate
from ..compile.rigidbody.system import no_slip
from ..oracle.integrator import _jump_fn
from .rollout import RobustRollout


def no_slip_rows(prim: CompiledPrimitive) -> dict[int, tuple[int, int]]:
    """h row -> (foot index in the primitive's contact set, 0 normal force | 1 friction cone)."""
    feet = list(prim.info.get("contacts", []))
    rows = {}
    for j, name in enumerate(prim.h_names):
        for kind, prefix in enumerate(("normal_force[", "friction_cone[")):
            if name.startswith(prefix) and name.endswith("]") and name[len(prefix):-1] in feet:
                rows[j] = (feet.index(name[len(prefix):-1]), kind)
    return rows


class RigidRobustRollout(RobustRollout):
    """RobustRollout of a rigid-body target: theta holds the named parameters (mass_scale,
    friction), d the push's world force (3 entries, or none)."""

    def __init__(self, prim: CompiledPrimitive, names: list[str], frame: str, push: bool, segments: int,
                 settings, horizon: float, duration: float | None = None):
        sys = prim.system
        self.names, self.push = list(names), push
        self.plant_fn = sys.uncertain_plant(tuple(prim.info.get("contacts", sys.model.contact_frames)), frame)
        super().__init__(prim, self.plant_fn, [], segments, settings, horizon, duration)

    def _loop(self, prim, plant_fn, dist_inputs, dt):
        sys = prim.system
        nx, nu = sys.nx, sys.nu
        nth, nd = len(self.names), 3 if self.push else 0
        law = prim.sampled
        nw = law.nw if law is not None else 0
        nhold = 1 + nu + nw if law is not None else 0
        z, d = ca.MX.sym("z", 2 * nx + 2 + nth + nhold), ca.MX.sym("d", nd)
        x, t, s, xsw = z[:nx], z[nx], z[nx + 1], z[nx + 2:2 * nx + 2]
        th, hold = z[2 * nx + 2:2 * nx + 2 + nth], z[2 * nx + 2 + nth:]
        k = th[self.names.index("mass_scale")] if "mass_scale" in self.names else 1.0
        mu = th[self.names.index("friction")] if "friction" in self.names else sys.friction
        F = d if nd else ca.DM.zeros(3)
        rows = no_slip_rows(prim)
        jump = _jump_fn(prim)

        def sat(u):
            return saturate(u, sys.u_lo, sys.u_hi)

        def control(xx, tt, ss, held):  # (u_raw, u) at a state; a sampled law holds its input
            if law is not None:
                return held, sat(held)
            return prim.control(xx, tt, ss, xsw)

        def h_at(xx, tt, ss, held, FF):
            ur, u = control(xx, tt, ss, held)
            h = prim.loop_u(xx, tt, ss, xsw, ur)[1] if law is not None else prim.h(xx, tt, ss, xsw)
            lam = plant_fn(xx, u, k, FF)[1]
            parts = [ca.vertsplit(h)[j] if j not in rows else
                     no_slip(*ca.vertsplit(lam[3 * rows[j][0]:3 * rows[j][0] + 3]), mu)[rows[j][1]]
                     for j in range(h.shape[0])]
            return ca.vertcat(ca.vertcat(*parts) if parts else ca.MX(0, 1), prim.roa_margin(xx, tt))

        held = hold[1:1 + nu] if law is not None else None

        def f(xx, tt, ss):
            return plant_fn(xx, control(xx, tt, ss, held)[1], k, F)[0]

        k1 = f(x, t, s)
        k2 = f(x + dt / 2 * k1, t + dt / 2, s + dt / 2)
        k3 = f(x + dt / 2 * k2, t + dt / 2, s + dt / 2)
        k4 = f(x + dt * k3, t + dt, s + dt)
        x_end = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        xn = jump(x_end, control(x, t, s, held)[1], t + dt, s + dt)
        if law is not None:  # solved at the start of every m-th step, from the previous solve's warm start
            m, c, w = law.steps(dt), hold[0], hold[1 + nu:]
            c_next = ca.if_else(c + 1 > m - 0.5, 0, c + 1)
            if m == 1:
                u_next, w_next = law.solve(xn, t + dt, s + dt, xsw, w)
            else:
                a = [*law.solve.mx_in(), ca.MX.sym("u", nu)]
                sample = ca.Function.if_else("sample", ca.Function("solve", a, law.solve.call(a[:5])),
                                             ca.Function("keep", a, [a[5], a[4]]))
                u_next, w_next = sample(c_next < 0.5, xn, t + dt, s + dt, xsw, w, held)
            hold_next = ca.vertcat(c_next, u_next, w_next)
        else:
            u_next, hold_next = None, ca.MX(0, 1)
        out = h_at(xn, t + dt, s + dt, u_next, F)
        step = ca.Function("robust_rigid_step", [z, d], [ca.vertcat(xn, t + dt, s + dt, xsw, th, hold_next), out])
        x0, t0, th0, d0 = ca.MX.sym("x0", nx), ca.MX.sym("t0"), ca.MX.sym("th0", nth), ca.MX.sym("d0", nd)
        zf = ca.vertcat(x0, t0, 0, x0, th0)
        if law is not None:
            u0, w0 = law.solve(x0, t0, 0, x0, ca.DM.zeros(nw))
            hold0 = ca.vertcat(0, u0, w0)
        else:
            u0, hold0 = None, ca.MX(0, 1)
        # the first sample: the same expressions on z0 = [x0; t0; 0; x0; theta0; hold0]
        out0 = ca.Function("o", [z, d], [h_at(x, t, s, held, F)])(
            ca.vertcat(zf, hold0), d0 if nd else ca.MX(0, 1))
        first = ca.Function("robust_rigid_first", [x0, t0, th0, d0], [out0, hold0])
        return step, first, nth, nd, nhold

