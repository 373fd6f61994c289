"""Format v1 as data: names, dtypes and shapes of every array (docs/format.md).

The writer, the reader and the validator all read these tables, so the
format is spelled out once.  Shapes are tuples whose entries are

- ``"N"``: the number of elements of the stream (the length of its ``timestamp_ns``),
- ``"N+1"``: one more than that (lidar ``offsets``),
- ``"P"``: a free length (lidar points),
- an ``int``: that exact size,
- ``None``: any size, the same for every element of the stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FORMAT_NAME = "zendar-dataset"
FORMAT_VERSION = 1
TIME_REFERENCE = "gps"
DATASET_JSON = "dataset.json"
SPLITS = ("train", "val", "test")
BACKEND_SUFFIX = {"zarr": ".zarr", "hdf5": ".h5"}

SCENE_ATTRS = ("scene_id", "time_reference", "enu_origin")
ENU_ORIGIN_KEYS = ("lat_deg", "lon_deg", "height_m")
CALIBRATION_GROUP = "calibration"
CALIBRATION_ATTR = "calibration"

SENSOR_GROUPS = ("radar", "sar", "camera", "lidar")
# Optional per-sensor groups that hold no frames of their own (written by ``import-release``).
DETECTIONS = "detections"
CAMERA_INDEX = "camera_index"
EXTRA_SENSOR_GROUPS = (DETECTIONS, CAMERA_INDEX)
TRACKLOG = "tracklog"
LABELS = "labels/moving_cars"


@dataclass(frozen=True)
class ArraySpec:
    """Name, dtype and shape rule of one array of a stream."""

    name: str
    dtype: np.dtype
    shape: tuple

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def describe(self) -> str:
        """The spec as written in docs/format.md, e.g. ``[N, 3] float64``."""
        dims = ", ".join("any" if d is None else str(d) for d in self.shape)
        return f"[{dims}] {self.dtype.name}"


def _spec(name: str, dtype: str, *shape) -> ArraySpec:
    return ArraySpec(name, np.dtype(dtype), tuple(shape))


TIMESTAMP = _spec("timestamp_ns", "int64", "N")

STREAM_ARRAYS: dict[str, tuple[ArraySpec, ...]] = {
    "radar": (TIMESTAMP, _spec("cube", "complex64", "N", None, None, None)),
    "sar": (
        TIMESTAMP,
        _spec("image", "complex64", "N", None, None),
        _spec("origin_ecef", "float64", "N", 3),
        _spec("di_ecef", "float64", "N", 3),
        _spec("dj_ecef", "float64", "N", 3),
        _spec("aperture_ns", "int64", "N", 2),
    ),
    "camera": (TIMESTAMP, _spec("image", "uint8", "N", None, None, 3)),
    "lidar": (TIMESTAMP, _spec("points", "float32", "P", 4), _spec("offsets", "int64", "N+1")),
    DETECTIONS: (
        TIMESTAMP,
        _spec("offsets", "int64", "N+1"),
        _spec("range_m", "float32", "P"),
        _spec("azimuth_rad", "float32", "P"),
        _spec("elevation_rad", "float32", "P"),
        _spec("range_velocity_mps", "float32", "P"),
        _spec("magnitude", "float32", "P"),
        _spec("snr", "float32", "P"),
        _spec("position_ecef", "float64", "P", 3),
    ),
    CAMERA_INDEX: (TIMESTAMP, _spec("frame_index", "int64", "N")),
    TRACKLOG: (
        TIMESTAMP,
        _spec("position_ecef", "float64", "N", 3),
        _spec("attitude_wxyz", "float64", "N", 4),
    ),
}

LABEL_FIELDS: tuple[ArraySpec, ...] = (
    TIMESTAMP,
    _spec("x", "float64", "N"),
    _spec("y", "float64", "N"),
    _spec("length", "float64", "N"),
    _spec("width", "float64", "N"),
    _spec("yaw", "float64", "N"),
    _spec("vx", "float64", "N"),
    _spec("vy", "float64", "N"),
    _spec("track_id", "int64", "N"),
)
LABEL_FIELD_NAMES = tuple(spec.name for spec in LABEL_FIELDS)
# Magnitude-only SAR images (a backward-compatible addition): ``sar/<radar>/image`` may hold the
# recording's real magnitudes as recorded, exactly, when the group's ``magnitude_only`` is true.
SAR_MAGNITUDE_ONLY_ATTR = "magnitude_only"
SAR_MAGNITUDE_DTYPES: tuple[np.dtype, ...] = (np.dtype("uint32"), np.dtype("float32"))
SAR_IMAGE_DTYPES: tuple[np.dtype, ...] = (np.dtype("complex64"), *SAR_MAGNITUDE_DTYPES)
# Optional per-frame arrays of a SAR stream (a backward-compatible addition): ego_stopped marks the
# frames whose synthetic aperture includes a moment when the ego stood still.
SAR_OPTIONAL_ARRAYS: tuple[ArraySpec, ...] = (_spec("ego_stopped", "bool", "N"),)
# Optional label fields (a backward-compatible addition): how visible each car is, as nuScenes'
# num_radar_pts / num_lidar_pts.  Written when known, passed through to ground truth.
LABEL_OPTIONAL_FIELDS: tuple[ArraySpec, ...] = (
    _spec("num_radar_scatterers", "int64", "N"),
    _spec("num_lidar_points", "int64", "N"),
)
LABEL_OPTIONAL_FIELD_NAMES = tuple(spec.name for spec in LABEL_OPTIONAL_FIELDS)
# Fields of one car in ground truth and predictions (everything but the frame's timestamp).
CAR_FIELDS = tuple(name for name in LABEL_FIELD_NAMES if name != "timestamp_ns")


def optional_specs(stream: str) -> tuple[ArraySpec, ...]:
    """The optional arrays of a stream path (checked when present): label fields, SAR frame flags."""
    if stream == LABELS:
        return LABEL_OPTIONAL_FIELDS
    return SAR_OPTIONAL_ARRAYS if stream.split("/", 1)[0] == "sar" else ()


def accepted_dtypes(stream: str, spec: ArraySpec) -> tuple[np.dtype, ...]:
    """The dtypes an array may have: its spec's, and for a SAR ``image`` also the magnitude dtypes."""
    if spec.name == "image" and stream.split("/", 1)[0] == "sar":
        return SAR_IMAGE_DTYPES
    return (spec.dtype,)


def stream_specs(stream: str) -> tuple[ArraySpec, ...]:
    """Array specs of a stream path such as ``"radar/left"``, ``"tracklog"`` or ``LABELS``."""
    if stream == LABELS:
        return LABEL_FIELDS
    group = stream.split("/", 1)[0]
    if group not in STREAM_ARRAYS:
        raise KeyError(stream)
    return STREAM_ARRAYS[group]


def expected_first_dim(spec: ArraySpec, n_elements: int) -> int | None:
    """Length the first axis of ``spec`` must have in a stream of ``n_elements``."""
    first = spec.shape[0]
    if first == "N":
        return n_elements
    if first == "N+1":
        return n_elements + 1
    return None


def frame_id(scene_id: str, timestamp_ns: int) -> str:
    """The identifier of a frame everywhere: ``"<scene_id>/<timestamp_ns>"``."""
    return f"{scene_id}/{int(timestamp_ns)}"
