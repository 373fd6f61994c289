"""``ZendarDataset``: one item per reference frame, every stream synchronised by GPS time.

>>> ds = ZendarDataset("path/to/root", split="train",
...                    streams=("radar", "sar", "tracklog", "labels"),
...                    reference="sar", cube_window=2)          # doctest: +SKIP
>>> item = ds[0]                                                # doctest: +SKIP
>>> item["radar"]["left"]["cube"].shape     # [K, R, D, A]        doctest: +SKIP
>>> item["sync"]["radar/left"]              # Δt ns of the latest cube   doctest: +SKIP

Construction reads ``dataset.json``, scene attributes and timestamp arrays only;
an item reads the chunks it needs (a radar window is one contiguous slice).
Scene stores are opened lazily in each process, so DataLoader workers work
under both the fork and spawn start methods.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
import torch
from torch.utils.data import Dataset, get_worker_info

from zendar_dataset import shared_batches
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import SceneReader, StoredArray, frame_id, open_dataset
from zendar_dataset.format.schema import LABEL_FIELD_NAMES
from zendar_dataset.geometry import PoseInterpolator
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.sync import (
    MISSING,
    SENSOR_GROUPS,
    STREAM_GROUPS,
    SyncReport,
    SyncTable,
    scene_sync_table,
)

DEFAULT_STREAMS = ("radar", "sar", "tracklog", "camera", "lidar", "labels")
SAR_FRAME_ARRAYS = ("origin_ecef", "di_ecef", "dj_ecef", "aperture_ns")
# Paths whose arrays vary in length between items: collate keeps them as lists.
VARIABLE_LENGTH_GROUPS = ("lidar", "labels")


def _check_streams(streams: Iterable[str]) -> tuple[str, ...]:
    if isinstance(streams, str):
        streams = (streams,)
    out = []
    for key in streams:
        group, _, sensor = str(key).partition("/")
        if group not in STREAM_GROUPS or (sensor and group not in SENSOR_GROUPS):
            raise ValueError(
                f"streams: {key!r} is not a stream; expected groups {STREAM_GROUPS} "
                f"or '<group>/<sensor>' for {SENSOR_GROUPS}"
            )
        out.append(str(key))
    if not out:
        raise ValueError(f"streams: expected at least one of {STREAM_GROUPS}")
    return tuple(dict.fromkeys(out))


def _check_keys(keys: Iterable[str], streams: Sequence[str], what: str) -> None:
    """Every key of ``require``/``tolerance_ms`` must name a requested group or stream."""
    groups = {s.partition("/")[0] for s in streams}
    whole_groups = {s for s in streams if "/" not in s}
    unknown = [k for k in keys if k not in streams and k not in groups and k.partition("/")[0] not in whole_groups]
    if unknown:
        raise ValueError(f"{what} names {unknown}, which are not among the requested streams {list(streams)}")


class _SceneState:
    """What one process caches about one scene: poses, labels, SAR geometry."""

    def __init__(self) -> None:
        self.poses: EgoPoses | None = None
        self.tracklog: PoseInterpolator | None = None
        self.labels: dict[str, np.ndarray] | None = None
        self.label_times: np.ndarray | None = None
        self.sar_frames: dict[str, dict[str, np.ndarray]] = {}
        # Opening an array reads its metadata (a file, or a request when remote): once per process.
        self.arrays: dict[str, StoredArray] = {}


class ZendarDataset(Dataset):
    """The Zendar dataset as a map-style torch ``Dataset``: one item per reference frame.

    Parameters
    ----------
    root
        Dataset root (directory or fsspec URL such as ``s3://bucket/zendar``).
    split
        A split of ``dataset.json`` (``"train"``, ``"val"``, ``"test"``).
    streams
        Groups (``"radar"``, ``"sar"``, ``"camera"``, ``"lidar"``, ``"tracklog"``,
        ``"labels"``) or single sensor streams (``"camera/front"``) to load.
    reference
        The stream giving one item per frame: ``"sar"`` is each scene's first SAR
        sensor in name order, ``"sar/<name>"`` a given one; any other sensor stream
        or ``"tracklog"`` works too.
    tolerance_ms
        Matching tolerance: None for the defaults (half a stream's median frame
        interval; 1.5 intervals for radar windows), one number for all streams, or
        a dict keyed by ``"<group>/<sensor>"`` or ``"<group>"``. ``|Δt| <= tolerance``
        matches (inclusive).
    cube_window
        K: each radar contributes its K latest cubes with ``timestamp_ns <=`` the
        reference time, ``[K, R, D, A]``. Items whose window cannot be filled are left
        out and counted in :meth:`sync_report` (unless ``keep_unfilled_windows``).
    require
        Groups or streams that must be present; items missing one are left out and counted.
    transforms
        Callable applied to each item (a dict) before it is returned.
    storage_options
        fsspec options for remote roots (e.g. ``{"endpoint_url": ..., "anon": True}``).
    keep_unfilled_windows
        Keep items whose radar window cannot be filled, with that radar set to None.
    worker_pool_slots
        Inside a DataLoader worker, radar batches are read into a pool of at most this
        many recycled shared-memory slots per worker (each the size of one radar's
        batch); beyond it, batches take torch's ordinary path. 0 turns the pool off.
    verify_checksums
        Check every chunk read against the CRC-32C its store recorded when written
        (docs/format.md), raising ZendarFormatError naming the chunk on a mismatch.
        Off by default: reads then hash nothing. Stores that record no checksums read as usual.

    Notes
    -----
    An item is a dict with ``frame_id`` (``"<scene_id>/<timestamp_ns>"``),
    ``scene_id``, ``timestamp_ns`` (int, the reference frame's), one dict per
    requested sensor group keyed by sensor name (None where nothing matched),
    ``labels`` (field name -> 1-D array; empty arrays for a frame without cars;
    None for a scene whose labels are withheld), ``sync`` (``"<group>/<sensor>"``
    -> Δt = element − reference in ns, or None) and, with the tracklog,
    ``ecef_T_ego`` / ``enu_T_ego`` ([4, 4] float64 at the reference time).
    A SAR ``image`` is ``[H, W]`` as stored: complex64, or for a magnitude-only stream of an
    imported recording its exact real magnitudes (uint32 or float32; docs/format.md); ``np.abs``
    gives the magnitude of both.
    """

    def __init__(
        self,
        root: str | os.PathLike,
        split: str = "train",
        streams: Iterable[str] = DEFAULT_STREAMS,
        reference: str = "sar",
        tolerance_ms: float | Mapping[str, float] | None = None,
        cube_window: int = 1,
        require: Iterable[str] = (),
        transforms: Callable[[dict], Any] | None = None,
        storage_options: dict | None = None,
        keep_unfilled_windows: bool = False,
        worker_pool_slots: int = 16,
        verify_checksums: bool = False,
    ) -> None:
        self.streams = _check_streams(streams)
        if isinstance(require, str):
            require = (require,)
        self.require = tuple(require)
        _check_keys(self.require, self.streams, "require")
        if isinstance(tolerance_ms, Mapping):
            _check_keys(tolerance_ms, self.streams, "tolerance_ms")
        if isinstance(cube_window, bool) or not isinstance(cube_window, (int, np.integer)) or cube_window < 1:
            raise ValueError(f"cube_window must be an integer >= 1, got {cube_window!r}")
        if (isinstance(worker_pool_slots, bool) or not isinstance(worker_pool_slots, (int, np.integer))
                or worker_pool_slots < 0):
            raise ValueError(f"worker_pool_slots must be an integer >= 0, got {worker_pool_slots!r}")
        if transforms is not None and not callable(transforms):
            raise ValueError(f"transforms must be callable, got {type(transforms).__name__}")
        self.root = os.fspath(root)
        self.split = split
        self.reference = reference
        self.tolerance_ms = tolerance_ms
        self.cube_window = int(cube_window)
        self.transforms = transforms
        self.storage_options = dict(storage_options or {})
        self.keep_unfilled_windows = keep_unfilled_windows
        self.worker_pool_slots = int(worker_pool_slots)
        self.verify_checksums = bool(verify_checksums)

        index = open_dataset(self.root, self.storage_options)
        self.dataset_name = index.name
        self.scene_ids: list[str] = index.scene_ids(split)
        self._readers: list[SceneReader] = []
        self._tables: list[SyncTable] = []
        for scene_id in self.scene_ids:
            reader = index.open_scene(scene_id, verify_checksums=self.verify_checksums)
            try:
                self._check_scene(reader)
                self._tables.append(
                    scene_sync_table(
                        reader,
                        self.streams,
                        reference=reference,
                        cube_window=self.cube_window,
                        tolerance_ms=tolerance_ms,
                        require=self.require,
                        keep_unfilled_windows=keep_unfilled_windows,
                    )
                )
            finally:
                # Handles reopen on first use, in whichever process reads items.
                reader.close()
            self._readers.append(reader)
        self._offsets = np.concatenate([[0], np.cumsum([len(t) for t in self._tables])]).astype(np.int64)
        self._state: dict[int, _SceneState] = {}
        self._state_pid = os.getpid()

    def _check_scene(self, reader: SceneReader) -> None:
        if ("tracklog" in self.streams and "tracklog" in reader.streams
                and "imu" not in reader.calibration.sensors):
            raise ZendarFormatError(
                f"{reader.scene_id}: calibration: expected an 'imu' entry (ego_T_imu) for the tracklog"
            )

    # -- pickling: drop per-process caches ------------------------------------
    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_state"] = {}
        return state

    # -- torchvision-style basics ---------------------------------------------
    def __len__(self) -> int:
        return int(self._offsets[-1])

    def __repr__(self) -> str:
        lines = [
            f"{type(self).__name__}(",
            f"    root={self.root!r},",
            f"    split={self.split!r}, scenes={len(self.scene_ids)}, size={len(self)},",
            f"    streams={list(self.streams)},",
            f"    reference={self.reference!r}, cube_window={self.cube_window}, "
            f"tolerance_ms={self.tolerance_ms!r}, require={list(self.require)},",
            ")",
        ]
        return "\n".join(lines)

    def scene_ranges(self) -> list[tuple[str, int, int]]:
        """``(scene_id, start, stop)`` of each scene's items (used by the samplers)."""
        return [
            (scene_id, int(self._offsets[k]), int(self._offsets[k + 1]))
            for k, scene_id in enumerate(self.scene_ids)
        ]

    def sync_table(self, scene_id: str) -> SyncTable:
        """The synchronisation index of one scene of this split."""
        try:
            return self._tables[self.scene_ids.index(scene_id)]
        except ValueError:
            raise ZendarFormatError(
                f"scene {scene_id!r} is not in split {self.split!r} (scenes: {self.scene_ids})"
            ) from None

    def scene_reader(self, scene_id: str) -> SceneReader:
        """The scene's reader (calibration, ENU origin, raw arrays)."""
        self.sync_table(scene_id)
        return self._readers[self.scene_ids.index(scene_id)]

    def ego_poses(self, scene_id: str) -> EgoPoses:
        """The scene's ego poses at any time within its tracklog.

        Interpolates the tracklog (linear translation, Slerp rotation) and applies the IMU
        calibration, e.g. ``ds.ego_poses(scene_id).enu_T_ego(timestamp_ns)``; built once per
        process and cached.
        """
        self.sync_table(scene_id)
        return self._poses(self.scene_ids.index(scene_id))

    def sync_report(self) -> SyncReport:
        """Residuals and drops per scene and stream (a DataFrame; ``print`` shows a summary).

        Columns: ``scene_id``, ``reference``, ``reference_frames`` (frames of the
        reference stream), ``items`` (kept), ``stream``, ``window``, ``tolerance_ms``,
        ``matched``, ``missing`` (kept items without this stream), ``dropped``
        (frames left out because of this stream), ``dt_mean_ns``, ``dt_min_ns``,
        ``dt_max_ns``, ``abs_dt_median_ns``, ``abs_dt_p95_ns``, ``abs_dt_max_ns``
        (Δt = element − reference; for windows, the latest element).
        """
        frames = []
        for scene_id, table in zip(self.scene_ids, self._tables):
            stats = table.residual_stats()
            extra = [g for g in table.dropped if g not in set(stats["stream"])]
            if extra:
                absent = pd.DataFrame(
                    [{"stream": g, "items": len(table), "matched": 0, "missing": len(table),
                      "dropped": table.dropped[g]} for g in extra]
                )
                stats = pd.concat([stats, absent], ignore_index=True)
            stats.insert(0, "scene_id", scene_id)
            stats.insert(1, "reference", table.reference)
            stats.insert(2, "reference_frames", table.n_reference)
            frames.append(stats)
        if not frames:
            return SyncReport(columns=["scene_id", "reference", "reference_frames", "stream"])
        return SyncReport(pd.concat(frames, ignore_index=True))

    # -- items ------------------------------------------------------------------
    def _locate(self, index: int) -> tuple[int, int]:
        n = len(self)
        if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)):
            raise TypeError(f"index must be an integer, got {type(index).__name__}")
        if not -n <= index < n:
            raise IndexError(f"index {index} out of range for {n} items")
        index = int(index) % n
        scene = int(np.searchsorted(self._offsets, index, side="right") - 1)
        return scene, index - int(self._offsets[scene])

    def _scene_state(self, scene: int) -> _SceneState:
        if self._state_pid != os.getpid():
            # A forked worker inherits the parent's caches; they are safe to reuse
            # (plain arrays) but keep ownership per process for clarity.
            self._state = {}
            self._state_pid = os.getpid()
        if scene not in self._state:
            self._state[scene] = _SceneState()
        return self._state[scene]

    def _poses(self, scene: int) -> EgoPoses:
        state = self._scene_state(scene)
        if state.poses is None:
            state.poses = self._readers[scene].ego_poses()
            state.tracklog = state.poses.tracklog
        return state.poses

    def _array(self, scene: int, path: str) -> StoredArray:
        arrays = self._scene_state(scene).arrays
        if path not in arrays:
            arrays[path] = self._readers[scene].array(path)
        return arrays[path]

    def _labels_at(self, scene: int, timestamp_ns: int) -> dict[str, np.ndarray]:
        state = self._scene_state(scene)
        if state.labels is None:
            labels = self._readers[scene].labels()
            order = np.argsort(labels["timestamp_ns"], kind="stable")
            state.labels = {name: np.asarray(labels[name])[order] for name in LABEL_FIELD_NAMES}
            state.label_times = state.labels["timestamp_ns"]
        lo, hi = np.searchsorted(state.label_times, [timestamp_ns, timestamp_ns + 1])
        return {name: values[lo:hi].copy() for name, values in state.labels.items()}

    def _sar_frame(self, scene: int, sensor: str, element: int) -> dict[str, np.ndarray]:
        state = self._scene_state(scene)
        if sensor not in state.sar_frames:
            reader = self._readers[scene]
            state.sar_frames[sensor] = {
                name: reader.array(f"sar/{sensor}/{name}")[...] for name in SAR_FRAME_ARRAYS
            }
        return {name: values[element].copy() for name, values in state.sar_frames[sensor].items()}

    def __getitem__(self, index: int) -> Any:
        scene, row = self._locate(index)
        return self._item(scene, row, {})

    def __getitems__(self, indices: Sequence[int]) -> list[Any]:
        """Items of one batch (called by the DataLoader): each radar's windows are read
        straight into one batch buffer, inside a worker a recycled shared-memory slot
        (:mod:`zendar_dataset.shared_batches`), so that :meth:`collate` copies nothing
        and the main process receives the batch with one kernel copy."""
        located = [self._locate(i) for i in indices]
        buffers: list[dict[str, np.ndarray]] = [{} for _ in located]
        radar_streams = {n for scene, _ in located for n in self._tables[scene].streams if n.startswith("radar/")}
        for name in sorted(radar_streams):
            shapes = set()
            for scene, row in located:
                table = self._tables[scene]
                if name not in table.element or table.element[name][row] == MISSING:
                    break
                shapes.add(self._array(scene, f"{name}/cube").shape[1:])
            else:
                if len(shapes) == 1:
                    batch = _batch_buffer(
                        (len(located), self.cube_window, *shapes.pop()), np.complex64, self.worker_pool_slots
                    )
                    for b, out in enumerate(batch):
                        buffers[b][name] = out
        return [self._item(scene, row, out) for (scene, row), out in zip(located, buffers)]

    def _item(self, scene: int, row: int, buffers: dict[str, np.ndarray]) -> Any:
        reader = self._readers[scene]
        table = self._tables[scene]
        timestamp_ns = int(table.timestamp_ns[row])
        item: dict[str, Any] = {
            "frame_id": frame_id(reader.scene_id, timestamp_ns),
            "scene_id": reader.scene_id,
            "timestamp_ns": timestamp_ns,
            "reference": table.reference,
        }
        sync: dict[str, int | None] = {}
        for name in table.streams:
            element = int(table.element[name][row])
            present = element != MISSING
            sync[name] = int(table.dt_ns[name][row]) if present else None
            group, _, sensor = name.partition("/")
            if group in SENSOR_GROUPS:
                item.setdefault(group, {})[sensor] = (
                    self._read_sensor(scene, group, sensor, element, buffers.get(name)) if present else None
                )
            elif group == "tracklog":
                self._add_poses(item, scene, timestamp_ns, present)
            elif group == "labels":
                label_time = int(table.timestamp_ns[row] + table.dt_ns[name][row])
                item["labels"] = self._labels_at(scene, label_time) if present else None
                if present:
                    item["label_timestamp_ns"] = label_time
        for group in self.streams:
            if group in SENSOR_GROUPS:
                item.setdefault(group, {})
        item["sync"] = sync
        return self.transforms(item) if self.transforms is not None else item

    def _add_poses(self, item: dict, scene: int, timestamp_ns: int, present: bool) -> None:
        if not present:
            item["tracklog"] = None
            item["ecef_T_ego"] = None
            item["enu_T_ego"] = None
            return
        poses = self._poses(scene)
        position_ecef, attitude_wxyz = poses.tracklog.at(timestamp_ns)
        item["tracklog"] = {
            "timestamp_ns": timestamp_ns,
            "position_ecef": position_ecef[0],
            "attitude_wxyz": attitude_wxyz[0],
        }
        item["ecef_T_ego"] = poses.ecef_T_ego(timestamp_ns).as_matrix()
        item["enu_T_ego"] = poses.enu_T_ego(timestamp_ns).as_matrix()

    def _read_sensor(
        self, scene: int, group: str, sensor: str, element: int, out: np.ndarray | None = None
    ) -> dict[str, Any]:
        """One stream's element; ``out`` is a preallocated [K, R, D, A] buffer for radar windows."""
        reader = self._readers[scene]
        stream = f"{group}/{sensor}"
        times = reader.timestamps(stream)
        if group == "radar":
            start = element - self.cube_window + 1
            cubes = self._array(scene, f"{stream}/cube")
            if out is None:
                cube = cubes[start : element + 1]
            else:
                cubes.read_into(start, element + 1, out)
                cube = out
            return {"cube": cube, "timestamp_ns": times[start : element + 1].copy()}
        frame: dict[str, Any] = {"timestamp_ns": int(times[element])}
        if group == "sar":
            frame["image"] = self._array(scene, f"{stream}/image")[element]
            frame.update(self._sar_frame(scene, sensor, element))
        elif group == "camera":
            frame["image"] = self._array(scene, f"{stream}/image")[element]
        elif group == "lidar":
            frame["points"] = reader.lidar_points(sensor, element)
        return frame

    # -- batching ----------------------------------------------------------------
    @staticmethod
    def collate(batch: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """Batch items for a DataLoader.

        Fixed-size arrays (radar cubes, SAR and camera images, poses, timestamps)
        present in every item are stacked into tensors with a leading batch axis;
        lidar points and labels stay lists of tensors (their lengths vary). Where
        any item lacks an element (None), that entry is a list with None in its place.
        ``sync`` becomes ``{stream: [Δt ns or None, ...]}``; strings stay lists.
        """
        if not batch:
            raise ValueError("collate needs at least one item")
        return _collate(list(batch), path=())


def _batch_buffer(shape: tuple[int, ...], dtype: np.dtype, pool_slots: int = 0) -> np.ndarray:
    """An uninitialised batch array. Inside a DataLoader worker: a slot of the worker's
    shared-memory pool, or, with none free, a fresh shared tensor (as torch's own collate
    makes), so that sending it copies nothing in the worker."""
    torch_dtype = torch.from_numpy(np.zeros(0, dtype=dtype)).dtype
    if get_worker_info() is None:
        # numpy asks for transparent huge pages for large arrays: cheaper fresh pages than torch.empty.
        return torch.from_numpy(np.empty(shape, dtype=dtype)).numpy()
    if pool_slots > 0:
        slot_array = shared_batches.worker_pool().buffer(shape, dtype, pool_slots)
        if slot_array is not None:
            return slot_array
    nbytes = int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    storage = torch.UntypedStorage._new_shared(nbytes)
    return torch.empty(0, dtype=torch_dtype).set_(storage, 0, shape).numpy()


def _batch_tensor(values: list[Any]) -> torch.Tensor | None:
    """The tensor behind ``values`` when they are exactly the rows of one batch buffer."""
    in_slot = shared_batches.slot_tensor(values)
    if in_slot is not None:
        return in_slot
    base = values[0].base if isinstance(values[0], np.ndarray) else None
    if not isinstance(base, np.ndarray) or not isinstance(base.base, torch.Tensor):
        return None
    if base.shape[0] != len(values) or not base.flags.c_contiguous:
        return None
    start = base.__array_interface__["data"][0]
    for b, v in enumerate(values):
        if not (isinstance(v, np.ndarray) and v.base is base and v.shape == base.shape[1:]
                and v.__array_interface__["data"][0] == start + b * base.strides[0]):
            return None
    tensor = base.base
    return tensor if tuple(tensor.shape) == base.shape else None


def _to_tensor(value: Any) -> Any:
    """Arrays to tensors, recursively through mappings; everything else unchanged."""
    if isinstance(value, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(value))
    if isinstance(value, Mapping):
        return {k: _to_tensor(v) for k, v in value.items()}
    return value


def _collate(values: list[Any], path: tuple[str, ...]) -> Any:
    first = next((v for v in values if v is not None), None)
    if first is None:
        return values
    if any(v is None for v in values):
        return [_to_tensor(v) for v in values]
    if isinstance(first, Mapping):
        keys = list(first)
        if path == ("sync",) or any(set(v) != set(keys) for v in values):
            return {k: [v.get(k) for v in values] for k in dict.fromkeys(k for v in values for k in v)}
        return {k: _collate([v[k] for v in values], path + (str(k),)) for k in keys}
    if path and path[0] in VARIABLE_LENGTH_GROUPS:
        return [_to_tensor(v) for v in values]
    if isinstance(first, np.ndarray):
        batched = _batch_tensor(values)
        if batched is not None:
            return batched
        if all(isinstance(v, np.ndarray) and v.shape == first.shape and v.dtype == first.dtype for v in values):
            return torch.from_numpy(np.stack(values))
        return [_to_tensor(v) for v in values]
    if isinstance(first, (bool, np.bool_)):
        return values
    if isinstance(first, (int, np.integer)) and all(isinstance(v, (int, np.integer)) for v in values):
        return torch.tensor(values, dtype=torch.int64)
    if isinstance(first, (float, np.floating)) and all(isinstance(v, (int, float, np.number)) for v in values):
        return torch.tensor(values, dtype=torch.float64)
    return values
