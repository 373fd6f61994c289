"""Reading format-v1 datasets from a local path or an fsspec URL (read-only, lazy).

>>> index = open_dataset("path/to/root")                       # doctest: +SKIP
>>> scene = index.open_scene(index.scene_ids("train")[0])      # metadata only
>>> cube = scene.array("radar/left/cube")[3]                   # reads one chunk
"""

from __future__ import annotations

import json
import os
from typing import Any

import fsspec
import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import checksums, stores
from zendar_dataset.format.calibration import Calibration
from zendar_dataset.format.checks import check_scene_metadata
from zendar_dataset.format.schema import (
    DATASET_JSON,
    FORMAT_NAME,
    FORMAT_VERSION,
    LABEL_FIELD_NAMES,
    LABEL_OPTIONAL_FIELD_NAMES,
    LABELS,
    SAR_MAGNITUDE_ONLY_ATTR,
    SENSOR_GROUPS,
    SPLITS,
)
from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.geometry.geodesy import LocalENU
from zendar_dataset.geometry.poses import PoseInterpolator


def _read_text(location: str, storage_options: dict | None) -> str:
    if stores.is_url(location):
        with fsspec.open(location, "r", encoding="utf-8", **(storage_options or {})) as handle:
            return handle.read()
    with open(stores.local_path(location), encoding="utf-8") as handle:
        return handle.read()


def read_dataset_json(root: str, storage_options: dict | None = None) -> Any:
    """The parsed ``dataset.json`` of a dataset root (not yet checked against the schema).

    Raises
    ------
    ZendarFormatError
        When the root or the file is missing, not a directory / not a file, not UTF-8 or not JSON.
    """
    location = stores.join_location(root, DATASET_JSON)
    if not stores.is_url(root) and os.path.exists(stores.local_path(root)) and not os.path.isdir(stores.local_path(root)):
        raise ZendarFormatError(f"{root}: expected a dataset root directory, found a file")
    try:
        text = _read_text(location, storage_options)
    except FileNotFoundError:
        raise ZendarFormatError(f"{root}: expected {DATASET_JSON} at the dataset root, found none") from None
    except IsADirectoryError:
        raise ZendarFormatError(f"{location}: expected a JSON file, found a directory") from None
    except UnicodeDecodeError as exc:
        raise ZendarFormatError(f"{location}: expected UTF-8 text, found {exc.reason} at byte {exc.start}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ZendarFormatError(f"{location}: expected JSON, found invalid text ({exc})") from None
    except RecursionError:
        raise ZendarFormatError(f"{location}: expected JSON of reasonable depth, found nesting too deep to parse") from None


def _object_member(document: dict, key: str, expected: str, where: str, problems: list[str]) -> dict:
    """``document[key]`` when it is a JSON object; otherwise note the problem and return ``{}``."""
    value = document.get(key)
    if isinstance(value, dict):
        return value
    problems.append(f"{where}: {key}: expected {expected}, found {value!r}")
    return {}


def check_dataset_json(document: Any, where: str) -> list[str]:
    """Every violation of the ``dataset.json`` schema (docs/format.md)."""
    if not isinstance(document, dict):
        return [f"{where}: expected a JSON object, found {type(document).__name__}"]
    problems = []
    if document.get("format") != FORMAT_NAME:
        problems.append(f"{where}: format: expected {FORMAT_NAME!r}, found {document.get('format')!r}")
    if document.get("format_version") != FORMAT_VERSION:
        problems.append(f"{where}: format_version: expected {FORMAT_VERSION}, found {document.get('format_version')!r}")
    if not isinstance(document.get("name"), str):
        problems.append(f"{where}: name: expected a string, found {document.get('name')!r}")
    scenes = _object_member(document, "scenes", '{scene_id: {"path": ...}}', where, problems)
    for scene_id, entry in scenes.items():
        if not scene_id or "/" in scene_id or scene_id.startswith("."):
            problems.append(f"{where}: scenes: expected scene ids without '/' and not starting with '.', found {scene_id!r}")
        path = entry.get("path") if isinstance(entry, dict) else None
        if not isinstance(path, str) or not path:
            problems.append(f"{where}: scenes.{scene_id}.path: expected a relative store path, found {path!r}")
        elif path.startswith("/") or ".." in path.split("/") or not path.endswith(tuple(stores.SUFFIX_BACKEND)):
            problems.append(f"{where}: scenes.{scene_id}.path: expected a relative path ending in .zarr or .h5, found {path!r}")
    splits = _object_member(document, "splits", "{split: [scene_id, ...]}", where, problems)
    absent = [split for split in SPLITS if split not in splits]
    if isinstance(document.get("splits"), dict) and absent:
        problems.append(f"{where}: splits: expected {list(SPLITS)} always present (possibly empty), found no {absent}")
    for split, scene_ids in splits.items():
        if not isinstance(scene_ids, list) or not all(isinstance(s, str) for s in scene_ids):
            problems.append(f"{where}: splits.{split}: expected a list of scene ids, found {scene_ids!r}")
            continue
        for scene_id in scene_ids:
            if scene_id not in scenes:
                problems.append(f"{where}: splits.{split}: expected scene {scene_id!r} in scenes, found no entry")
    return problems


class DatasetIndex:
    """A dataset root: its ``dataset.json`` and how to open each scene.

    Attributes
    ----------
    root : str
        Local path or fsspec URL of the root.
    name : str
    splits : dict[str, list[str]]
    scenes : dict[str, str]
        Scene id → store path relative to the root.
    """

    def __init__(self, root: str, document: dict, storage_options: dict | None = None) -> None:
        self.root = root
        self.storage_options = dict(storage_options or {})
        self.document = document
        self.name: str = document["name"]
        self.splits: dict[str, list[str]] = {k: list(v) for k, v in document["splits"].items()}
        self.scenes: dict[str, str] = {k: v["path"] for k, v in document["scenes"].items()}

    def __repr__(self) -> str:
        sizes = ", ".join(f"{k}={len(v)}" for k, v in self.splits.items())
        return f"DatasetIndex(root={self.root!r}, name={self.name!r}, scenes={len(self.scenes)}, splits: {sizes})"

    def scene_ids(self, split: str | None = None) -> list[str]:
        """Scene ids of ``split`` in the order listed (every scene when None)."""
        if split is None:
            return list(self.scenes)
        if split not in self.splits:
            raise ZendarFormatError(
                f"{self.root}: dataset.json splits: expected one of {sorted(self.splits)}, found unknown split {split!r}"
            )
        return list(self.splits[split])

    def scene_location(self, scene_id: str) -> str:
        """Path or URL of a scene's store."""
        if scene_id not in self.scenes:
            raise ZendarFormatError(
                f"{self.root}: dataset.json scenes: expected a scene id listed there, found unknown scene {scene_id!r}"
            )
        return stores.join_location(self.root, self.scenes[scene_id])

    def open_scene(self, scene_id: str, *, verify_checksums: bool = False) -> "SceneReader":
        """Open a scene read-only (metadata only); see :class:`SceneReader` for ``verify_checksums``."""
        return SceneReader(
            self.scene_location(scene_id), self.storage_options, scene_id=scene_id, verify_checksums=verify_checksums
        )


def open_dataset(root: str | os.PathLike, storage_options: dict | None = None) -> DatasetIndex:
    """Open a dataset root (local path or fsspec URL such as ``s3://bucket/root``) read-only.

    Parameters
    ----------
    root
        Directory or URL holding ``dataset.json``.
    storage_options
        Passed to fsspec for URLs (e.g. ``{"endpoint_url": ..., "anon": True}``).

    Raises
    ------
    ZendarFormatError
        When ``dataset.json`` is missing, not JSON, or violates the schema (all problems listed).
    """
    root = os.fspath(root)
    if stores.is_url(root):
        root = root.rstrip("/")
    document = read_dataset_json(root, storage_options)
    problems = check_dataset_json(document, stores.join_location(root, DATASET_JSON))
    if problems:
        raise ZendarFormatError("; ".join(problems), problems)
    return DatasetIndex(root, document, storage_options)


class StoredArray:
    """A lazy array of a scene: slicing reads only the chunks it needs.

    Wraps the backend's ``zarr.Array`` or ``h5py.Dataset`` (``.raw``) so that a
    truncated or corrupt chunk raises :class:`ZendarFormatError` naming the scene and path.

    Parameters
    ----------
    array
        The backend array.
    scene_id, path
        Where it is, for messages.
    checksummed : bool
        Its store records chunk checksums (docs/format.md): a chunk that is not stored is
        then an error; otherwise it reads as the array's fill value, as Zarr v3 specifies.
    verify_crc32c : list of int, optional
        The array's recorded chunk checksums (C order of the chunk grid): every chunk a read
        touches is read whole and checked against them.  None: no verification (the fast path).
    """

    def __init__(
        self,
        array: Any,
        scene_id: str,
        path: str,
        *,
        checksummed: bool = False,
        verify_crc32c: list[int] | None = None,
    ) -> None:
        self.raw = array
        self.scene_id = scene_id
        self.path = path
        self._checksummed = checksummed or verify_crc32c is not None
        self._crc32c = verify_crc32c
        self._verify = verify_crc32c is not None
        self._missing: set[tuple[int, ...]] | None = None  # HDF5: listed once (a lookup per chunk is slow)
        self._direct = stores.direct_frame_reader(array, missing_is_fill=not self._checksummed)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.raw.shape)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.raw.dtype)

    @property
    def ndim(self) -> int:
        return len(self.raw.shape)

    @property
    def chunks(self) -> tuple[int, ...] | None:
        return stores.chunk_shape(self.raw)

    def __len__(self) -> int:
        return int(self.raw.shape[0])

    def _frames(self, key: Any) -> tuple[int, int, bool] | None:
        """(start, stop, squeeze) when ``key`` selects whole frames along axis 0, else None."""
        if isinstance(key, tuple) and len(key) == 1:
            key = key[0]
        n = self.raw.shape[0]
        if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
            index = int(key) + n if key < 0 else int(key)
            if not 0 <= index < n:
                raise IndexError(f"{self.scene_id}: {self.path}: index {int(key)} out of range for {n} frames")
            return index, index + 1, True
        if isinstance(key, slice) and key.step in (None, 1):
            start, stop, _ = key.indices(n)
            return start, max(start, stop), False
        return None

    def __getitem__(self, key: Any) -> np.ndarray:
        try:
            frames = self._frames(key) if self._direct is not None else None
            if frames is not None:
                start, stop, squeeze = frames
                out = self._direct.read(start, stop)
                if self._verify:
                    self._check_block(out, start)
                return out[0] if squeeze else out
            if not self._checksummed:
                return self.raw[key]
            return self._read_checked(key)
        except (IndexError, ZendarFormatError):
            raise
        except stores.DECODE_ERRORS as exc:
            raise self._corrupt(exc) from exc

    def read_into(self, start: int, stop: int, out: np.ndarray) -> None:
        """Read frames ``start:stop`` into the preallocated ``out`` [stop - start, ...].

        Local raw stores with one frame per chunk are read straight into ``out``
        (no intermediate copy: the loader uses this to fill shared-memory batch
        buffers); anything else goes through the backend and is copied.
        """
        direct_ok = (
            self._direct is not None and out.dtype == self.dtype and out.flags.c_contiguous
        )
        try:
            if direct_ok:
                self._direct.read_into(start, stop, out)
                if self._verify:
                    self._check_block(out, start)
            elif not self._checksummed:
                out[...] = self.raw[start:stop]
            else:
                out[...] = self._read_checked(slice(start, stop))
        except ZendarFormatError:
            raise
        except stores.DECODE_ERRORS as exc:
            raise self._corrupt(exc) from exc

    # -- stores that record checksums: missing chunks are errors, verification on request --
    def _row_span(self, key: Any) -> tuple[int, int, tuple] | None:
        """(first row, end row, key with a non-negative axis-0 index or forward slice) of a selection.

        None for selections this does not analyse (Ellipsis, new axes, index arrays, a
        backward slice): those read every row.
        """
        parts = key if isinstance(key, tuple) else (key,)
        if not parts or any(p is Ellipsis or p is None or not isinstance(p, (int, np.integer, slice)) for p in parts):
            return None
        first, n = parts[0], self.raw.shape[0]
        if isinstance(first, slice):
            start, stop, step = first.indices(n)
            if step < 0:
                return None
            stop = max(start, stop)
            return start, stop, (slice(start, stop, step), *parts[1:])
        index = int(first) + n if first < 0 else int(first)
        if not 0 <= index < n:
            raise IndexError(f"{self.scene_id}: {self.path}: index {int(first)} out of range for {n} rows")
        return index, index + 1, (index, *parts[1:])

    def _read_checked(self, key: Any) -> np.ndarray:
        """Read ``key`` from a store that records checksums: no missing chunk, and verified on request."""
        shape = self.shape
        if not shape:
            block = np.asarray(self.raw[...])
            if self._verify:
                self._check_block(block, 0)
            return block[key]
        chunks = self.chunks or shape
        span = self._row_span(key)
        lo, hi, normal = span if span is not None else (0, shape[0], key)
        grid = checksums.grid_shape(shape, chunks)
        first_chunk, end_chunk = lo // chunks[0], -(-hi // chunks[0])
        if not stores.is_zarr(self.raw) and self._missing is None:
            self._missing = set(stores.missing_chunks(self.raw))
        for coords in np.ndindex(max(0, end_chunk - first_chunk), *grid[1:]) if self._missing != set() else ():
            coords = (coords[0] + first_chunk, *coords[1:])
            stored = coords not in self._missing if self._missing is not None else stores.chunk_stored(self.raw, coords)
            if not stored:
                raise ZendarFormatError(
                    f"{self.scene_id}: {self.path}: expected every chunk stored (the store records checksums), "
                    f"found chunk {list(coords)} missing"
                )
        if not self._verify:
            return self.raw[key]
        start, stop = first_chunk * chunks[0], min(shape[0], end_chunk * chunks[0])
        block = np.asarray(self.raw[start:stop])
        self._check_block(block, start)
        if span is None:
            return block[key]
        first = normal[0]
        first = first - start if isinstance(first, int) else slice(first.start - start, first.stop - start, first.step)
        return block[(first, *normal[1:])]

    def _check_block(self, block: np.ndarray, start: int) -> None:
        """Compare each chunk of ``block`` (rows from ``start``, a chunk boundary, every other axis whole)."""
        shape = self.shape
        chunks = self.chunks or shape or (1,)
        grid = checksums.grid_shape(shape, chunks)
        for coords, index, found in checksums.array_chunk_checksums(block, start, chunks, grid):
            if found != self._crc32c[index]:
                raise ZendarFormatError(
                    f"{self.scene_id}: {self.path}: chunk {list(coords)}: expected {checksums.ALGORITHM} "
                    f"{self._crc32c[index]:08x} (recorded when written), found {found:08x}; the chunk is corrupt"
                )

    def _corrupt(self, exc: BaseException) -> ZendarFormatError:
        return ZendarFormatError(
            f"{self.scene_id}: {self.path}: expected readable {self.dtype.name} chunks, "
            f"found a truncated or corrupt chunk ({type(exc).__name__}: {exc})"
        )

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        data = self[...]
        return data if dtype is None else data.astype(dtype, copy=False)

    def __repr__(self) -> str:
        return f"StoredArray({self.scene_id}:{self.path}, shape={self.shape}, dtype={self.dtype.name})"


class SceneReader:
    """One scene store, opened read-only and lazily.

    Opening checks attributes and array metadata (no bulk data).  The reader
    pickles as its location: a copy in another process (DataLoader workers
    under spawn) or a forked child reopens its own handle on first use.

    Attributes
    ----------
    scene_id : str
    enu_origin : dict
        ``{"lat_deg", "lon_deg", "height_m"}`` of the scene's ENU frame.
    calibration : Calibration
    backend : {"zarr", "hdf5"}
    location : str
        Path or URL of the store.
    records_checksums : bool
        The store records a checksum of every chunk (docs/format.md).
    verify_checksums : bool
        Every read checks the chunks it touches against their recorded checksums
        (whole chunks are read and hashed; off by default, the fast path).  Stores that
        record no checksums read as usual.
    """

    def __init__(
        self,
        location: str | os.PathLike,
        storage_options: dict | None = None,
        *,
        scene_id: str | None = None,
        verify_checksums: bool = False,
    ) -> None:
        self.location = os.fspath(location)
        self.storage_options = dict(storage_options or {})
        self._expected_scene_id = scene_id
        self.verify_checksums = bool(verify_checksums)
        self._crc32c: dict[str, list[int]] = {}
        self._label = scene_id or self.location
        self._store: stores.OpenStore | None = None
        self._pid: int | None = None
        self._timestamps: dict[str, np.ndarray] = {}
        self._offsets: dict[str, np.ndarray] = {}
        self._open()

    def _open(self) -> None:
        try:
            store = stores.open_store(self.location, self.storage_options)
        except FileNotFoundError:
            raise ZendarFormatError(f"{self._label}: expected a scene store at {self.location}, found none") from None
        except (OSError, ValueError) as exc:
            raise ZendarFormatError(f"{self._label}: {self.location}: expected a readable zarr/HDF5 store ({exc})") from None
        meta, problems = check_scene_metadata(store.root, self._label, self._expected_scene_id)
        if problems:
            store.close()
            raise ZendarFormatError("; ".join(problems), problems)
        self._store = store
        self._pid = os.getpid()
        self.backend: str = store.backend
        self.scene_id: str = meta.scene_id
        self.enu_origin: dict = meta.enu_origin
        self.calibration: Calibration = meta.calibration
        self.attrs: dict = meta.attrs
        self.streams: list[str] = meta.streams
        self.records_checksums: bool = meta.attrs.get(checksums.ROOT_ATTR) == checksums.ALGORITHM

    @property
    def _root(self) -> Any:
        if self._store is None or self._pid != os.getpid():
            # A forked child must not share the parent's file handle.
            self._store = None
            self._open()
        return self._store.root

    @property
    def store_root(self) -> Any:
        """The backend's root group (``zarr.Group`` or ``h5py.File``), opened read-only."""
        return self._root

    # -- pickling: location only --------------------------------------------
    def __getstate__(self) -> dict:
        return {
            "location": self.location,
            "storage_options": self.storage_options,
            "expected_scene_id": self._expected_scene_id,
            "verify_checksums": self.verify_checksums,
            "timestamps": self._timestamps,
            "offsets": self._offsets,
            "metadata": (
                self.backend, self.scene_id, self.enu_origin, self.calibration, self.attrs, self.streams,
                self.records_checksums,
            ),
        }

    def __setstate__(self, state: dict) -> None:
        self.location = state["location"]
        self.storage_options = state["storage_options"]
        self._expected_scene_id = state["expected_scene_id"]
        self.verify_checksums = state["verify_checksums"]
        self._crc32c = {}
        self._label = self._expected_scene_id or self.location
        self._timestamps = state["timestamps"]
        self._offsets = state["offsets"]
        (
            self.backend, self.scene_id, self.enu_origin, self.calibration, self.attrs, self.streams,
            self.records_checksums,
        ) = state["metadata"]
        self._store = None
        self._pid = None

    def __enter__(self) -> "SceneReader":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"SceneReader({self.scene_id!r}, backend={self.backend!r}, streams={self.streams})"

    def close(self) -> None:
        """Close the store handle (it reopens on next use)."""
        if self._store is not None and self._pid == os.getpid():
            self._store.close()
        self._store = None

    # -- access --------------------------------------------------------------
    def sensors(self, group: str) -> list[str]:
        """Sorted sensor names under ``radar``, ``sar``, ``camera`` or ``lidar``."""
        if group not in SENSOR_GROUPS:
            raise ValueError(f"group: expected one of {SENSOR_GROUPS}, found {group!r}")
        return sorted(s.split("/", 1)[1] for s in self.streams if s.startswith(group + "/"))

    def has(self, path: str) -> bool:
        """Whether an array or group exists at ``path`` inside the scene."""
        try:
            return stores.get_node(self._root, path.strip("/")) is not None
        except stores.MetadataError as exc:
            raise ZendarFormatError(f"{self.scene_id}: {exc}") from None

    def array(self, path: str) -> StoredArray:
        """The lazy array at ``path`` (e.g. ``"radar/left/cube"``)."""
        try:
            node = stores.get_node(self._root, path.strip("/"))
        except stores.MetadataError as exc:
            raise ZendarFormatError(f"{self.scene_id}: {exc}") from None
        if node is None or not stores.is_array(node):
            raise ZendarFormatError(f"{self.scene_id}: {path}: expected an array, found {'a group' if node is not None else 'nothing'}")
        path = path.strip("/")
        crc32c = None
        if self.verify_checksums and self.records_checksums:
            if path not in self._crc32c:
                count = checksums.chunk_count(tuple(node.shape), stores.chunk_shape(node) or tuple(node.shape))
                try:
                    self._crc32c[path] = checksums.decode(stores.read_attrs(node).get(checksums.ARRAY_ATTR), count)
                except ValueError as exc:
                    raise ZendarFormatError(f"{self.scene_id}: {path}: {checksums.ARRAY_ATTR}: {exc}") from None
            crc32c = self._crc32c[path]
        return StoredArray(node, self.scene_id, path, checksummed=self.records_checksums, verify_crc32c=crc32c)

    def sar_magnitude_only(self, sensor: str) -> bool:
        """Whether ``sar/<sensor>`` holds magnitudes only (group attribute ``magnitude_only``; docs/format.md).

        Its ``image`` is then real (uint32 or float32, exact) or, in stores written before magnitude
        images existed, complex64 with the magnitude in the real part; either way it has no phase.
        """
        stream = f"sar/{sensor}"
        if stream not in self.streams:
            raise ZendarFormatError(f"{self.scene_id}: {stream}: expected one of the scene's SAR streams {self.sensors('sar')}, found none")
        return stores.read_attrs(stores.get_node(self._root, stream)).get(SAR_MAGNITUDE_ONLY_ATTR) is True

    def timestamps(self, stream: str) -> np.ndarray:
        """``timestamp_ns`` [N] int64 of a stream (``"radar/left"``, ``"tracklog"``, ``"labels/moving_cars"``…).

        Raises ZendarFormatError unless strictly increasing (label timestamps may repeat).
        """
        stream = stream.strip("/")
        if stream not in self._timestamps:
            if stream not in self.streams:
                raise ZendarFormatError(
                    f"{self.scene_id}: {stream}: expected one of the scene's streams {self.streams}, found no such stream"
                )
            values = np.asarray(self.array(f"{stream}/timestamp_ns")[...], dtype=np.int64)
            steps = np.diff(values)
            bad = np.flatnonzero(steps < 0 if stream == LABELS else steps <= 0)
            if bad.size:
                i = int(bad[0]) + 1
                order = "non-decreasing" if stream == LABELS else "strictly increasing"
                raise ZendarFormatError(
                    f"{self.scene_id}: {stream}/timestamp_ns: expected {order} timestamps, "
                    f"found {values[i]} at index {i} after {values[i - 1]}"
                )
            self._timestamps[stream] = values
        return self._timestamps[stream]

    def lidar_points(self, sensor: str, frame: int) -> np.ndarray:
        """Points ``[P, 4]`` float32 (x, y, z, intensity; lidar frame, metres) of one sweep."""
        stream = f"lidar/{sensor}"
        offsets = self._lidar_offsets(stream)
        n = offsets.shape[0] - 1
        if not -n <= frame < n:
            raise IndexError(f"{self.scene_id}: {stream}: frame {frame} out of range for {n} sweeps")
        frame %= n
        return self.array(f"{stream}/points")[offsets[frame] : offsets[frame + 1]]

    def lidar_sweeps(self, sensor: str) -> tuple[np.ndarray, np.ndarray]:
        """Every sweep of a lidar in one read: points ``[P, 4]`` float32 (as :meth:`lidar_points`) and
        ``[N + 1]`` int64 offsets, sweep ``k`` being ``points[offsets[k]:offsets[k + 1]]``."""
        stream = f"lidar/{sensor}"
        offsets = self._lidar_offsets(stream)
        return np.asarray(self.array(f"{stream}/points")[...]), offsets

    def _lidar_offsets(self, stream: str) -> np.ndarray:
        if stream not in self._offsets:
            offsets = np.asarray(self.array(f"{stream}/offsets")[...], dtype=np.int64)
            total = self.array(f"{stream}/points").shape[0]
            if offsets[0] != 0 or offsets[-1] != total or np.any(np.diff(offsets) < 0):
                raise ZendarFormatError(
                    f"{self.scene_id}: {stream}/offsets: expected non-decreasing offsets from 0 to {total} (rows of points), "
                    f"found {offsets[0]} … {offsets[-1]}"
                )
            self._offsets[stream] = offsets
        return self._offsets[stream]

    def ego_poses(self) -> EgoPoses:
        """The scene's ego pose at any time of its tracklog (IMU calibration and ENU origin applied).

        Reads the whole tracklog; build it once per scene.
        """
        tracklog = PoseInterpolator(
            self.timestamps("tracklog"), self.array("tracklog/position_ecef")[...], self.array("tracklog/attitude_wxyz")[...]
        )
        origin = self.enu_origin
        return EgoPoses(
            tracklog, ego_T_sensor(self.calibration.sensors["imu"]),
            LocalENU(origin["lat_deg"], origin["lon_deg"], origin["height_m"]),
        )

    def labels(self) -> dict[str, np.ndarray] | None:
        """Every field of ``labels/moving_cars`` as 1-D arrays, or None when labels are withheld."""
        if LABELS not in self.streams:
            return None
        names = [*LABEL_FIELD_NAMES, *(name for name in LABEL_OPTIONAL_FIELD_NAMES if self.has(f"{LABELS}/{name}"))]
        return {name: self.array(f"{LABELS}/{name}")[...] for name in names}
