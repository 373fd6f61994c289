"""Console script ``zendar-bench``: the Ctrl-C handler goes in before the heavy imports."""

from __future__ import annotations

from zendar_dataset.cli.interrupt import exit_while_starting


def zendar_bench() -> int:
    """Console script ``zendar-bench``."""
    exit_while_starting()
    from zendar_baselines.bench.cli import main

    return main()
