"""`mpgspec simulate`: the goal sequence naive and through the graph (or under seeded draws of the
project's uncertainty), through mpgspec.api.simulate and mpgspec.api.simulate_uncertain."""
from __future__ import annotations

import json

from .. import api
from ..errors import EXIT_CHECK_FAILED, EXIT_OK
from ..streams import stdout_to_stderr
from .plan import notifier


def cmd_simulate(args) -> int:
    if args.uncertain:
        return _simulate_uncertain(args)
    modes = ("naive", "graph") if args.mode == "both" else (args.mode,)
    with stdout_to_stderr():
        sim = api.simulate(args.project, modes, args.out, args.rebuild, args.crosscheck, notifier(args),
                           args.runs, args.seed)
    runs, expect, xc = sim["runs"], sim["expected"], sim["crosscheck"]
    ok = {m: r.safe == expect.get(m, True) for m, r in runs.items()}
    args.exit_code = EXIT_OK if all(ok.values()) and (xc is None or all(x["agree"] for x in xc.values())) \
        else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({m: {**{k: v for k, v in r.to_dict().items() if k in (
            "mode", "safe", "switches", "violations", "final_primitive", "failed")},
            "expected_safe": expect.get(m, True), "as_expected": ok[m],
            **({"crosscheck": {k: v for k, v in xc[m].items() if k != "series"}} if xc is not None else {})}
            for m, r in runs.items()}, indent=1, default=float))
    else:
        for m, r in runs.items():
            note = "as expected" if ok[m] else f"NOT as expected: the project expects it to be " \
                                                f"{'safe' if expect.get(m, True) else 'unsafe'}"
            print(f"{m}: {'safe' if r.safe else 'UNSAFE'}; ends in {r.final_primitive} ({note})")
            for sw in r.switches:
                print(f"    t = {sw['t']:7.3f} s  -> {sw['to']} (clock {sw['clock']:.3f}; {sw['reason']})")
            if r.violations:
                v = r.violations[0]
                print(f"    first violation: {v['h']} of {v['primitive']} at t = {v['t']:.3f} s ({v['value']:.3g})")
            if xc is not None:
                print("    " + _crosscheck_line(xc[m]))
    return args.exit_code


def _simulate_uncertain(args) -> int:
    """The fraction of seeded runs that stay safe naive, through the nominal graph and through the
    robust graph. Exit 0 when every robust-graph run stays safe."""
    with stdout_to_stderr():
        sim = api.simulate_uncertain(args.project, args.runs, args.seed, args.out, args.rebuild, args.crosscheck,
                                     notifier(args))
    stats, unc, runs, seed = sim["stats"], sim["uncertainty"], sim["runs"], sim["seed"]
    modes = stats["modes"]
    args.exit_code = EXIT_OK if modes["robust_graph"]["safe_runs"] == runs else EXIT_CHECK_FAILED
    if args.format == "json":
        print(json.dumps({**stats, "modes": {m: {k: v for k, v in r.items() if k != "final"} for m, r in modes.items()},
                          "uncertainty": {"parameters": {n: list(r.range) for n, r in unc.parameters.items()},
                                          "initial_state": dict(unc.initial_state),
                                          "disturbance": unc.disturbance.model_dump() if unc.disturbance else None}},
                         indent=1))
        return args.exit_code
    window = stats.get("disturbance_after_switch_in_s")
    held = (f"a push on for {window:g} s after every switch-in, each value held {stats['disturbance_hold_s']:g} s"
            if window else f"a disturbance held {stats['disturbance_hold_s']:g} s")
    print(f"{runs} seeded runs (seed {seed}) of the goal sequence: parameters, start error and {held}, "
          "drawn uniformly from the project's uncertainty")
    for m, r in modes.items():
        first = r["first_violation"][0] if r["first_violation"] else None
        why = "" if first is None else (f"; first unsafe at t = {first['t']:.3f} s in {first['primitive']}"
                                        + (f" ({first['h']} = {first['value']:.4g})" if first.get("h") else "")
                                        + (f" ({first['error']})" if first.get("error") else "")
                                        + (f" (unverified hand-over to {first['unverified_hand_over']})"
                                           if first.get("unverified_hand_over") else ""))
        print(f"  {m.replace('_', ' '):13} {r['safe_runs']:>5} / {r['runs']} safe ({100 * r['safe_fraction']:.1f} %), "
              f"{r.get('reached_goal', 0)} safe and in every goal{why}")
    return args.exit_code


def _crosscheck_line(x: dict) -> str:
    """One replayed run: the simulator's verdict, agreement and the largest divergences."""
    fv, dv = x["mujoco"]["first_violation"], x["divergence"]
    verdict = "safe" if x["mujoco"]["safe"] else "UNSAFE" + (
        f" (first: {fv['h']} of {fv['primitive']} at t = {fv['t']:.3f} s)" if fv else f" ({x['mujoco']['failed']})")
    com = f"{1000 * dv['com']['max']:.3g} mm" if dv["com"] else "-"
    joint = f"{dv['joint']['max']:.3g} rad" if dv["joint"] else "-"
    return (f"MuJoCo: {verdict}; {'agrees' if x['agree'] else 'DISAGREES'}; largest divergence: CoM {com}, "
            f"joints {joint}")
