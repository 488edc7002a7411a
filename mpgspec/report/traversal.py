"""What each run of a goal sequence did per command (Table II of the paper): the primitives it went
through, when it reached the goal and where it first left the safe set."""
from __future__ import annotations

EPS = 1e-9


def _window(commands: list[dict], k: int, end: float) -> tuple[float, float]:
    t0 = float(commands[k]["t"])
    return t0, float(commands[k + 1]["t"]) if k + 1 < len(commands) else end


def _active_at(switches: list[dict], t: float) -> str | None:
    """The primitive a run was in just before time t."""
    prev = [s for s in switches if float(s["t"]) < t - EPS or s.get("reason") == "start"]
    return prev[-1]["to"] if prev else None


def _stopped(run: dict, t0: float, t1: float, end: float) -> float | None:
    """The time of the run's last sample when the run stopped early inside [t0, t1)."""
    t = run.get("t") or []
    last = float(t[-1]) if t else 0.0
    gap = 2 * (float(t[-1]) - float(t[-2])) if len(t) > 1 else 0.0
    return last if last < end - max(gap, 0.01) and t0 - EPS <= last < t1 + EPS else None


def command_rows(seq: dict) -> list[dict]:
    """One row per command: its time and goal and, per run, the switches made while it was the goal
    (`steps`: primitive, time, reason), when the goal was reached (`reached`: a time, 'active' when the
    run was already in it, None when it was not reached before the next command or the end), the
    first violation in that window (or None) and, when the run stopped early in it, its last time."""
    commands = sorted(seq.get("commands") or [], key=lambda c: float(c["t"]))
    runs = seq.get("runs") or {}
    end = float(seq.get("duration") or 0.0)
    rows = []
    for k, c in enumerate(commands):
        t0, t1 = _window(commands, k, end)
        last = k + 1 == len(commands)
        per_run = {}
        for mode, run in runs.items():
            sw = run.get("switches") or []
            inside = [s for s in sw if s.get("reason") != "start" and t0 - EPS <= float(s["t"])
                      and (float(s["t"]) < t1 - EPS or last and float(s["t"]) <= t1 + EPS)]
            before = _active_at(sw, t0)
            reached = "active" if before == c["goal"] and not inside else next(
                (float(s["t"]) for s in inside if s["to"] == c["goal"]), None)
            viol = next((v for v in run.get("violations") or [] if t0 - EPS <= float(v["t"]) < t1 - EPS
                         or last and float(v["t"]) >= t0 - EPS), None)
            per_run[mode] = {"steps": [{"to": s["to"], "t": float(s["t"]), "reason": s.get("reason", "")}
                                       for s in inside],
                             "from": before, "reached": reached, "violation": viol,
                             "stopped": _stopped(run, t0, t1, end)}
        rows.append({"t": float(c["t"]), "goal": c["goal"], "until": t1, "runs": per_run,
                     "reference": c.get("reference")})
    return rows
