"""zendar-dataset: loader, signal processing, simulator and official evaluator
for the Zendar high-resolution radar dataset (Mostajabi et al., CVPR-W 2020).

The headline object is :class:`ZendarDataset`; it is imported lazily so that
``import zendar_dataset`` stays cheap for tools that only need the evaluator
or the signal-processing functions.
"""

from __future__ import annotations

import os as _os
import sys as _sys

#: The console scripts of this distribution (pyproject.toml, ``[project.scripts]``).
CONSOLE_SCRIPTS = ("zendar-data", "zendar-eval", "zendar-bench", "zendar-leaderboard")

# Every console script imports this package first: run as one, Ctrl-C exits 130 without a traceback
# from here on (zendar_dataset.cli.interrupt), not only once the command's function is called after the
# imports of its module (~30 ms of a Ctrl-C ending in a traceback).
if _sys.argv and _os.path.splitext(_os.path.basename(_sys.argv[0]))[0] in CONSOLE_SCRIPTS:
    from zendar_dataset.cli.interrupt import exit_while_starting as _exit_while_starting

    _exit_while_starting()

from zendar_dataset.errors import PredictionsError, ZendarError, ZendarFormatError  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "ZendarDataset",
    "ZendarError",
    "ZendarFormatError",
    "PredictionsError",
    "__version__",
]


def __getattr__(name: str):
    # Lazy so that importing the package does not import torch.
    if name == "ZendarDataset":
        from zendar_dataset.dataset import ZendarDataset

        return ZendarDataset
    raise AttributeError(f"module 'zendar_dataset' has no attribute {name!r}")
