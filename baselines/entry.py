"""Console script ``zendar-bench``: the Ctrl-C handler goes in before the heavy imports."""

from __future__ import annotations

from zendar_dataset.cli.interrupt import console_script


@console_script
def zendar_bench() -> int:
    """Console script ``zendar-bench``: Ctrl-C exits 130 from the start, imports included."""
    from zendar_baselines.bench.cli import main

    return main()
