"""Shared pieces of the spec models: the strict base model and expression text."""
from __future__ import annotations

from typing import Union

from pydantic import BaseModel, ConfigDict

ExprText = Union[str, float, int]
"""An expression in the whitelisted grammar (mpgspec.spec.expr) or a number."""


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)


# ----------------------------------------------------------------------------- system
