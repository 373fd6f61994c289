"""Array coercion shared by every layer (pure numpy, no I/O).

It sits beside ``errors.py`` at the bottom of the layering so that the record
checks of ``radar/`` and ``format/`` can share it without importing each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def float64_array_or_none(value: Any) -> np.ndarray | None:
    """A float64 copy of ``value``, or ``None`` where numpy cannot read it as numbers.

    Callers check the shape themselves and name the field in their own message,
    so a ragged or non-numeric input is not an exception here.

    Parameters
    ----------
    value : array_like
        Nested sequences or an array of numbers.

    Returns
    -------
    numpy.ndarray or None
        float64, the shape of ``value``; a new array the caller may freeze or keep.
    """
    try:
        return np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError):
        return None
