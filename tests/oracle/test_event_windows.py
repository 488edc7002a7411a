"""Safe-set windows anchored on contact events, on a falling body (tests/fixtures/falling_body).

A trunk on a rigid 0.2 m leg with a point foot, released at rest with the foot DROP = 0.1 m above
the ground, falls freely (the leg's mass hangs on the hip axis below the trunk's centre, so nothing
turns) until the foot reaches the ground at t_c = sqrt(2 DROP / g). The touchdown is detected at the
end of the step in which the foot gets there, so the first touchdown T_c lies in (t_c, t_c + dt];
a plastic impact then stops the body, which stands on its foot while the contact's drift
correction lifts it back out of the ground.

Each safety function below holds on one side of T_c and fails on the other, so a window that is
not where it should be changes the verdict.
"""
from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mpgspec.api import compile_project, settings_for
from mpgspec.cli import main
from mpgspec.compile.events import NEVER, EventWindow
from mpgspec.oracle import Reason, SafetyOracle
from mpgspec.oracle.flow import RAMP_STEPS
from mpgspec.oracle.integrator import build_chunk, initial_state
from mpgspec.oracle.trace import trace
from mpgspec.spec.loader import load_project

FIXTURE = Path(__file__).parents[1] / "fixtures" / "falling_body"
G = 9.81  # pinocchio's gravity
DROP = 0.1
T_C = math.sqrt(2 * DROP / G)  # 0.1428 s
LAND_SAFE_SET = """\
    safe_set:
      - use: joint_limits
      - {use: aerial, when: {before: first_touchdown}}
      - {use: ground_contact, when: {after: first_touchdown, delay: 0.16}}
"""


def land(tmp_path: Path, safe_set: str | None = None, radius: float | None = None):
    """(Land compiled, oracle settings, spec path) of the fixture, its safe set replaced by YAML flow
    mappings (one a line) and its radius of E by `radius`."""
    folder = tmp_path / "falling_body"
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(FIXTURE / "body.urdf", folder)
    text = (FIXTURE / "project.yaml").read_text()
    assert LAND_SAFE_SET in text
    if safe_set is not None:
        text = text.replace(LAND_SAFE_SET, "    safe_set:\n" + "".join(f"      - {f}\n" for f in safe_set.split("\n")))
    if radius is not None:
        text = text.replace("radius: 0.01\n", f"radius: {radius}\n")
    path = folder / "project.yaml"
    path.write_text(text)
    spec = load_project(path)
    return compile_project(spec)["Land"], settings_for(spec), path


def dropped(prim) -> np.ndarray:
    """The state at release: at rest, the foot DROP above the ground and out of contact."""
    sys = prim.system
    x = prim.x_star(0.0)
    x[sys.state_names.index("base_z")] += DROP
    x[sys.state_names.index("contact_foot")] = 0.0
    return x


def touchdown(prim, settings, x0=None, horizon: float = 0.4) -> tuple[float, dict, np.ndarray, np.ndarray]:
    """(T_c: time of the first sample back in contact after one out of it, the trace, its times, its
    states) of a rollout from x0 (default: the release)."""
    out = trace(prim, dropped(prim) if x0 is None else x0, 0.0, horizon, settings, max_points=100000)
    t, X = np.array(out["t"]), np.array(out["x"], dtype=float)
    flag = X[prim.system.state_names.index("contact_foot")] > 0.5
    k = int(np.argmax(flag[1:] & ~flag[:-1])) + 1
    assert flag[k] and not flag[k - 1] and np.all(flag[k:])
    return float(t[k]), out, t, X


@pytest.fixture(scope="module")
def paper_land(tmp_path_factory):
    return land(tmp_path_factory.mktemp("land"))


@pytest.mark.parametrize("dt", [0.002, 0.005])
def test_first_touchdown_is_the_free_fall_time_within_one_step(paper_land, dt):
    prim, settings, _ = paper_land
    names = prim.system.state_names
    Tc, _, t, X = touchdown(prim, settings.replace(dt=dt))
    assert T_C < Tc <= T_C + dt + 1e-9
    since = X[names.index("since_first_touchdown")]
    after = t >= Tc - 1e-12
    assert np.all(since[~after] == NEVER)  # not before it happened
    assert np.allclose(t[after] - since[after], Tc, atol=1e-9)  # T_c = s - tau from then on
    assert np.all(X[names.index("since_takeoff")] == NEVER)  # nothing took off


def test_takeoff_and_an_event_clock_carried_over_from_before_switch_in(paper_land):
    """Standing on the foot and pushed up at 1 m/s, the body lifts off in the first step (T_t = dt),
    flies and lands again: the touchdown 0.05 s before switch-in does not count, the landing does,
    within one step of the ballistic time from the state at lift-off."""
    prim, settings, _ = paper_land
    names = prim.system.state_names
    i = names.index
    dt = settings.dt
    x0 = prim.x_star(0.0)
    x0[i("base_vz")] = 1.0
    x0[i("since_first_touchdown")] = 0.05
    Tc, _, t, X = touchdown(prim, settings, x0=x0)
    assert X[i("contact_foot"), 1] == 0.0 and t[1] == pytest.approx(dt)
    assert np.allclose(t[1:] - X[i("since_takeoff"), 1:], dt, atol=1e-9)  # T_t = dt
    z1, v1 = X[i("base_z"), 1] - 0.2, X[i("base_vz"), 1]  # foot height and speed at lift-off
    t_land = dt + (v1 + math.sqrt(v1 ** 2 + 2 * G * z1)) / G
    assert t_land < Tc <= t_land + dt + 1e-9
    before = t < Tc - 1e-12
    assert np.all(X[i("since_first_touchdown"), before] >= t[before])  # carried over: not since switch-in
    assert np.allclose(t[~before] - X[i("since_first_touchdown"), ~before], Tc, atol=1e-9)


FALLING = '{name: falling, h: "0.01 - base_vz - 0.5*9.81*s"}'
"""Falls at least half as fast as in free fall: holds in flight, fails once the body stands."""


def test_a_function_before_the_first_touchdown_stops_counting_there(tmp_path):
    windowed, settings, _ = land(tmp_path / "a", FALLING[:-1] + ", when: {before: first_touchdown}}")
    x0 = dropped(windowed)
    e = SafetyOracle(windowed, settings)(x0, 0.0)
    assert (e.status, e.reason) == ("safe", Reason.ENTERED_E) and e.t_enter > T_C + 0.1
    assert e.min_margins["falling"] == pytest.approx(0.01)  # counted from the release on, never after T_c
    always, settings, _ = land(tmp_path / "b", FALLING)
    Tc = touchdown(always, settings)[0]
    e = SafetyOracle(always, settings)(x0, 0.0)
    assert (e.status, e.reason, e.violated) == ("unsafe", Reason.LEFT_C, "falling")
    assert e.t_stop == pytest.approx(Tc, abs=1e-9)  # the first sample standing


AT_REST = '{name: at_rest, h: "0.05 - abs(base_vz)"}'
"""Moves slower than 5 cm/s: fails 5 ms into the fall, holds once the impact has stopped the body."""


def test_a_function_after_the_first_touchdown_is_inactive_before_it(tmp_path):
    windowed, settings, _ = land(tmp_path / "a", AT_REST[:-1] + ", when: {after: first_touchdown}}")
    x0 = dropped(windowed)
    e = SafetyOracle(windowed, settings)(x0, 0.0)
    assert (e.status, e.reason) == ("safe", Reason.ENTERED_E)
    assert 0 < e.min_margins["at_rest"] < 0.05  # counted while standing
    always, settings, _ = land(tmp_path / "b", AT_REST)
    e = SafetyOracle(always, settings)(x0, 0.0)
    assert (e.status, e.reason, e.violated) == ("unsafe", Reason.LEFT_C, "at_rest")
    assert 0.05 / G <= e.t_stop <= 0.05 / G + settings.dt + 1e-9


EPS = 0.002
DT = 0.005  # the window [T_c, T_c + EPS) is shorter than a step


def sunk(depth: float) -> str:
    """Sunk less than `depth` into the ground, judged only on [T_c, T_c + EPS)."""
    return f'{{name: sunk, h: "base_z - 0.2 + {float(depth)!r}", when: {{after: first_touchdown, for: {EPS}}}}}'


@pytest.mark.parametrize("error", ["local", "doubling"])
def test_a_window_shorter_than_a_step_after_the_first_touchdown_is_judged(tmp_path, error):
    prim, settings, _ = land(tmp_path / "ref")
    settings = settings.replace(dt=DT, error=error)
    Tc, out, t, X = touchdown(prim, settings)
    z = X[prim.system.state_names.index("base_z")] - 0.2
    sink = -z[(t >= Tc - 1e-12) & (t < Tc + EPS)]  # the reference: how deep it is on the window
    assert sink.size == 1 and sink[0] > 1e-3  # only T_c itself is a sample of it at dt = 5 ms
    deep, _, _ = land(tmp_path / "deep", sunk(sink[0] / 2), radius=0.1)  # E: sunk < 0.1 mm, speeds < 1 cm/s
    e = SafetyOracle(deep, settings)(dropped(deep), 0.0)
    assert (e.status, e.reason, e.violated) == ("unsafe", Reason.LEFT_C, "sunk")
    assert e.t_stop == pytest.approx(Tc, abs=1e-9)
    shallow, _, _ = land(tmp_path / "shallow", sunk(2 * sink[0]), radius=0.1)
    e = SafetyOracle(shallow, settings)(dropped(shallow), 0.0)
    assert (e.status, e.reason) == ("safe", Reason.ENTERED_E)
    assert e.t_enter > Tc + EPS and 0 < e.min_margins["sunk"] <= sink[0] + 1e-9


def test_the_oracle_steps_onto_the_end_of_an_event_window(tmp_path):
    """A step starts at T_c and is EPS long; without that edge the violation on the window is missed."""
    prim, settings, _ = land(tmp_path / "a", sunk(1e-3))
    settings = settings.replace(dt=DT)
    Tc = touchdown(prim, settings)[0]
    ch = build_chunk(prim, DT, 64, jit=False, with_state=True)
    zf, out = ch.run(initial_state(prim, dropped(prim), 0.0)[:, None])
    s, h = out[ch.rows.s, 0], out[ch.rows.dt, 0]
    k = int(np.argmin(np.abs(s - Tc)))
    assert s[k] == pytest.approx(Tc, abs=1e-9) and h[k] == pytest.approx(EPS, abs=1e-12)
    n = RAMP_STEPS + 1  # the first DT after switch-in: RAMP_STEPS + 1 steps growing from DT / 2^RAMP_STEPS
    assert h[:n].sum() == pytest.approx(DT) and np.allclose(h[n:k], DT) and np.allclose(h[k + 1:k + 5], DT)
    sink = -out[ch.rows.x, 0, k][prim.system.state_names.index("base_z")] + 0.2
    assert sink > 1e-3  # sunk(1e-3) is violated at T_c

    blind, _, _ = land(tmp_path / "b", sunk(1e-3))
    (w,) = [w for w in blind.windows if isinstance(w, EventWindow)]
    no_edge = dataclasses.replace(w, end=math.inf)  # active from T_c on: the control case
    e = SafetyOracle(dataclasses.replace(blind, windows=[*blind.windows[:-1], no_edge], cache={}),
                     settings)(dropped(blind), 0.0)
    assert (e.status, e.violated, e.t_stop) == ("unsafe", "sunk", pytest.approx(Tc, abs=1e-9))

    class NoEdges(EventWindow):
        def gap(self, tau, s):
            return ca.inf

    missed = dataclasses.replace(blind, windows=[*blind.windows[:-1], NoEdges(**dataclasses.asdict(w))], cache={})
    e = SafetyOracle(missed, settings)(dropped(blind), 0.0)
    assert e.status != "unsafe"  # steps of DT from T_c: the window's middle is never inside it


def test_the_papers_land_safe_set(paper_land, tmp_path):
    """C_aerial until T_c, joint limits, C_ground from T_c + 0.16 s: safe; with eps = 0.02 s the
    contact's drift correction still moves the foot when C_ground starts: unsafe."""
    prim, settings, _ = paper_land
    Tc = touchdown(prim, settings)[0]
    e = SafetyOracle(prim, settings)(dropped(prim), 0.0)
    assert (e.status, e.reason) == ("safe", Reason.ENTERED_E) and e.t_enter > Tc + 0.16
    assert all(e.min_margins[n] is not None for n in ("above_ground[foot]", "on_ground[foot]", "foot_still[foot]"))
    short, settings, _ = land(tmp_path, "\n".join(["{use: joint_limits}", "{use: aerial, when: {before: first_touchdown}}",
                                                  "{use: ground_contact, when: {after: first_touchdown, delay: 0.02}}"]))
    e = SafetyOracle(short, settings)(dropped(short), 0.0)
    assert (e.status, e.reason, e.violated) == ("unsafe", Reason.LEFT_C, "foot_still[foot]")
    assert Tc + 0.02 - 1e-9 <= e.t_stop < Tc + 0.16


def test_an_event_window_needs_contact_events(tmp_path, capsys):
    folder = tmp_path / "off"
    folder.mkdir()
    shutil.copy(FIXTURE / "body.urdf", folder)
    path = folder / "project.yaml"
    path.write_text((FIXTURE / "project.yaml").read_text().replace("contact_events: true", "contact_events: false"))
    assert main(["verify", str(path), "--no-write", "-q"]) == 2
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith(f"{path}:")]
    assert [ln.split(" ")[0].split(":")[1] for ln in lines] == ["20", "21"]  # both windows, at their lines
    assert all(" MPG108 " in ln and "found contact_events: false" in ln for ln in lines)
    assert "safe_set.1.when" in lines[0] and "expected a rigid_body system with contact_events: true" in lines[0]
