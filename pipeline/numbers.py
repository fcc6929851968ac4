"""Number types for config schemas: a YAML number that is a real number, not a boolean or a string,
and finite (``.inf``/``.nan`` are errors, not values that later show up as "the model diverges")."""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import BeforeValidator, Field


def _finite(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"expected a number, got {type(v).__name__} {v!r}"[:120])
    try:
        f = float(v)
    except OverflowError:
        raise ValueError("number too large for a double") from None
    if not math.isfinite(f):
        raise ValueError(f"expected a finite number, got {v!r}")
    return f


def _integer(v):
    if isinstance(v, bool) or not isinstance(v, int):
        if isinstance(v, float) and v.is_integer() and abs(v) < 2 ** 53:
            return int(v)
        raise ValueError(f"expected a whole number, got {type(v).__name__} {v!r}"[:120])
    return v


Finite = Annotated[float, BeforeValidator(_finite)]
Integer = Annotated[int, BeforeValidator(_integer)]
Seed = Annotated[int, BeforeValidator(_integer), Field(ge=0, lt=2 ** 32)]
