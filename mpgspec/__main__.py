"""`python -m mpgspec`: the command line."""
from .cli import entry

entry()
