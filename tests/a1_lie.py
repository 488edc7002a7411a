"""The paper's Lie for tests that need a continuous law on the A1's four grounded feet: specs/a1's Lie
runs the ID-QP (sampled, held between solves); the paper's is a joint PD with gravity compensation and
the cubic motion profile (eq. 7)."""
from __future__ import annotations

import re
from pathlib import Path

PD_LIE = """controller:
  type: pd
  outputs: [FL_hip_joint, FL_thigh_joint, FL_calf_joint, FR_hip_joint, FR_thigh_joint, FR_calf_joint,
            RL_hip_joint, RL_thigh_joint, RL_calf_joint, RR_hip_joint, RR_thigh_joint, RR_calf_joint]
  kp: [60, 60, 60, 60, 60, 60, 60, 60, 60, 60, 60, 60]
  kd: [3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3]
  gravity_compensation: true
  profile: {duration: 1.0}
"""
"""The paper's Lie law: a joint PD with gravity compensation and the cubic motion profile (eq. 7)."""


def pd_lie(folder: Path) -> Path:
    """Rewrite the Lie of a copy of specs/a1 at `folder` to the paper's joint PD (PD_LIE) with the radius it
    had (0.023: the largest, 0.024 by bisection, for which its E lies inside C, rounded down), for the tests
    of a continuous law on four grounded feet; returns lie.yaml's path."""
    path = Path(folder) / "primitives" / "lie.yaml"
    text = with_controller(path.read_text(), PD_LIE)
    text, n = re.subn(r"\n  radius: [^\n]*", "\n  radius: 0.023", text)
    assert n == 1, f"{path}: expected one roa radius, found {n}"
    text = re.sub(r"\ndescription: [^\n]*", "\ndescription: Rest low on the ground with folded legs (joint PD with the cubic motion profile).", text)
    path.write_text(text)
    return path


def with_controller(text: str, block: str) -> str:
    """A primitive file's text (of specs/a1, whose `controller:` block is followed by `safe_set:`) with its
    controller block replaced by `block` (YAML from `controller:` on)."""
    head, rest = text.split("controller:\n", 1)
    return head + block + rest[rest.index("safe_set:\n"):]
