"""Ground truth of a split for the evaluator: ``{"frames": {frame_id: [car, ...]}}``.

Every frame of the first SAR stream (in name order) of each labelled scene of
the split appears, frames without cars with an empty list.  A car is
``{"x", "y", "length", "width", "yaw", "vx", "vy", "track_id"}`` in the ego
frame at the frame's timestamp (metres, radians, m/s), plus the optional label
fields (``num_radar_scatterers``, ``num_lidar_points``) where the scene has them.
"""

from __future__ import annotations

import errno
import os
import pathlib

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format.reader import SceneReader, open_dataset
from zendar_dataset.format.schema import CAR_FIELDS, LABEL_OPTIONAL_FIELD_NAMES, LABELS, frame_id
from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.output_location import refuse_output_inside


def scene_ground_truth(scene: SceneReader) -> dict[str, list[dict]] | None:
    """Cars per frame of one scene, or None when its labels are withheld."""
    labels = scene.labels()
    if labels is None:
        return None
    sar_sensors = scene.sensors("sar")
    if not sar_sensors:
        raise ZendarFormatError(f"{scene.scene_id}: {LABELS}: expected a SAR stream whose frames the labels refer to, found none")
    stream = f"sar/{sar_sensors[0]}"
    frame_timestamps = scene.timestamps(stream)
    label_timestamps = labels["timestamp_ns"]
    unknown = ~np.isin(label_timestamps, frame_timestamps)
    if np.any(unknown):
        raise ZendarFormatError(
            f"{scene.scene_id}: {LABELS}/timestamp_ns: expected timestamps of {stream} frames, "
            f"found {int(np.count_nonzero(unknown))} that are not (first {int(label_timestamps[unknown][0])})"
        )
    frames: dict[str, list[dict]] = {frame_id(scene.scene_id, t): [] for t in frame_timestamps}
    # Optional label fields (docs/format.md) ride along; the evaluator ignores what it does not use.
    names = [*CAR_FIELDS, *(name for name in LABEL_OPTIONAL_FIELD_NAMES if name in labels)]
    columns = {name: labels[name].tolist() for name in names}
    for row, timestamp_ns in enumerate(label_timestamps.tolist()):
        frames[frame_id(scene.scene_id, timestamp_ns)].append({name: columns[name][row] for name in names})
    return frames


def ground_truth_frames(root: str | os.PathLike, split: str, storage_options: dict | None = None) -> dict[str, list[dict]]:
    """Cars per frame id of every labelled scene of ``split``.

    Raises
    ------
    ZendarFormatError
        For an unknown split, a split without any labelled scene (labels
        withheld), or labels that refer to no SAR frame.
    """
    index = open_dataset(root, storage_options)
    frames: dict[str, list[dict]] = {}
    labelled = 0
    for scene_id in index.scene_ids(split):
        with index.open_scene(scene_id) as scene:
            scene_frames = scene_ground_truth(scene)
        if scene_frames is not None:
            labelled += 1
            frames.update(scene_frames)
    if not labelled:
        raise ZendarFormatError(
            f"{root}: split {split!r}: expected labelled scenes, found none with {LABELS} (labels withheld?)"
        )
    return frames


def export_ground_truth(
    root: str | os.PathLike,
    split: str,
    out_path: str | os.PathLike,
    *,
    overwrite: bool = False,
    storage_options: dict | None = None,
) -> int:
    """Write ``{"frames": ...}`` of ``split`` to ``out_path`` atomically; returns the number of frames.

    Raises
    ------
    ZendarError
        When ``out_path`` is inside the dataset ``root`` (links resolved).
    FileExistsError
        When ``out_path`` exists and ``overwrite`` is false.
    IsADirectoryError, NotADirectoryError
        When ``out_path`` is a directory, or a parent of it is a file.
    """
    out_path = pathlib.Path(out_path)
    refuse_output_inside(out_path, datasets=(root,), what="output")
    if out_path.is_dir():
        raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), str(out_path))
    if out_path.exists() and not overwrite:
        raise FileExistsError(errno.EEXIST, "exists already (pass overwrite=True to replace it)", str(out_path))
    frames = ground_truth_frames(root, split, storage_options)
    for parent in (out_path.parent, *out_path.parent.parents):
        if parent.exists():
            if not parent.is_dir():
                raise NotADirectoryError(errno.ENOTDIR, os.strerror(errno.ENOTDIR), str(parent))
            break
    out_path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out_path, {"frames": frames})
    return len(frames)
