"""Sizing and certifying the explicit safe regions of attraction E (Definition 1)."""
from .roa import RoARecord, size_regions

__all__ = ["RoARecord", "size_regions"]
