"""Point-foot quadrupeds (the Unitree A1, ANYmal, any robot whose four legs the kinematic tree
gives): the trot, jump and land controller kinds, their stance helpers, and the gait tools behind
`mpgspec gait`."""
