"""Radar signal processing: FMCW model, range-Doppler compression, CFAR, direction of arrival.

Pure array math on numpy, with torch paths (CPU and CUDA) where a batched GPU
chain pays (:mod:`zendar_dataset.radar.batched_chain`, imported on its own so that
importing this package does not import torch).
"""

from zendar_dataset.radar.cfar import CfarDetections, CfarResult, cfar_2d, detect, window_misfit
from zendar_dataset.radar.doa import detections_to_points, estimate_azimuth, is_centro_symmetric, steering_vectors
from zendar_dataset.radar.fmcw import CALIBRATION_KEYS, SPEED_OF_LIGHT_MPS, FmcwParams, beat_signal_exact
from zendar_dataset.radar.range_doppler import range_axis_m, range_doppler, range_profiles, velocity_axis_mps

__all__ = [
    "CALIBRATION_KEYS",
    "SPEED_OF_LIGHT_MPS",
    "CfarDetections",
    "CfarResult",
    "FmcwParams",
    "beat_signal_exact",
    "cfar_2d",
    "detect",
    "detections_to_points",
    "estimate_azimuth",
    "is_centro_symmetric",
    "range_axis_m",
    "range_doppler",
    "range_profiles",
    "steering_vectors",
    "velocity_axis_mps",
    "window_misfit",
]
