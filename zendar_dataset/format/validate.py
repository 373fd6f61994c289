"""Check a dataset or a scene against format v1 and report every violation at once.

Unlike opening a scene for reading (metadata only), validation also reads
every chunk once: it finds missing, truncated and corrupt chunks, timestamps
out of order, bad lidar offsets, non-unit quaternions and labels that point
at no SAR frame.  Each message names the scene, the path inside it, what was
expected and what was found.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import stores
from zendar_dataset.format.checks import check_scene_metadata
from zendar_dataset.format.reader import _read_text, check_dataset_json
from zendar_dataset.format.schema import DATASET_JSON, DETECTIONS, LABELS, TRACKLOG, stream_specs

_QUATERNION_NORM_TOLERANCE = 1e-6
# Arrays stored one frame per chunk: (stream group, array name).
_FRAME_CHUNKED = {("radar", "cube"), ("sar", "image"), ("camera", "image")}


def _read_all(array: Any, scene: str, path: str, problems: list[str]) -> np.ndarray | None:
    """Read an array block by block along axis 0, reporting missing and undecodable chunks."""
    missing = stores.count_missing_chunks(array)
    if missing:
        problems.append(f"{scene}: {path}: expected every chunk stored, found {missing} missing")
    step = (stores.chunk_shape(array) or array.shape or (1,))[0] or 1
    keep = array.size * np.dtype(array.dtype).itemsize <= 64 * 2**20
    blocks = []
    for start in range(0, array.shape[0], step):
        try:
            block = array[start : start + step]
        except stores.DECODE_ERRORS as exc:
            problems.append(
                f"{scene}: {path}: expected readable chunks, found a truncated or corrupt chunk at rows "
                f"{start}:{start + step} ({type(exc).__name__}: {exc})"
            )
            return None
        if keep:
            blocks.append(block)
    if not keep:
        return None
    return np.concatenate(blocks) if blocks else np.zeros(array.shape, dtype=array.dtype)


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


def _check_stream_data(root: Any, scene: str, stream: str, problems: list[str]) -> dict[str, np.ndarray]:
    group = stream.split("/", 1)[0]
    values: dict[str, np.ndarray] = {}
    for spec in stream_specs(stream):
        path = f"{stream}/{spec.name}"
        node = stores.get_node(root, path)
        if node is None or not stores.is_array(node) or np.dtype(node.dtype) != spec.dtype:
            continue  # reported by the metadata check
        if (group, spec.name) in _FRAME_CHUNKED:
            chunks = stores.chunk_shape(node)
            want = (1, *node.shape[1:])
            if chunks != want:
                problems.append(f"{scene}: {path}: expected one chunk per frame {list(want)}, found chunks {list(chunks) if chunks else None}")
        data = _read_all(node, scene, path, problems)
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
        points = stores.get_node(root, f"{stream}/{'points' if group == 'lidar' else 'range_m'}")
        total = int(points.shape[0]) if points is not None and stores.is_array(points) else None
        if offsets.size and (offsets[0] != 0 or (total is not None and offsets[-1] != total) or np.any(np.diff(offsets) < 0)):
            problems.append(
                f"{scene}: {stream}/offsets: expected non-decreasing offsets from 0 to {total} (rows of points), "
                f"found first {offsets[0]}, last {offsets[-1]}, {int(np.count_nonzero(np.diff(offsets) < 0))} decreasing steps"
            )
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
    return values


def _validate_open_store(store: stores.OpenStore, scene: str, expected_scene_id: str | None) -> list[str]:
    meta, problems = check_scene_metadata(store.root, scene, expected_scene_id)
    data = {stream: _check_stream_data(store.root, scene, stream, problems) for stream in meta.streams}
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
    location: str | os.PathLike, scene_id: str | None = None, storage_options: dict | None = None
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
        problems = _validate_open_store(store, scene, scene_id)
    finally:
        store.close()
    stale = stores.consolidated_mismatches(location, storage_options)
    if stale:
        problems.append(
            f"{scene}: zarr.json: expected consolidated metadata matching the store, found {len(stale)} "
            f"differing paths (first {stale[0]!r}); re-run zarr.consolidate_metadata"
        )
    return problems


def validate_dataset(root: str | os.PathLike, storage_options: dict | None = None) -> list[str]:
    """Every violation of format v1 in a dataset root: ``dataset.json`` and every scene it lists."""
    root = os.fspath(root)
    location = stores.join_location(root, DATASET_JSON)
    try:
        document = json.loads(_read_text(location, storage_options))
    except FileNotFoundError:
        return [f"{root}: /: expected {DATASET_JSON} at the dataset root, found none"]
    except json.JSONDecodeError as exc:
        return [f"{location}: expected JSON, found invalid text ({exc})"]
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
            problems.extend(validate_scene(stores.join_location(root, path), scene_id, storage_options))
    return problems


def check_dataset(root: str | os.PathLike, storage_options: dict | None = None) -> None:
    """Raise :class:`ZendarFormatError` listing every violation, if any."""
    problems = validate_dataset(root, storage_options)
    if problems:
        raise ZendarFormatError(f"{root}: {len(problems)} format violations: " + "; ".join(problems), problems)
