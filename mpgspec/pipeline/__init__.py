"""The stages of a build and their typed results, in order: load (spec.loader), settings
(settings.py), compile and regions of attraction, oracle and traces, then the checks: plans,
sequence, cross-check, robust graph, assumptions (stages.py); the report of a project
(project.py); what a run returns (results.py); plans and sequence runs that reuse a verified
report (reuse.py, plan.py, simulate.py).

Importing the package imports none of its stages: mpgspec.api reads a report without CasADi."""
