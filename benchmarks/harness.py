"""What every benchmark script shares: timing with spread, load average, versions, threads.

Figures on a shared machine swing by 2x, so each script times the package and its
references in the same run, interleaved where the cost allows, and reports the
min / median / max of several repeats rather than the best. The load average is
printed before and after: a figure taken at a load above the CPU count is an
upper bound on the time, not the time.
"""

from __future__ import annotations

import importlib.metadata
import os
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Spread:
    """Minimum, median and maximum of repeated measurements (seconds, or any unit)."""

    min: float
    median: float
    max: float
    repeats: int

    @classmethod
    def of(cls, values: Sequence[float]) -> "Spread":
        if not values:
            raise ValueError("a spread needs at least one value")
        return cls(min(values), statistics.median(values), max(values), len(values))

    def scaled(self, factor: float) -> "Spread":
        """The same spread in other units (e.g. ``1e3`` for milliseconds)."""
        return Spread(self.min * factor, self.median * factor, self.max * factor, self.repeats)

    def text(self, fmt: str = ".3g") -> str:
        """``median (min-max)``, the form every table in the benchmarks uses."""
        return f"{self.median:{fmt}} ({self.min:{fmt}}-{self.max:{fmt}})"


def time_calls(fn: Callable[[], Any], repeats: int, warmup: int = 1) -> Spread:
    """Wall seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return Spread.of(times)


def interleaved(fns: dict[str, Callable[[], Any]], repeats: int, warmup: int = 1) -> dict[str, Spread]:
    """Wall seconds of each of ``fns``, called in turn ``repeats`` times, so that all
    of them see the same moments of a shared machine's load."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: Spread.of(values) for name, values in times.items()}


def load_average() -> str:
    """``1-min, 5-min, 15-min load on N CPUs``."""
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f}, {five:.2f}, {fifteen:.2f} (1, 5, 15 min) on {os.cpu_count()} CPUs"


def version(distribution: str) -> str | None:
    """Installed version of a distribution, or None when it is not installed."""
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def print_environment(distributions: Sequence[str]) -> None:
    """Print the load average and the versions of ``distributions`` (``missing`` when absent)."""
    print(f"load average before: {load_average()}")
    versions = ", ".join(f"{name} {version(name) or 'missing'}" for name in distributions)
    print(f"versions: {versions}")


def print_load_after() -> None:
    print(f"load average after:  {load_average()}")


def missing_peer(distribution: str, row: str) -> None:
    """The one line a script prints instead of a row whose peer package is not installed."""
    print(f"skipped: {row} -- {distribution} is not installed (pip install -e '.[bench]', see benchmarks/README.md)")
