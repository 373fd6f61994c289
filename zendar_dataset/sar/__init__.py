"""SAR imaging: the format's image model, time-domain backprojection, labelling helpers."""

from zendar_dataset.sar.backprojection import backproject
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sar.labeling import local_snr_db, noise_power, project_points, snr_at_points_db

__all__ = ["ImageGrid", "backproject", "local_snr_db", "noise_power", "project_points", "snr_at_points_db"]
