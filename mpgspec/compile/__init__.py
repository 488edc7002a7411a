"""Compile a project's primitives (Definition 1) into CasADi Functions: the system (system.py, a
registry of system kinds; rigidbody/ for URDF robots), the control laws (laws/, a registry of
controller kinds), the contact plan (contacts.py), the setpoint (setpoint.py) and the closed loop
with its safe set and E (primitive.py, closed_loop.py). Nothing here integrates."""
