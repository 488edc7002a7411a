"""Robust graph: the nominal graph's edges re-checked under parameter ranges, input disturbances and
initial-state error (an adversarial falsification, never a proof).

rollout.py runs the perturbed closed loops (rigid.py those of rigid bodies: mass scale, friction,
a push on the base), scenarios.py draws the scenarios, starts.py samples start states on the
boundary of the source's region of attraction, cells.py checks one target's cells, graph.py builds
the robust graph, sequence.py runs the goal sequence under sampled uncertainty, plan.py plans on
the robust graph from a report. The `uncertainty` block itself is checked in the spec layer
(spec/uncertainty_refs.py).
"""
