"""Checks of command-line values (``type=`` of ``add_argument``), shared by every command-line tool.

A value that fails its check stops parsing: the usage line, ``PROG: error: MESSAGE`` on one line and
exit status 2, before any work.

Examples
--------
>>> import argparse
>>> parser = argparse.ArgumentParser(prog="tool")
>>> _ = parser.add_argument("--seed", type=whole_number("--seed", 0), default=0)
>>> parser.parse_args(["--seed", "7"]).seed
7
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

#: Where the tools that compute on arrays can run (``--device``).
DEVICES = ("cpu", "cuda")


def _out_of_range(message: str) -> argparse.ArgumentError:
    # Without an argument the error prints as its message alone: "PROG: error: --seed must be ...".
    # The message names the option itself, so argparse's "argument --seed: " prefix would say it twice.
    return argparse.ArgumentError(None, message)


def _parse(text: str, kind: type) -> int | float:
    try:
        return kind(text)
    except ValueError:
        # argparse's own words for a plain type=int or type=float.
        raise argparse.ArgumentTypeError(f"invalid {kind.__name__} value: {text!r}") from None


def whole_number(option: str, minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """A ``type=`` for an integer option from ``minimum`` up (to ``maximum``, inclusive, when given).

    Parameters
    ----------
    option : str
        The option's name, which starts the message: ``--seed must be 0 or more, got -1``,
        ``--bootstrap must be between 0 and 100,000, got -3``.
    minimum, maximum : int
        The bounds.

    Returns
    -------
    callable
        Text -> int, raising argparse's errors.
    """
    requirement = f"{minimum:,} or more" if maximum is None else f"between {minimum:,} and {maximum:,}"

    def check(text: str) -> int:
        value = _parse(text, int)
        if value < minimum or (maximum is not None and value > maximum):
            raise _out_of_range(f"{option} must be {requirement}, got {value}")
        return value

    return check


def positive_number(option: str, maximum: float | None = None) -> Callable[[str], float]:
    """A ``type=`` for a finite number option above 0 (a time limit), up to ``maximum`` when given:
    ``--time-limit-s must be positive, got 0.0``, ``--time-limit-s must be a finite number, got inf``,
    ``--time-limit-s must be at most 604,800, got 1e+308`` (a timeout the OS cannot wait for)."""

    def check(text: str) -> float:
        value = _finite(option, text)
        if value <= 0:
            raise _out_of_range(f"{option} must be positive, got {value}")
        if maximum is not None and value > maximum:
            raise _out_of_range(f"{option} must be at most {maximum:,}, got {text.strip()}")
        return value

    return check


def number_between(option: str, minimum: float, maximum: float) -> Callable[[str], float]:
    """A ``type=`` for a finite number option from ``minimum`` to ``maximum``, both inclusive.

    Parameters
    ----------
    option : str
        The option's name, which starts the message: ``--tolerance-ms must be between 0 and 86,400,000, got -1``.
    minimum, maximum : float
        The bounds (pass whole numbers as ``int`` to print them without a decimal point).

    Returns
    -------
    callable
        Text -> float, raising argparse's errors.
    """

    def check(text: str) -> float:
        value = _finite(option, text)
        if not minimum <= value <= maximum:
            raise _out_of_range(f"{option} must be between {minimum:,} and {maximum:,}, got {text.strip()}")
        return value

    return check


def _finite(option: str, text: str) -> float:
    # float() takes "nan" and "inf", and a comparison with nan is always False, so bounds alone let it through.
    value = _parse(text, float)
    if not math.isfinite(value):
        raise _out_of_range(f"{option} must be a finite number, got {text.strip()}")
    return value


def seed_count(maximum: int) -> Callable[[str], int]:
    """A ``type=`` for a number of training seeds, 1 to ``maximum``."""

    def check(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number of seeds, got {text!r}") from None
        if not 1 <= value <= maximum:
            raise argparse.ArgumentTypeError(f"expected 1 to {maximum} seeds, got {value}")
        return value

    return check


def split_ratios(text: str) -> tuple[float, float, float]:
    """A ``type=`` for ``train,val,test`` shares of the scenes, e.g. ``0.6,0.2,0.2``: finite, 0 or more,
    with a positive (finite) sum."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers like 0.6,0.2,0.2, got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers (train,val,test), got {text!r}")
    # The sum is checked too: three finite shares of 1e308 add up to inf, and the shares are divided by it.
    if not all(math.isfinite(v) and v >= 0 for v in values) or not 0 < sum(values) < math.inf:
        raise argparse.ArgumentTypeError(
            f"expected finite shares of 0 or more (train,val,test) with a positive, finite sum, got {text!r}"
        )
    return values  # type: ignore[return-value]
