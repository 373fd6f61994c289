"""Check a dataset or a scene against format v1 and report every violation at once.

Unlike opening a scene for reading (metadata only), validation also reads
every chunk once: it finds missing, truncated and corrupt chunks, timestamps
out of order, bad lidar offsets, non-unit quaternions and labels that point
at no SAR frame.  Each message names the scene, the path inside it, what was
expected and what was found.
"""

from __future__ import annotations

import os
from collections import Counter
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import checksums, stores
from zendar_dataset.format.checks import check_scene_metadata
from zendar_dataset.format.reader import check_dataset_json, read_dataset_json
from zendar_dataset.format.schema import DATASET_JSON, DETECTIONS, LABEL_OPTIONAL_FIELDS, LABELS, TRACKLOG, optional_specs, stream_specs

_QUATERNION_NORM_TOLERANCE = 1e-6
_KEEP_BYTES = 64 * 2**20  # arrays up to this size are kept in memory for the value checks
_LISTED = 5  # chunk coordinates named in a message before "…"
NO_CHECKSUMS_NOTE = (
    "note: the store records no chunk checksums (written by another tool or an older writer): "
    "its chunks cannot be verified, and chunks not stored read as the fill value"
)


def _listed(coords: list[tuple[int, ...]]) -> str:
    shown = ", ".join(str(list(c)) for c in coords[:_LISTED])
    return shown + (", …" if len(coords) > _LISTED else "")


def _read_all(array: Any, scene: str, path: str, problems: list[str], checksummed: bool) -> np.ndarray | None:
    """Read an array chunk row by chunk row, reporting missing, undecodable and altered chunks.

    In a store that records checksums, every chunk must be stored and hash to its
    recorded CRC-32C; every failure is listed (scene, path, chunk coordinates).
    Returns the values when the array is small enough to keep and every chunk was readable.
    """
    shape = tuple(array.shape)
    chunks = stores.chunk_shape(array) or shape or (1,)
    grid = checksums.grid_shape(shape, chunks)
    expected: list[int] | None = None
    missing: set[tuple[int, ...]] = set()
    if checksummed:
        expected = checksums.decode(stores.read_attrs(array).get(checksums.ARRAY_ATTR), checksums.chunk_count(shape, chunks))
        try:
            absent = stores.missing_chunks(array)
        except stores.DECODE_ERRORS as exc:
            problems.append(f"{scene}: {path}: expected a readable chunk index, found {type(exc).__name__}: {exc}")
            return None
        missing = set(absent)
        if absent:
            problems.append(
                f"{scene}: {path}: expected every chunk stored (the store records checksums), found "
                f"{len(absent)} missing: chunk {_listed(absent)}"
            )
    keep = int(np.prod(shape, dtype=object)) * np.dtype(array.dtype).itemsize <= _KEEP_BYTES
    blocks, unreadable, altered = [], [], []
    for start in range(0, shape[0], chunks[0]) if shape else [None]:
        try:
            block = np.asarray(array[start : start + chunks[0]] if shape else array[...])
        except stores.DECODE_ERRORS as exc:
            # Blocks span whole chunk rows; the format's arrays have one chunk per row block.
            where = [start // chunks[0], *(0 if g == 1 else "*" for g in grid[1:])] if shape else []
            unreadable.append(
                f"{scene}: {path}: chunk {where}: expected a readable chunk (rows {start}:{start + chunks[0]}), "
                f"found a truncated or corrupt one ({type(exc).__name__}: {exc})"
            )
            continue
        if expected is not None:
            for coords, index, found in checksums.array_chunk_checksums(block, start or 0, chunks, grid):
                if coords not in missing and found != expected[index]:
                    altered.append(coords)
        if keep:
            blocks.append(block)
    problems.extend(unreadable)
    for coords in altered:
        problems.append(
            f"{scene}: {path}: chunk {list(coords)}: expected the values written ({checksums.ALGORITHM} "
            f"{expected[checksums.linear_index(coords, grid)]:08x} recorded), found different ones; the chunk is corrupt"
        )
    if not keep or unreadable:
        return None
    if not shape:
        return blocks[0]
    return np.concatenate(blocks) if blocks else np.zeros(shape, dtype=array.dtype)


def _check_increasing(values: np.ndarray, scene: str, path: str, strict: bool, problems: list[str]) -> None:
    steps = np.diff(values)
    bad = np.flatnonzero(steps <= 0 if strict else steps < 0)
    if bad.size:
        i = int(bad[0]) + 1
        order = "strictly increasing" if strict else "non-decreasing"
        problems.append(
            f"{scene}: {path}: expected {order} timestamps, found {values[i]} at index {i} after {values[i - 1]}"
            + (f" ({bad.size} places)" if bad.size > 1 else "")
        )


def _check_stream_data(
    arrays: dict[str, Any], root: Any, scene: str, stream: str, problems: list[str], checksummed: bool
) -> dict[str, np.ndarray]:
    """Read every array of ``stream`` whose metadata passed (``arrays``: path -> array) and check its values."""
    group = stream.split("/", 1)[0]
    values: dict[str, np.ndarray] = {}
    for spec in (*stream_specs(stream), *optional_specs(stream)):
        path = f"{stream}/{spec.name}"
        node = arrays.get(path)
        if node is None:
            continue  # reported by the metadata check
        data = _read_all(node, scene, path, problems, checksummed)
        if data is not None:
            values[spec.name] = data
            # Detections keep the release's NaN (a quantity not measured), as docs/format.md allows.
            if data.dtype.kind == "f" and group != DETECTIONS and not np.all(np.isfinite(data)):
                problems.append(f"{scene}: {path}: expected finite values, found {int(np.count_nonzero(~np.isfinite(data)))} NaN/inf")
    timestamps = values.get("timestamp_ns")
    if timestamps is not None:
        _check_increasing(timestamps, scene, f"{stream}/timestamp_ns", stream != LABELS, problems)
    if group in ("lidar", DETECTIONS) and "offsets" in values:
        offsets = values["offsets"]
        try:
            points = stores.get_node(root, f"{stream}/{'points' if group == 'lidar' else 'range_m'}")
        except stores.MetadataError:
            points = None  # reported by the metadata check; the offsets are checked without the total
        total = int(points.shape[0]) if points is not None and stores.is_array(points) else None
        if offsets.size and (offsets[0] != 0 or (total is not None and offsets[-1] != total) or np.any(np.diff(offsets) < 0)):
            problems.append(
                f"{scene}: {stream}/offsets: expected non-decreasing offsets from 0 to {total} (rows of points), "
                f"found first {offsets[0]}, last {offsets[-1]}, {int(np.count_nonzero(np.diff(offsets) < 0))} decreasing steps"
            )
    if group == DETECTIONS:
        rows = {s.name: int(arrays[f"{stream}/{s.name}"].shape[0]) for s in stream_specs(stream) if s.shape[0] == "P" and arrays.get(f"{stream}/{s.name}") is not None}
        if len(set(rows.values())) > 1:
            problems.append(f"{scene}: {stream}: expected every per-detection array to have the same rows, found {rows}")
    if group == "sar" and "aperture_ns" in values:
        aperture = values["aperture_ns"]
        bad = np.flatnonzero(aperture[:, 0] > aperture[:, 1])
        if bad.size:
            problems.append(f"{scene}: {stream}/aperture_ns: expected start <= end, found {bad.size} frames with start > end (first {int(bad[0])})")
    if stream == TRACKLOG and "attitude_wxyz" in values:
        norms = np.linalg.norm(values["attitude_wxyz"], axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > _QUATERNION_NORM_TOLERANCE)
        if bad.size:
            problems.append(
                f"{scene}: {TRACKLOG}/attitude_wxyz: expected unit quaternions, found {bad.size} with |q| != 1 (first at {int(bad[0])}: {norms[bad[0]]:.9f})"
            )
    if stream == LABELS:
        for name in ("length", "width"):
            if name in values and np.any(values[name] <= 0):
                problems.append(f"{scene}: {LABELS}/{name}: expected positive metres, found {int(np.count_nonzero(values[name] <= 0))} values <= 0")
        for spec in LABEL_OPTIONAL_FIELDS:
            if spec.name in values and np.any(values[spec.name] < 0):
                problems.append(f"{scene}: {LABELS}/{spec.name}: expected counts >= 0, found {int(np.count_nonzero(values[spec.name] < 0))} negative")
    return values


def _validate_open_store(
    store: stores.OpenStore, scene: str, expected_scene_id: str | None, notes: list[str] | None
) -> list[str]:
    meta, problems = check_scene_metadata(store.root, scene, expected_scene_id)
    # The nodes the schema checks do not open (a sensor's group, an extra array) must be readable too:
    # a dataset that validates must convert.
    for message in stores.unreadable_metadata(store.root):
        if f"{scene}: {message}" not in problems:
            problems.append(f"{scene}: {message}")
    if not meta.records_checksums and notes is not None:
        notes.append(f"{scene}: {NO_CHECKSUMS_NOTE}")
    data = {
        stream: _check_stream_data(meta.arrays, store.root, scene, stream, problems, meta.records_checksums)
        for stream in meta.streams
    }
    if LABELS in data:
        sar_streams = sorted(s for s in meta.streams if s.startswith("sar/"))
        label_timestamps = data[LABELS].get("timestamp_ns")
        if not sar_streams:
            problems.append(f"{scene}: {LABELS}: expected a SAR stream whose frames the labels refer to, found none")
        elif label_timestamps is not None and "timestamp_ns" in data[sar_streams[0]]:
            unknown = ~np.isin(label_timestamps, data[sar_streams[0]]["timestamp_ns"])
            if np.any(unknown):
                problems.append(
                    f"{scene}: {LABELS}/timestamp_ns: expected timestamps of {sar_streams[0]} frames, found "
                    f"{int(np.count_nonzero(unknown))} that are not (first {int(label_timestamps[unknown][0])})"
                )
    return problems


def validate_scene(
    location: str | os.PathLike,
    scene_id: str | None = None,
    storage_options: dict | None = None,
    notes: list[str] | None = None,
) -> list[str]:
    """Every violation of format v1 in one scene store (an empty list when valid).

    Parameters
    ----------
    location
        Path or fsspec URL of a ``.zarr`` or ``.h5`` store.
    scene_id
        The id the dataset gives this scene (checked against its attribute); messages use it.
    storage_options
        fsspec options for URLs.
    notes
        When given, receives remarks that are not violations (a store that records no checksums).
    """
    location = os.fspath(location)
    scene = scene_id or location
    try:
        store = stores.open_store(location, storage_options, consolidated=False)
    except FileNotFoundError:
        return [f"{scene}: /: expected a scene store at {location}, found none"]
    except (OSError, ValueError) as exc:
        return [f"{scene}: /: expected a readable zarr v3 or HDF5 store at {location}, found {type(exc).__name__}: {exc}"]
    try:
        problems = _validate_open_store(store, scene, scene_id, notes)
    finally:
        store.close()
    stale = stores.consolidated_mismatches(location, storage_options)
    if stale:
        problems.append(
            f"{scene}: zarr.json: expected consolidated metadata matching the store, found {len(stale)} "
            f"differing paths (first {stale[0]!r}); re-run zarr.consolidate_metadata"
        )
    return problems


def validate_dataset(
    root: str | os.PathLike, storage_options: dict | None = None, notes: list[str] | None = None
) -> list[str]:
    """Every violation of format v1 in a dataset root: ``dataset.json`` and every scene it lists.

    ``notes``, when given, receives remarks that are not violations (scenes whose stores record no checksums).
    """
    root = os.fspath(root)
    try:
        document = read_dataset_json(root, storage_options)
    except ZendarFormatError as exc:
        return list(exc.problems)
    problems = check_dataset_json(document, DATASET_JSON)
    if problems and not isinstance(document, dict):
        return problems
    splits = document.get("splits") if isinstance(document.get("splits"), dict) else {}
    seen = Counter(s for ids in splits.values() if isinstance(ids, list) for s in ids if isinstance(s, str))
    for scene_id, count in sorted(seen.items()):
        if count > 1:
            in_splits = sorted(k for k, ids in splits.items() if isinstance(ids, list) and scene_id in ids)
            problems.append(f"{DATASET_JSON}: splits: expected each scene in one split, found {scene_id!r} in {in_splits}")
    scenes = document.get("scenes") if isinstance(document.get("scenes"), dict) else {}
    for scene_id, entry in scenes.items():
        path = entry.get("path") if isinstance(entry, dict) else None
        if isinstance(path, str) and path.endswith(tuple(stores.SUFFIX_BACKEND)):
            problems.extend(validate_scene(stores.join_location(root, path), scene_id, storage_options, notes))
    return problems


def check_dataset(root: str | os.PathLike, storage_options: dict | None = None) -> None:
    """Raise :class:`ZendarFormatError` listing every violation, if any."""
    problems = validate_dataset(root, storage_options)
    if problems:
        raise ZendarFormatError(f"{root}: {len(problems)} format violations: " + "; ".join(problems), problems)
