"""Console script ``zendar-bench``: the Ctrl-C handler goes in before the heavy imports."""

from __future__ import annotations

import sys

from zendar_dataset.cli.interrupt import console_script


@console_script
def zendar_bench() -> int:
    """Console script ``zendar-bench``: Ctrl-C exits 130 from the start, imports included; numerics
    pinned to the AVX2 paths before numpy and torch load (:mod:`zendar_baselines.cnn.numerics`)."""
    from zendar_baselines.cnn.numerics import pin_portable_numerics

    pin_portable_numerics(sys.argv[1:])
    from zendar_baselines.bench.cli import main

    return main()
