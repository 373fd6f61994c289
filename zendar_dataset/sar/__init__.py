"""SAR imaging: the format's image model, time-domain backprojection, labelling helpers."""

from zendar_dataset.sar.backprojection import backproject
from zendar_dataset.sar.grid import ImageGrid

__all__ = ["ImageGrid", "backproject"]
