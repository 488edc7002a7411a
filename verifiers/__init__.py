"""Plug-ins of mpgspec: oracle backends (rk4, scipy_ref; group `mpgspec.verifiers`) and
region-of-attraction verifiers (lyapunov, sos, floquet, sampling; group `mpgspec.roa`).

They import the core's contracts (mpgspec.oracle.backend, mpgspec.certify.problem); the core
never imports them.
"""
