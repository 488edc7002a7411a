"""Gait generation: periodic orbits of trot primitives, written as the gait tables their specs read."""
