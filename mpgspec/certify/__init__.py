"""Sizing and certifying the explicit safe regions of attraction E (Definition 1).

problem.py is the contract RoA verifiers (plug-ins, `mpgspec.roa` entry points) implement;
registry.py loads them; roa.py gives every primitive its E; monodromy.py and hybrid_orbit.py are
the orbit numerics the assumption checks and the floquet verifier share.
"""
from .roa import RoARecord, size_regions

__all__ = ["RoARecord", "size_regions"]
