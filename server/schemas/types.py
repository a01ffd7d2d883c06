"""Strict scalar types for request bodies: JSON `true` is not the number 1, `1.5` is not an
integer, and a number is finite (JSON has no NaN or Infinity; Python's parser accepts them)."""

from typing import Annotated

from pydantic import Field, StringConstraints

Int = Annotated[int, Field(strict=True)]
Number = Annotated[float, Field(strict=True, allow_inf_nan=False)]
Key = Annotated[str, StringConstraints(min_length=1, max_length=64)]
"""A key of a body's map (a config field, a text's name)."""
