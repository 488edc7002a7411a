"""The trot's setup: its contact schedule from the gait timing, and the calibrated command read
from the gait table `mpgspec gait` wrote for it (stale tables are refused)."""
from __future__ import annotations

import hashlib
import json

from ...compile.laws.kind import Setup
from ...compile.setpoint import spec_file
from ...errors import SpecError
from ...spec.paths import MAX_FILE_BYTES, ReadProblem, clip, read_text_bounded, shown
from .pairs import trot_pairs
from .trot import check_pose, gains_of, min_normal_force, stance_height


def trot_setup(inst, sys, ec, consts: dict) -> Setup:
    """The trot's contact schedule (from its timing) and, for its info and law, the speed, the
    calibrated command of its gait table and the table's header."""
    c = inst.spec.controller
    owner = f"primitive '{inst.name}'"
    check_ready(c, sys, ec)
    speed = ec.number(c.speed, ("controller", "speed"), consts, finite=True)
    out = {"speed": speed, "command": speed, "gait": None, "inputs": trot_inputs(c, sys, speed)}
    if c.gait is not None:
        where = inst.locate(("controller", "gait"))
        raw, path = spec_file(inst, c.gait, where, f"{owner}: controller.gait")
        if not path.is_file():
            raise SpecError("the gait table does not exist", location=where, key=f"{owner}: controller.gait",
                            expected="a table written by `mpgspec gait`", found=str(raw), code="MPG110",
                            hint="generate it with `mpgspec gait <project>/gaits.yaml`")
        try:
            head = gait_header(path)
        except ReadProblem as prob:
            raise SpecError(f"cannot read the gait table: {prob.message}", location=where,
                            key=f"{owner}: controller.gait", expected=prob.expected or "a table written by "
                            "`mpgspec gait`", found=f"{raw} ({prob.found})" if prob.found else raw,
                            code="MPG110") from None
        if head.get("inputs") != out["inputs"]:
            raise SpecError("the gait table is stale: it was generated for other settings", location=where,
                            key=f"{owner}: controller.gait", expected=f"inputs {out['inputs']}",
                            found=shown(f"inputs {clip(str(head.get('inputs')), 60)}", path, inst.roots),
                            code="MPG110",
                            hint="regenerate it with `mpgspec gait <project>/gaits.yaml`")
        try:
            out["command"] = float(head["command"])
        except (KeyError, ValueError):
            raise SpecError("the gait table has no calibrated command", location=where,
                            key=f"{owner}: controller.gait", expected="a header line '# command: <m/s>'",
                            found=shown(clip(str(head.get("command")), 60), path, inst.roots),
                            code="MPG110") from None
        out["gait"] = {k: head[k] for k in head}
        out["gait_file"] = str(raw)
    gains = gains_of(c, out["command"], sys, ec)
    return Setup(contacts=gains.schedule(tuple(sys.model.contact_frames)), info={"trot": out})


def check_ready(c, sys, ec) -> None:
    """The checks a trot passes before its gait table is read (or written by `mpgspec gait`): a
    quadruped with its pairs named, and a pose of the system's joints (located SpecErrors)."""
    trot_pairs(c, sys, ec)
    check_pose(c, sys, ec)


def gait_header(path) -> dict[str, str]:
    """The `# key: value` lines at the top of a gait table (read with the bound of every spec file)."""
    out = {}
    for line in read_text_bounded(path, MAX_FILE_BYTES).splitlines():
        if not line.startswith("#"):
            break
        key, _, value = line[1:].partition(":")
        out[key.strip()] = value.strip()
    return out


LEGACY = {"kz": 100.0, "dz": 20.0, "d_yaw": 10.0, "f_min": 10.0, "regularization": 1e-4, "moment_weight": 10.0,
          "cone_fraction": 0.9, "placement_fraction": 0.8, "lift_fraction": 0.0,
          "touchdown_height": 0.0, "swing_feedforward": 0.0}
"""Settings the trot's law had as fixed numbers before they were spec fields: the hash of the inputs
holds them only when they differ, so that tables generated before stay valid."""
OPTIONAL = ("accel_limit", "height_accel_limit", "tilt_accel_limit", "friction")
"""Settings added later whose default is none: the hash holds them only when they are given."""


def trot_inputs(c, sys, speed: float) -> str:
    """Hash of what a gait table depends on: the robot model and limits, the trot's settings (as the
    law resolves them: h_d, f_min) and the speed."""
    m = sys.model
    ctrl = c.model_dump(mode="json", exclude={"gait", "speed", "pairs", "f_min_fraction", *OPTIONAL, *LEGACY})
    ctrl["height"] = float(c.height) if c.height is not None else stance_height(sys, dict(c.pose))
    resolved = {**{k: float(getattr(c, k)) for k in LEGACY if k != "f_min"}, "f_min": min_normal_force(c, sys)}
    ctrl.update({k: v for k, v in resolved.items() if v != LEGACY[k]})
    ctrl.update({k: float(getattr(c, k)) for k in OPTIONAL if getattr(c, k) is not None})
    if c.pairs is not None:
        ctrl["pairs"] = [list(p) for p in c.pairs]
    robot = {"mass": round(float(m.total_mass), 9), "nq": m.nq, "feet": list(m.contact_frames),
             "friction": float(sys.friction), "u_hi": [float(v) for v in sys.u_hi],
             "baumgarte": [float(sys.baumgarte.alpha), float(sys.baumgarte.beta)]}
    text = json.dumps({"robot": robot, "trot": ctrl, "speed": round(float(speed), 12)}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]
