"""Radar signal processing: FMCW model, range-Doppler compression, CFAR, direction of arrival.

Pure array math on numpy, with torch paths (CPU and CUDA) where a batched GPU
chain pays. Importing this package does not import torch.
"""

from zendar_dataset.radar.fmcw import CALIBRATION_KEYS, SPEED_OF_LIGHT_MPS, FmcwParams, beat_signal_exact

__all__ = ["CALIBRATION_KEYS", "SPEED_OF_LIGHT_MPS", "FmcwParams", "beat_signal_exact"]
