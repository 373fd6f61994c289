"""Writing format-v1 scenes and datasets.

A scene is written under a hidden temporary sibling of its final path and
renamed into place by :meth:`SceneWriter.close`, so an interrupted write never
leaves a store at the final path; ``dataset.json`` is written last and
atomically by :meth:`DatasetWriter.finalize` and lists only completed scenes.

Example
-------
>>> with SceneWriter(path, "scene-0001", enu_origin=origin, calibration=calib) as scene:  # doctest: +SKIP
...     scene.append_radar("left", timestamp_ns, cube)
"""

from __future__ import annotations

import os
import pathlib
from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Any

import numpy as np

from zendar_dataset import temporary_files as temporary
from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import checksums, stores
from zendar_dataset.format.calibration import CameraCalibration, Calibration, RadarCalibration
from zendar_dataset.format.schema import (
    BACKEND_SUFFIX,
    CALIBRATION_ATTR,
    CALIBRATION_GROUP,
    CAMERA_INDEX,
    DATASET_JSON,
    DETECTIONS,
    ENU_ORIGIN_KEYS,
    FORMAT_NAME,
    FORMAT_VERSION,
    LABEL_FIELDS,
    LABEL_OPTIONAL_FIELDS,
    LABELS,
    SAR_MAGNITUDE_DTYPES,
    SAR_MAGNITUDE_ONLY_ATTR,
    SPLITS,
    STREAM_ARRAYS,
    TIME_REFERENCE,
    TRACKLOG,
)

LIDAR_CHUNK_ROWS = 65536
# Lidar rows are buffered up to 16 chunks (16 MiB) per write: each write resizes the array (a metadata
# rewrite) and zarr compresses the chunks of one write concurrently.
_LIDAR_FLUSH_ROWS = 16 * LIDAR_CHUNK_ROWS
SMALL_CHUNK_ROWS = 65536
_QUATERNION_NORM_TOLERANCE = 1e-6


def check_scene_id(scene_id: Any) -> str:
    """``scene_id`` when it can name a scene's store (a non-empty string without ``/``, not starting
    with ``.``); else :class:`ZendarFormatError`."""
    if not isinstance(scene_id, str) or not scene_id or "/" in scene_id or scene_id.startswith("."):
        raise ZendarFormatError(
            f"scene_id: expected a non-empty string without '/' and not starting with '.', found {scene_id!r}"
        )
    return scene_id


def _check_enu_origin(scene_id: str, enu_origin: Any) -> dict[str, float]:
    if not isinstance(enu_origin, dict) or set(enu_origin) != set(ENU_ORIGIN_KEYS):
        found = sorted(enu_origin) if isinstance(enu_origin, dict) else type(enu_origin).__name__
        raise ZendarFormatError(f"{scene_id}: enu_origin: expected keys {list(ENU_ORIGIN_KEYS)}, found {found}")
    out = {}
    for key in ENU_ORIGIN_KEYS:
        value = enu_origin[key]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) or not np.isfinite(value):
            raise ZendarFormatError(f"{scene_id}: enu_origin.{key}: expected a finite number, found {value!r}")
        out[key] = float(value)
    return out


def _as(value: Any, dtype: str, shape: tuple, what: str) -> np.ndarray:
    """``value`` as an array of ``dtype`` with ``shape`` (None = any size), without unsafe casts."""
    array = np.asarray(value)
    target = np.dtype(dtype)
    if not np.can_cast(array.dtype, target, casting="same_kind"):
        raise ZendarFormatError(f"{what}: expected {target.name}, found {array.dtype.name}")
    if array.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, array.shape)):
        expected = ", ".join("any" if s is None else str(s) for s in shape)
        raise ZendarFormatError(f"{what}: expected shape [{expected}], found {list(array.shape)}")
    return np.ascontiguousarray(array, dtype=target)


@dataclass
class _Stream:
    """What the writer holds for one stream until close: small per-frame arrays are buffered."""

    path: str
    timestamps: list[int] = field(default_factory=list)
    small: dict[str, list[np.ndarray]] = field(default_factory=dict)
    bulk: Any = None
    bulk_path: str = ""  # where ``bulk`` is, below the scene's root
    appender: stores.FrameAppender | None = None  # appends to ``bulk`` when it is stored one frame per chunk
    frame_shape: tuple[int, ...] | None = None
    pending_points: list[np.ndarray] = field(default_factory=list)
    pending_rows: int = 0
    written_rows: int = 0
    bulk_crc32c: list[int] = field(default_factory=list)  # one per chunk of ``bulk`` written so far
    offsets: list[int] = field(default_factory=lambda: [0])
    made_dirs: set[pathlib.Path] = field(default_factory=set)  # folders of ``bulk``'s chunks made so far


class SceneWriter:
    """Write one scene store (zarr directory or HDF5 file).

    Parameters
    ----------
    path : path-like
        Final store path, ``…/<scene_id>.zarr`` or ``…/<scene_id>.h5``.
    scene_id : str
        The scene's identifier (no ``/``).
    enu_origin : dict
        ``{"lat_deg", "lon_deg", "height_m"}`` (WGS-84) of the scene's local ENU frame.
    calibration : dict or Calibration
        ``{"sensors": {name: {...}}}``; every sensor written must appear here with
        the right kind (radars with radar fields, cameras with intrinsics, ``"imu"`` for the tracklog).
    backend : {"zarr", "hdf5"}, optional
        Defaults to the one named by the suffix of ``path``.
    overwrite : bool
        Replace an existing scene at ``path`` (only once this one is complete).

    Notes
    -----
    Use as a context manager: leaving the block normally calls :meth:`close`
    (finalise and rename into place), leaving it with an exception calls
    :meth:`abort` (the temporary store is removed).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        scene_id: str,
        *,
        enu_origin: dict,
        calibration: dict | Calibration,
        backend: str | None = None,
        overwrite: bool = False,
    ) -> None:
        self.path = pathlib.Path(path)
        self.scene_id = check_scene_id(scene_id)
        self.backend = backend or stores.backend_from_path(self.path)
        if self.backend not in stores.BACKENDS:
            raise ValueError(f"unknown backend {self.backend!r}; expected one of {stores.BACKENDS}")
        self.overwrite = overwrite
        if self.path.exists() and not overwrite:
            raise FileExistsError(f"{self.path}: a scene exists already (pass overwrite=True to replace it)")
        self.enu_origin = _check_enu_origin(self.scene_id, enu_origin)
        self.calibration = (
            calibration if isinstance(calibration, Calibration) else Calibration.from_json(calibration)
        )
        self.completed = False
        self._closed = False
        self._streams: dict[str, _Stream] = {}
        self._tracklog_written = False
        self._labels: dict[str, np.ndarray] | None = None
        self._pending_small: list[stores.NewArray] = []  # written by _flush_small
        self.path.parent.mkdir(parents=True, exist_ok=True)
        temporary.remove_stale_temporaries(self.path.parent, self.path.name)  # left by a killed writer
        self._temp_path = temporary.temporary_sibling(self.path)
        try:
            self._store = stores.create_store(self._temp_path, self.backend)
            root = self._store.root
            stores.merge_attrs(
                root,
                "",
                {
                    "scene_id": self.scene_id,
                    "time_reference": TIME_REFERENCE,
                    "enu_origin": self.enu_origin,
                    checksums.ROOT_ATTR: checksums.ALGORITHM,
                },
            )
            stores.merge_attrs(root, CALIBRATION_GROUP, {CALIBRATION_ATTR: self.calibration.to_json()})
        except BaseException:
            # No ``with`` block owns the store yet (a full disk, Ctrl-C): discard it here.
            if hasattr(self, "_store"):
                self.abort()
            else:
                temporary.remove_temporary(self._temp_path)
            raise

    # -- context manager -------------------------------------------------
    def __enter__(self) -> "SceneWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- streams -----------------------------------------------------------
    def _stream(self, group: str, sensor: str, kind: type | None) -> _Stream:
        if self._closed:
            raise RuntimeError(f"{self.scene_id}: the writer is closed")
        if not isinstance(sensor, str) or not sensor or "/" in sensor:
            raise ZendarFormatError(f"{self.scene_id}: {group}: expected a sensor name without '/', found {sensor!r}")
        path = f"{group}/{sensor}"
        if path not in self._streams:
            calibration = self.calibration.sensors.get(sensor)
            if calibration is None or (kind is not None and not isinstance(calibration, kind)):
                wanted = "a calibration entry" if kind is None else f"a {kind.__name__} entry"
                raise ZendarFormatError(
                    f"{self.scene_id}: {path}: expected {wanted} for sensor {sensor!r} in the calibration, "
                    f"found {type(calibration).__name__ if calibration is not None else 'none'}"
                )
            self._streams[path] = _Stream(path)
        return self._streams[path]

    def _stamp(self, stream: _Stream, timestamp_ns: Any) -> None:
        if isinstance(timestamp_ns, bool) or not isinstance(timestamp_ns, (int, np.integer)):
            raise ZendarFormatError(
                f"{self.scene_id}: {stream.path}/timestamp_ns: expected an int64 nanosecond count, found {timestamp_ns!r}"
            )
        timestamp_ns = int(timestamp_ns)
        if stream.timestamps and timestamp_ns <= stream.timestamps[-1]:
            raise ZendarFormatError(
                f"{self.scene_id}: {stream.path}/timestamp_ns: expected strictly increasing timestamps, "
                f"found {timestamp_ns} after {stream.timestamps[-1]}"
            )
        stream.timestamps.append(timestamp_ns)

    def _append_frame(self, stream: _Stream, timestamp_ns: Any, name: str, frame: np.ndarray, kind: str) -> None:
        """Stamp and append one frame to a bulk array stored one frame per chunk.

        A frame of the wrong shape is rejected without its timestamp, so the stream stays consistent.
        """
        self._stamp(stream, timestamp_ns)
        if stream.bulk is None:
            stream.frame_shape = frame.shape
            stream.bulk_path = f"{stream.path}/{name}"
            stream.bulk = stores.create_array(
                self._store.root,
                stream.bulk_path,
                shape=(0, *frame.shape),
                dtype=frame.dtype,
                chunks=(1, *frame.shape),
                kind=kind,
                resizable=True,
            )
            stream.appender = stores.FrameAppender(stream.bulk)
        elif frame.shape != stream.frame_shape:
            stream.timestamps.pop()
            raise ZendarFormatError(
                f"{self.scene_id}: {stream.path}/{name}: expected every frame of shape {list(stream.frame_shape)}, "
                f"found {list(frame.shape)}"
            )
        stream.appender.append(frame)
        self._store.raise_if_failed()  # disk full: stop now, not after writing the rest into the void
        stream.bulk_crc32c.append(checksums.crc32c(frame))  # the frame is the chunk

    def append_radar(self, sensor: str, timestamp_ns: int, cube: np.ndarray) -> None:
        """Append a range-Doppler cube ``[R, D, A]`` complex64 stamped at the centre of its chirps."""
        stream = self._stream("radar", sensor, RadarCalibration)
        cube = _as(cube, "complex64", (None, None, None), f"{self.scene_id}: {stream.path}/cube")
        antennas = self.calibration.radar(sensor).rx_positions_m.shape[0]
        if cube.shape[2] != antennas:
            raise ZendarFormatError(
                f"{self.scene_id}: {stream.path}/cube: expected A={antennas} antennas (rx_positions_m), "
                f"found {cube.shape[2]}"
            )
        self._append_frame(stream, timestamp_ns, "cube", cube, stores.RAW)

    def append_sar(
        self,
        sensor: str,
        timestamp_ns: int,
        image: np.ndarray,
        origin_ecef: Any,
        di_ecef: Any,
        dj_ecef: Any,
        aperture_ns: Any,
        ego_stopped: bool | None = None,
        *,
        magnitude_only: bool = False,
    ) -> None:
        """Append a SAR image ``[H, W]`` complex64; pixel (i, j) is at origin + i·di + j·dj (ECEF, m).

        ``aperture_ns`` is the (start, end) GPS time of the synthetic aperture. ``ego_stopped``
        (optional, docs/format.md): whether the ego stood still at some moment of the aperture;
        given for every frame of the stream or for none. ``magnitude_only``: the image holds real
        magnitudes (uint32 or float32), stored exactly as given; the stream's group then gets
        ``magnitude_only: true`` (docs/format.md). Every frame of a stream has the same dtype.
        """
        stream = self._stream("sar", sensor, RadarCalibration)
        where = f"{self.scene_id}: {stream.path}"
        image = np.asarray(image)
        if magnitude_only and image.dtype not in SAR_MAGNITUDE_DTYPES:
            raise ZendarFormatError(
                f"{where}/image: expected real magnitudes ({' or '.join(d.name for d in SAR_MAGNITUDE_DTYPES)}) "
                f"for a magnitude-only image, found {image.dtype.name}"
            )
        image = _as(image, image.dtype.name if magnitude_only else "complex64", (None, None), f"{where}/image")
        if stream.bulk is not None and np.dtype(stream.bulk.dtype) != image.dtype:
            raise ZendarFormatError(
                f"{where}/image: expected every frame of the stream as {np.dtype(stream.bulk.dtype).name} "
                f"(magnitude_only={np.dtype(stream.bulk.dtype) in SAR_MAGNITUDE_DTYPES}), found {image.dtype.name}"
            )
        if stream.timestamps and ("ego_stopped" in stream.small) != (ego_stopped is not None):
            raise ZendarFormatError(
                f"{where}/ego_stopped: expected a value for every frame of the stream or for none, found "
                f"{'none' if ego_stopped is None else 'one'} after {len(stream.timestamps)} frames "
                f"{'with' if 'ego_stopped' in stream.small else 'without'}"
            )
        if ego_stopped is not None and not isinstance(ego_stopped, (bool, np.bool_)):
            raise ZendarFormatError(f"{where}/ego_stopped: expected a bool, found {ego_stopped!r}")
        vectors = {
            name: _as(value, "float64", (3,), f"{where}/{name}")
            for name, value in (("origin_ecef", origin_ecef), ("di_ecef", di_ecef), ("dj_ecef", dj_ecef))
        }
        for name, vector in vectors.items():
            if not np.all(np.isfinite(vector)):
                raise ZendarFormatError(f"{where}/{name}: expected finite metres, found {vector.tolist()}")
        aperture = _as(aperture_ns, "int64", (2,), f"{where}/aperture_ns")
        if aperture[0] > aperture[1]:
            raise ZendarFormatError(f"{where}/aperture_ns: expected start <= end, found {aperture.tolist()}")
        self._append_frame(stream, timestamp_ns, "image", image, stores.RAW)
        for name, vector in (*vectors.items(), ("aperture_ns", aperture)):
            stream.small.setdefault(name, []).append(vector)
        if ego_stopped is not None:
            stream.small.setdefault("ego_stopped", []).append(np.bool_(ego_stopped))

    def append_camera(self, sensor: str, timestamp_ns: int, image: np.ndarray) -> None:
        """Append a camera image ``[H, W, 3]`` uint8 (RGB)."""
        stream = self._stream("camera", sensor, CameraCalibration)
        image = np.asarray(image)
        where = f"{self.scene_id}: {stream.path}/image"
        if image.dtype != np.uint8:
            raise ZendarFormatError(f"{where}: expected uint8, found {image.dtype.name}")
        image = _as(image, "uint8", (None, None, 3), where)
        calibration = self.calibration.camera(sensor)
        if image.shape[:2] != (calibration.height, calibration.width):
            raise ZendarFormatError(
                f"{where}: expected [height={calibration.height}, width={calibration.width}, 3] from the calibration, "
                f"found {list(image.shape)}"
            )
        self._append_frame(stream, timestamp_ns, "image", image, stores.FAST)

    def append_lidar(self, sensor: str, timestamp_ns: int, points: np.ndarray) -> None:
        """Append a lidar sweep ``[P, 4]`` float32 (x, y, z in the lidar frame in metres, intensity)."""
        stream = self._stream("lidar", sensor, None)
        points = _as(points, "float32", (None, 4), f"{self.scene_id}: {stream.path}/points")
        self._stamp(stream, timestamp_ns)
        if stream.bulk is None:
            stream.bulk_path = f"{stream.path}/points"
            stream.bulk = stores.create_array(
                self._store.root,
                stream.bulk_path,
                shape=(0, 4),
                dtype=np.dtype(np.float32),
                chunks=(LIDAR_CHUNK_ROWS, 4),
                kind=stores.FAST,
                resizable=True,
            )
        stream.offsets.append(stream.offsets[-1] + points.shape[0])
        stream.pending_points.append(points)
        stream.pending_rows += points.shape[0]
        if stream.pending_rows >= _LIDAR_FLUSH_ROWS:
            self._flush_points(stream, final=False)

    def _flush_points(self, stream: _Stream, *, final: bool) -> None:
        """Write buffered lidar rows in whole chunks, so no chunk is rewritten (the last one at close)."""
        if not stream.pending_points:
            return
        rows = np.concatenate(stream.pending_points)
        take = rows.shape[0] if final else (rows.shape[0] // LIDAR_CHUNK_ROWS) * LIDAR_CHUNK_ROWS
        start = stream.written_rows
        stream.bulk.resize((start + take, 4))
        stores.write_rows(stream.bulk, start, rows[:take], stream.made_dirs)
        stream.bulk_crc32c.extend(checksums.block_checksums(rows[:take], (LIDAR_CHUNK_ROWS, 4)))
        stream.written_rows += take
        rest = rows[take:]
        stream.pending_points = [rest] if rest.shape[0] else []
        stream.pending_rows = rest.shape[0]

    def write_tracklog(self, timestamp_ns: Any, position_ecef: Any, attitude_wxyz: Any) -> None:
        """Write the whole tracklog: ``[K]`` int64, ``[K, 3]`` ECEF metres, ``[K, 4]`` IMU→ECEF wxyz."""
        if self._closed:
            raise RuntimeError(f"{self.scene_id}: the writer is closed")
        if self._tracklog_written:
            raise ZendarFormatError(f"{self.scene_id}: {TRACKLOG}: written already (write it once, whole)")
        if "imu" not in self.calibration.sensors:
            raise ZendarFormatError(f"{self.scene_id}: {TRACKLOG}: expected an 'imu' entry in the calibration, found none")
        where = f"{self.scene_id}: {TRACKLOG}"
        timestamps = _as(timestamp_ns, "int64", (None,), f"{where}/timestamp_ns")
        k = timestamps.shape[0]
        position = _as(position_ecef, "float64", (k, 3), f"{where}/position_ecef")
        attitude = _as(attitude_wxyz, "float64", (k, 4), f"{where}/attitude_wxyz")
        if k == 0:
            raise ZendarFormatError(f"{where}/timestamp_ns: expected at least one pose, found none")
        if np.any(np.diff(timestamps) <= 0):
            bad = int(np.flatnonzero(np.diff(timestamps) <= 0)[0]) + 1
            raise ZendarFormatError(
                f"{where}/timestamp_ns: expected strictly increasing timestamps, found {timestamps[bad]} "
                f"at index {bad} after {timestamps[bad - 1]}"
            )
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(attitude))):
            raise ZendarFormatError(f"{where}: expected finite positions and attitudes")
        norms = np.linalg.norm(attitude, axis=1)
        if np.any(np.abs(norms - 1.0) > _QUATERNION_NORM_TOLERANCE):
            bad = int(np.argmax(np.abs(norms - 1.0)))
            raise ZendarFormatError(f"{where}/attitude_wxyz: expected unit quaternions, found norm {norms[bad]:.9f} at {bad}")
        for name, array in (("timestamp_ns", timestamps), ("position_ecef", position), ("attitude_wxyz", attitude)):
            self._write_small(f"{TRACKLOG}/{name}", array)
        self._flush_small()
        self._tracklog_written = True

    def write_labels(self, labels: dict[str, np.ndarray]) -> None:
        """Write ``labels/moving_cars``: equal-length 1-D arrays of every label field (docs/format.md).

        Each ``timestamp_ns`` must equal a frame of the scene's first SAR stream
        (checked at :meth:`close`, once every SAR frame is in).
        """
        if self._closed:
            raise RuntimeError(f"{self.scene_id}: the writer is closed")
        where = f"{self.scene_id}: {LABELS}"
        missing = [spec.name for spec in LABEL_FIELDS if spec.name not in labels]
        unknown = sorted(set(labels) - {spec.name for spec in (*LABEL_FIELDS, *LABEL_OPTIONAL_FIELDS)})
        if missing or unknown:
            raise ZendarFormatError(
                f"{where}: expected fields {[s.name for s in LABEL_FIELDS]} (optional {[s.name for s in LABEL_OPTIONAL_FIELDS]}), "
                f"missing {missing}, unknown {unknown}"
            )
        out = {}
        for spec in (*LABEL_FIELDS, *(s for s in LABEL_OPTIONAL_FIELDS if s.name in labels)):
            value = np.asarray(labels[spec.name])
            if spec.dtype.kind == "i" and value.dtype.kind not in "iu":
                raise ZendarFormatError(f"{where}/{spec.name}: expected {spec.dtype.name}, found {value.dtype.name}")
            out[spec.name] = _as(value, spec.dtype.name, (None,), f"{where}/{spec.name}")
        lengths = {name: array.shape[0] for name, array in out.items()}
        if len(set(lengths.values())) > 1:
            raise ZendarFormatError(f"{where}: expected equal-length fields, found lengths {lengths}")
        for name, array in out.items():
            if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
                raise ZendarFormatError(f"{where}/{name}: expected finite values")
        self._labels = out

    def write_detections(
        self, sensor: str, timestamp_ns: Any, offsets: Any, columns: dict[str, np.ndarray]
    ) -> None:
        """Write a whole ``detections/<sensor>`` group (optional; docs/format.md).

        ``timestamp_ns`` [N] int64 frame times; ``offsets`` [N + 1] int64 (frame n is rows
        ``offsets[n]:offsets[n+1]``); ``columns`` holds every per-detection array of
        ``schema.STREAM_ARRAYS["detections"]`` with ``offsets[-1]`` rows (NaN allowed: not measured).
        """
        stream = self._stream(DETECTIONS, sensor, None)
        where = f"{self.scene_id}: {stream.path}"
        timestamps = _as(timestamp_ns, "int64", (None,), f"{where}/timestamp_ns")
        n = timestamps.shape[0]
        offsets = _as(offsets, "int64", (n + 1,), f"{where}/offsets")
        if offsets[0] != 0 or np.any(np.diff(offsets) < 0):
            raise ZendarFormatError(f"{where}/offsets: expected non-decreasing offsets from 0, found {offsets[:4].tolist()}...")
        if np.any(np.diff(timestamps) <= 0):
            raise ZendarFormatError(f"{where}/timestamp_ns: expected strictly increasing timestamps")
        specs = {spec.name: spec for spec in STREAM_ARRAYS[DETECTIONS]}
        missing = sorted(set(specs) - {"timestamp_ns", "offsets"} - set(columns))
        if missing:
            raise ZendarFormatError(f"{where}: expected columns {sorted(specs)}, missing {missing}")
        arrays = {"timestamp_ns": timestamps, "offsets": offsets}
        for name, spec in specs.items():
            if name not in arrays:
                shape = (int(offsets[-1]), *spec.shape[1:])
                arrays[name] = _as(columns[name], spec.dtype.name, shape, f"{where}/{name}")
        stream.timestamps = timestamps.tolist()
        for name, array in arrays.items():
            if name != "timestamp_ns":
                self._write_small(f"{stream.path}/{name}", array)
        self._flush_small()

    def write_camera_index(self, sensor: str, timestamp_ns: Any, frame_index: Any) -> None:
        """Write a whole ``camera_index/<sensor>`` group: [N] int64 times and [N] int64 video frame numbers."""
        stream = self._stream(CAMERA_INDEX, sensor, None)
        where = f"{self.scene_id}: {stream.path}"
        timestamps = _as(timestamp_ns, "int64", (None,), f"{where}/timestamp_ns")
        if np.any(np.diff(timestamps) <= 0):
            raise ZendarFormatError(f"{where}/timestamp_ns: expected strictly increasing timestamps")
        index = _as(frame_index, "int64", (timestamps.shape[0],), f"{where}/frame_index")
        stream.timestamps = timestamps.tolist()
        self._write_small(f"{stream.path}/frame_index", index)
        self._flush_small()

    def write_extra_array(self, path: str, array: np.ndarray) -> None:
        """Write an array that format v1 lists as optional inside an existing stream group
        (e.g. ``lidar/<lidar>/position_ecef``; docs/format.md); written whole, checksummed."""
        if self._closed:
            raise RuntimeError(f"{self.scene_id}: the writer is closed")
        array = np.asarray(array)
        if array.ndim == 0 or 0 in array.shape[1:]:
            raise ZendarFormatError(
                f"{self.scene_id}/{path}: expected an array of rows with non-empty trailing axes, got shape {array.shape}"
            )
        self._write_small(path, np.ascontiguousarray(array))
        self._flush_small()

    def write_attrs(self, path: str, attrs: dict[str, Any]) -> None:
        """Add JSON attributes to the scene root (``""``) or one of its groups (readers ignore unknown ones)."""
        if self._closed:
            raise RuntimeError(f"{self.scene_id}: the writer is closed")
        root = self._store.root
        stores.merge_attrs(root, path, attrs)

    def _write_small(self, path: str, array: np.ndarray) -> None:
        """Queue a whole array (with its chunk checksums; compressed as :func:`stores.array_kind` says) for
        :meth:`_flush_small` (zarr)."""
        rows = max(1, min(array.shape[0], SMALL_CHUNK_ROWS))
        chunks = (rows, *array.shape[1:])
        crc32c = checksums.encode(checksums.block_checksums(array, chunks))
        kind = stores.array_kind(path)
        self._pending_small.append(stores.NewArray(path, array, chunks, kind, {checksums.ARRAY_ATTR: crc32c}))
        if self.backend != "zarr":
            self._flush_small()  # HDF5 gains nothing from a batch: keep its file's order of writes

    def _flush_small(self) -> None:
        """Write the queued small arrays together (one pass through zarr's event loop, not one per array)."""
        pending, self._pending_small = self._pending_small, []
        stores.write_arrays(self._store.root, pending)

    # -- finishing -----------------------------------------------------------
    def _first_sar_timestamps(self) -> np.ndarray | None:
        names = sorted(path for path, stream in self._streams.items() if path.startswith("sar/") and stream.timestamps)
        return np.asarray(self._streams[names[0]].timestamps, dtype=np.int64) if names else None

    def _finish_streams(self) -> None:
        for stream in self._streams.values():
            if not stream.timestamps:
                continue  # every append to it was rejected
            self._write_small(f"{stream.path}/timestamp_ns", np.asarray(stream.timestamps, dtype=np.int64))
            for name, rows in stream.small.items():
                self._write_small(f"{stream.path}/{name}", np.stack(rows))
            if stream.path.startswith("lidar/"):
                self._flush_points(stream, final=True)
                self._write_small(f"{stream.path}/offsets", np.asarray(stream.offsets, dtype=np.int64))
            if stream.appender is not None:
                stream.appender.finish()
            if stream.bulk is not None:
                stores.merge_attrs(self._store.root, stream.bulk_path, {checksums.ARRAY_ATTR: checksums.encode(stream.bulk_crc32c)})
                if stream.path.startswith("sar/") and np.dtype(stream.bulk.dtype) in SAR_MAGNITUDE_DTYPES:
                    stores.merge_attrs(self._store.root, stream.path, {SAR_MAGNITUDE_ONLY_ATTR: True})
        if self._labels is not None:
            sar_timestamps = self._first_sar_timestamps()
            label_timestamps = self._labels["timestamp_ns"]
            if label_timestamps.size:
                known = np.isin(label_timestamps, sar_timestamps if sar_timestamps is not None else [])
                if not np.all(known):
                    raise ZendarFormatError(
                        f"{self.scene_id}: {LABELS}/timestamp_ns: expected timestamps of the first SAR stream's frames, "
                        f"found {int(np.count_nonzero(~known))} that are not (first: {int(label_timestamps[~known][0])})"
                    )
            for name, array in self._labels.items():
                self._write_small(f"{LABELS}/{name}", array)
        self._flush_small()

    def close(self) -> None:
        """Finalise the store and rename it to its final path (no-op when already closed)."""
        if self._closed:
            return
        try:
            self._finish_streams()
            self._store.close()
            if self.backend == "zarr":
                stores.consolidate(self._temp_path)
            self._closed = True
            self._publish()
        except BaseException:
            self.abort()
            raise
        self.completed = True

    def _publish(self) -> None:
        if self.path.exists():
            if not self.overwrite:
                raise FileExistsError(f"{self.path}: a scene appeared while writing (pass overwrite=True to replace it)")
            if not self.path.is_dir():
                os.replace(self._temp_path, self.path)  # a file (HDF5) is replaced atomically
            else:
                # A directory cannot be renamed over a non-empty one: move the old scene aside first,
                # and put it back if the new one does not arrive (a failure or Ctrl-C in between).
                trash = temporary.temporary_sibling(self.path)
                try:
                    os.replace(self.path, trash)
                    os.replace(self._temp_path, self.path)
                except BaseException:
                    if trash.exists() and not self.path.exists():
                        os.replace(trash, self.path)
                    raise
                temporary.remove_temporary(trash)
        else:
            os.replace(self._temp_path, self.path)
        temporary.forget(self._temp_path)

    def abort(self) -> None:
        """Discard everything written: the temporary store is removed, the final path untouched."""
        self._closed = True
        try:
            self._store.close()
        finally:
            temporary.remove_temporary(self._temp_path)


class DatasetWriter:
    """Write a dataset root: scenes under ``scenes/`` and, last, ``dataset.json``.

    Parameters
    ----------
    root : path-like
        Dataset root directory (created if needed).
    name : str
        The dataset's name in ``dataset.json``.
    backend : {"zarr", "hdf5"}
        Backend of the scenes written through :meth:`scene`.
    overwrite : bool
        Allow replacing an existing ``dataset.json`` (and scenes, when passed on to :meth:`scene`).
    """

    def __init__(self, root: str | os.PathLike, name: str, *, backend: str = "zarr", overwrite: bool = False) -> None:
        if backend not in BACKEND_SUFFIX:
            raise ValueError(f"unknown backend {backend!r}; expected one of {tuple(BACKEND_SUFFIX)}")
        self.root = pathlib.Path(root)
        self.name = name
        self.backend = backend
        self.overwrite = overwrite
        if (self.root / DATASET_JSON).exists() and not overwrite:
            raise FileExistsError(f"{self.root / DATASET_JSON}: a dataset exists already (pass overwrite=True)")
        (self.root / "scenes").mkdir(parents=True, exist_ok=True)
        self._writers: dict[str, SceneWriter] = {}

    def scene_path(self, scene_id: str) -> pathlib.Path:
        """``root/scenes/<scene_id>.zarr`` or ``.h5``."""
        return self.root / "scenes" / f"{check_scene_id(scene_id)}{BACKEND_SUFFIX[self.backend]}"

    def scene(self, scene_id: str, **kwargs: Any) -> SceneWriter:
        """A :class:`SceneWriter` for ``scene_id`` at :meth:`scene_path` (kwargs go to it)."""
        kwargs.setdefault("backend", self.backend)
        kwargs.setdefault("overwrite", self.overwrite)
        writer = SceneWriter(self.scene_path(scene_id), scene_id, **kwargs)
        self._writers[scene_id] = writer
        return writer

    def finalize(self, splits: dict[str, list[str]], existing_paths: Mapping[str, str] | None = None) -> None:
        """Write ``dataset.json`` atomically.

        It lists the scenes completed through this writer, the scenes of ``existing_paths``, and any
        scene named in ``splits`` whose store exists; a split naming a scene that is not complete raises.

        Parameters
        ----------
        splits : dict of str to list of str
            Split name -> scene ids.
        existing_paths : mapping of str to str, optional
            Scene id -> store path relative to the root, of scenes written earlier (by another run,
            possibly in the other backend): listed as they are.
        """
        known = dict(existing_paths or {})
        suffix = BACKEND_SUFFIX[self.backend]

        def relative_path(scene_id: str) -> str:
            return known.get(scene_id, f"scenes/{check_scene_id(scene_id)}{suffix}")

        problems = []
        for split, scene_ids in splits.items():
            if not isinstance(split, str) or not isinstance(scene_ids, (list, tuple)):
                problems.append(f"splits: expected {{name: [scene_id, ...]}}, found {split!r}: {scene_ids!r}")
                continue
            for scene_id in scene_ids:
                if not (self.root / relative_path(scene_id)).exists():
                    problems.append(f"splits.{split}: scene {scene_id!r} is not complete ({self.root / relative_path(scene_id)} missing)")
        if problems:
            raise ZendarFormatError(f"{self.root}: cannot finalize: " + "; ".join(problems), problems)
        completed = {scene_id for scene_id, writer in self._writers.items() if writer.completed}
        completed |= {scene_id for scene_ids in splits.values() for scene_id in scene_ids} | set(known)
        document = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "name": self.name,
            "splits": {**{split: [] for split in SPLITS}, **{k: list(v) for k, v in splits.items()}},
            "scenes": {scene_id: {"path": relative_path(scene_id)} for scene_id in sorted(completed)},
        }
        write_json_atomic(self.root / DATASET_JSON, document)
