"""Point-foot quadrupeds (the Unitree A1): the trot and jump controller kinds, their stance
helpers, and the gait tools behind `mpgspec gait`."""
