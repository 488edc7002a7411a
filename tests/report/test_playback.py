"""The 3D playback page: frame sampling, the data a hostile name cannot break out of, and (in
test_browser.py) the A1's page in Chromium."""
from __future__ import annotations

import json
import re

import numpy as np

from mpgspec.execute.sequence import playback_samples
from mpgspec.report.playback import render_playback


def test_frames_are_the_samples_nearest_to_each_frame_time():
    t = np.array([0.0, 0.011, 0.03, 0.05, 0.079, 0.081, 0.2])
    # frame times 0, 0.04 (a tie: the earlier), 0.08, 0.12, 0.16, 0.2; each sample once
    assert list(playback_samples(t, fps=25.0)) == [0, 2, 4, 5, 6]
    assert list(playback_samples([], 25.0)) == []
    assert list(playback_samples([1.5], 25.0)) == [0]


def test_a_hostile_name_stays_text():
    name = "</script><script>alert(1)</script>&"
    data = {"project": name, "duration": 1.0, "end": 1.0, "fps": 25.0, "layout": {"trunk": 8, "legs": [2]},
            "runs": [{"name": name, "mode": "graph", "source": "mpgspec", "color": "#0072B2", "safe": True,
                      "t": [0.0], "p": [0.0] * 33, "active": [[name, 1]], "switches": [], "violation": None}]}
    page = render_playback(data)
    assert page.count("<script") == 2 and "alert(1)</script>" not in page
    blob = re.search(r'<script type="application/json" id="data">(.*?)</script>', page, re.S).group(1)
    assert json.loads(blob)["runs"][0]["name"] == name
    assert "&lt;/script&gt;" in page.split("<body>")[0]  # the title, escaped


def test_each_frame_holds_the_points_of_its_own_configuration():
    """The frames of several configurations, computed at once, are those of each alone (the trunk
    box's eight corners, every leg point, the CoM)."""
    from pathlib import Path

    import casadi as ca

    from mpgspec.compile.system import compile_system
    from mpgspec.execute.sequence import body_points
    from mpgspec.report.playback import _Skeleton
    from mpgspec.spec.loader import load_project

    system = compile_system(load_project(Path(__file__).resolve().parents[2] / "specs" / "a1" / "project.yaml"))
    sk = _Skeleton(system)
    rng = np.random.default_rng(3)
    X = np.zeros((3, int(system.x.shape[0])))
    nq = system.model.nq
    X[:, :3] = rng.uniform(-1, 1, (3, 3))
    quat = rng.normal(size=(3, 4))
    X[:, 3:7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    X[:, 7:nq] = rng.uniform(-0.5, 0.5, (3, nq - 7))
    flat = np.asarray(sk.frames(X)).reshape(3, -1)
    fun, legs = body_points(system, box=True)
    for i in range(3):
        com, trunk, pts = (np.asarray(v, float) for v in fun(ca.DM(X[i])))
        want = np.concatenate([trunk.T.ravel(), pts.T.ravel(), com.ravel()])
        assert np.allclose(flat[i], want, atol=6e-4), i
    assert trunk.shape == (3, 8) and sum(legs) == pts.shape[1]
