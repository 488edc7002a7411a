"""The 3D playback of a project's goal-sequence runs: playback.html beside report.html.

A static page in the spirit of MeshCat's recorded animations: the robot of every run (mpgspec's naive
and graph runs, and their replays in the cross-check's simulator, the graph executor on the
simulator's own state included) drawn in 3D on one floor, a time slider and a play button, the active
primitive of each run and its first violation marked. The robot is drawn as its kinematic skeleton
(execute.sequence.body_points: the trunk as the box spanning the hips, each leg joint by joint to
the foot), computed here with the system's own kinematics, so the page needs no meshes, no network and
no library: one file, its script inline, that opens offline. `#t=3.2` in its address starts it at that
time (report.html links to it at each run's first violation).

Only systems with a floating base have a playback (there is no robot to draw otherwise).
"""
from __future__ import annotations

import json
from functools import lru_cache

import jinja2
import numpy as np
from markupsafe import Markup

from ..execute.sequence import PLAYBACK_FPS, SequenceRun, body_points, playback_samples
from .fig6 import run_color
from .findings import SIMULATORS

POINT_DIGITS = 3
"""Decimals of the drawn points (m): 1 mm."""


@lru_cache(maxsize=1)
def _template() -> jinja2.Template:
    env = jinja2.Environment(loader=jinja2.PackageLoader("mpgspec.report", "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined)
    return env.get_template("playback.html.j2")


def _runs_rle(names: list[str]) -> list[list]:
    out: list[list] = []
    for n in names:
        if out and out[-1][0] == n:
            out[-1][1] += 1
        else:
            out.append([n, 1])
    return out


def _violation(v: dict | None) -> dict | None:
    if not v:
        return None
    return {"t": float(v.get("t", 0.0)), "h": str(v.get("h", "")), "primitive": str(v.get("primitive", "")),
            "value": float(v["value"]) if isinstance(v.get("value"), (int, float)) else None}


class _Skeleton:
    """Configurations -> the drawn points of each frame (trunk box, legs, CoM), flat, in mm steps."""

    def __init__(self, system):
        got = body_points(system, box=True)
        if got is None:
            raise ValueError("no floating base")
        self.fun, self.legs = got
        self.nx = int(system.x.shape[0])

    def frames(self, X: np.ndarray) -> list[float]:
        if not len(X):
            return []
        full = np.zeros((len(X), self.nx))
        full[:, :X.shape[1]] = X[:, :self.nx]
        com, trunk, pts = (np.asarray(v, float) for v in self.fun.map(len(X))(full.T))
        n = len(X)
        # a mapped output stacks each call's columns side by side: (3, n * k) -> (n, k, 3) -> one row a frame
        per = np.concatenate([trunk.reshape(3, n, -1).transpose(1, 2, 0).reshape(n, -1),
                              pts.reshape(3, n, -1).transpose(1, 2, 0).reshape(n, -1), com.T], axis=1)
        return [round(float(v), POINT_DIGITS) for v in per.ravel()]


def playback_data(project: str, system, runs: dict[str, SequenceRun], replays: dict[str, dict] | None = None,
                  crosscheck: dict | None = None, duration: float | None = None) -> dict | None:
    """The page's data: every run's frames at PLAYBACK_FPS, its primitives, switches and first
    violation; None when the system has no floating base or there is no run to show.

    replays: name -> {t, x, active} of the simulator's runs (CrossCheckResult.playback());
    crosscheck: the report's cross-check entry (their verdicts and first violations)."""
    try:
        sk = _Skeleton(system)
    except ValueError:
        return None
    out = []
    for k, (mode, r) in enumerate(runs.items()):
        if not r.t or not r.x:
            continue
        idx = playback_samples(r.t)
        X = np.asarray([r.x[i] for i in idx], float)
        out.append({"name": f"{mode} (mpgspec)", "mode": mode, "source": "mpgspec", "color": run_color(mode, k),
                    "safe": bool(r.safe), "t": [round(float(r.t[i]), 4) for i in idx], "p": sk.frames(X),
                    "active": _runs_rle([r.active[i] for i in idx]) if len(r.active) == len(r.t) else [],
                    "switches": [{"t": float(s["t"]), "to": s["to"]} for s in r.switches],
                    "violation": _violation(r.violations[0] if r.violations else None)})
    xc = crosscheck or {}
    sim_key = xc.get("simulator")
    sim = SIMULATORS.get(sim_key, str(sim_key or "simulator"))
    for name, rep in (replays or {}).items():
        mode, _, executor = name.partition(" ")
        entry = (xc.get("runs") or {}).get(mode) or {}
        verdict = (entry.get("executor") or {}) if executor else (entry.get(sim_key) or {})
        if not rep.get("t") or not rep.get("x"):
            continue
        switches = verdict.get("switches") if executor else entry.get("switches")
        out.append({"name": f"{mode} {'executor ' if executor else ''}({sim})", "mode": mode, "source": sim,
                    "color": "#555555" if executor else "#999999", "dash": True,
                    "safe": bool(verdict.get("safe", True)), "t": [float(v) for v in rep["t"]],
                    "p": sk.frames(np.asarray(rep["x"], float)), "active": _runs_rle(list(rep.get("active") or [])),
                    "switches": [{"t": float(s["t"]), "to": s["to"]} for s in (switches or []) if "to" in s],
                    "violation": _violation(verdict.get("first_violation"))})
    if not out:
        return None
    end = max(r["t"][-1] for r in out)
    return {"project": project, "duration": float(duration if duration is not None else end), "end": float(end),
            "fps": PLAYBACK_FPS, "layout": {"trunk": 8, "legs": list(sk.legs)}, "runs": out}


def render_playback(data: dict) -> str:
    """playback.html's text: the template with the data inline (as JSON a script cannot close)."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return _template().render(project=data["project"], data=Markup(text))
