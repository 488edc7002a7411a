"""mpgspec: verify safe transitions between motion primitives and build the motion primitive graph."""
__version__ = "0.1.0"
