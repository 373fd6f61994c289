"""``python -m zendar_baselines [options]`` is ``zendar-bench [options]``; the form torchrun launches:
``torchrun --nproc-per-node N -m zendar_baselines ...`` (:mod:`zendar_baselines.bench.ranks`)."""

import sys

from zendar_baselines.entry import zendar_bench

if __name__ == "__main__":
    sys.exit(zendar_bench())
