"""Verification backends of mpgspec, registered through the `mpgspec.verifiers` entry-point group."""
