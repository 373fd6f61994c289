"""zendar-dataset: loader, signal processing, simulator and official evaluator
for the Zendar high-resolution radar dataset (Mostajabi et al., CVPR-W 2020).

The headline object is :class:`ZendarDataset`; it is imported lazily so that
``import zendar_dataset`` stays cheap for tools that only need the evaluator
or the signal-processing functions.
"""

from __future__ import annotations

from zendar_dataset.errors import PredictionsError, ZendarError, ZendarFormatError

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
