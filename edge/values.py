"""What counts as a number in a config or in model metadata, and how a bad value is shown.

Why one module: the simulator's config checks (`sim.scene`) and the model-metadata checks
(`edge.meta`) both refuse hostile values with a one-line message; both need the same answers to
"is this a number" (a bool is not, a string is not), "is it finite" (an integer too large for a
float is not, rather than an OverflowError) and "how is it quoted" (a megabyte string is cut).

Numpy only.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["show", "is_number", "is_finite"]


def show(value: Any, limit: int = 60) -> str:
    """``repr(value)`` cut to one short line (a hostile input may hold a megabyte string).

    Args:
        value: anything.
        limit: the longest result, in characters.
    """
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def is_number(value: Any) -> bool:
    """A JSON number (int or float, numpy scalars too); never a bool or a string."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def is_finite(value: Any) -> bool:
    """``value`` converts to a finite float (False for NaN, infinities and ints beyond a float)."""
    try:
        return math.isfinite(float(value))
    except OverflowError:  # an int too large for a float
        return False
