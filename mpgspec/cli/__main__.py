"""`python -m mpgspec.cli`: the command line."""
from . import entry

entry()
