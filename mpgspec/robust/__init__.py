"""Robust graph: the nominal graph's edges re-checked under parameter ranges, input disturbances and
initial-state error (an adversarial falsification, never a proof).

check.py validates a project's `uncertainty` block, rollout.py runs the perturbed closed loops
(rigid.py those of rigid bodies: mass scale, friction, a push on the base), starts.py samples
start states on the boundary of the source's region of attraction, graph.py builds the robust
graph, plan.py plans on it from a report.
"""
