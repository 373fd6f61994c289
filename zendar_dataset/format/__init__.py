"""Format v1 of the Zendar dataset (docs/format.md): schema, stores, writer, reader,
validation, conversion between backends and ground-truth export."""

from zendar_dataset.format.calibration import (
    Calibration,
    CameraCalibration,
    RadarCalibration,
    SensorCalibration,
)
from zendar_dataset.format.reader import DatasetIndex, SceneReader, StoredArray, open_dataset
from zendar_dataset.format.schema import FORMAT_NAME, FORMAT_VERSION, frame_id
from zendar_dataset.format.writer import DatasetWriter, SceneWriter

__all__ = [
    "Calibration",
    "CameraCalibration",
    "DatasetIndex",
    "DatasetWriter",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "RadarCalibration",
    "SceneReader",
    "SceneWriter",
    "SensorCalibration",
    "StoredArray",
    "frame_id",
    "open_dataset",
]
