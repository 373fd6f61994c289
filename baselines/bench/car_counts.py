"""Distinct labelled cars per range band and split, by kind of motion: how much the data can tell.

A car is one ``track_id`` of one scene (track ids are per scene). It counts in a band when at least
one of its labelled frames puts its centre in the band (the evaluator's bands, at the range of its
label). Its kind of motion comes from its heading (label ``yaw``, relative to the ego's x axis) and the
ego's own heading (from the poses):

- **turning**: its heading over ground (label yaw + ego yaw, unwrapped) spans at least
  :data:`TURN_SPAN_RAD` over its labelled frames — a car that turns at an intersection changes its
  course by about 90°; a straight car whose relative heading changes only because the ego turns
  keeps its course and is not turning;
- otherwise by its mean heading relative to the ego: **ahead** (within 45° of the ego's heading),
  **oncoming** (within 45° of the opposite heading), **crossing** (in between).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from zendar_dataset.eval.protocol import BAND_NAMES, in_band, range_m
from zendar_dataset.format.reader import DatasetIndex

#: Kinds of motion, in the order tables list them.
KINDS = ("ahead", "oncoming", "crossing", "turning")
#: A car whose course over ground changes by at least this much is turning (half an intersection turn).
TURN_SPAN_RAD = np.pi / 4
#: Within this of the ego's heading: ahead; within this of the opposite: oncoming.
HEADING_TOLERANCE_RAD = np.pi / 4


@dataclass(frozen=True)
class LabelRows:
    """Labelled cars of some scenes, one row per car per frame (N rows).

    Attributes
    ----------
    scene_ids : tuple of str
        The scenes (S,).
    scene : numpy.ndarray
        int64 (N,): index into ``scene_ids``.
    timestamp_ns : numpy.ndarray
        int64 (N,): the frame's timestamp.
    track_id : numpy.ndarray
        int64 (N,): the car's identity within its scene.
    x_m, y_m : numpy.ndarray
        float64 (N,): car centre, ego frame at the frame's timestamp, metres.
    yaw_rad : numpy.ndarray
        float64 (N,): car heading relative to the ego's x axis, radians.
    ego_yaw_rad : numpy.ndarray
        float64 (N,): the ego's heading in the scene's local ENU frame at the frame, radians.
    """

    scene_ids: tuple[str, ...]
    scene: np.ndarray
    timestamp_ns: np.ndarray
    track_id: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    yaw_rad: np.ndarray
    ego_yaw_rad: np.ndarray

    def of_scenes(self, scene_ids: tuple[str, ...] | list[str]) -> LabelRows:
        """The rows of the given scenes only (scene indices keep referring to ``scene_ids``)."""
        wanted = np.isin(self.scene, [k for k, s in enumerate(self.scene_ids) if s in set(scene_ids)])
        return LabelRows(self.scene_ids, *(column[wanted] for column in (
            self.scene, self.timestamp_ns, self.track_id, self.x_m, self.y_m, self.yaw_rad, self.ego_yaw_rad)))


def read_label_rows(dataset: DatasetIndex, scene_ids: list[str] | tuple[str, ...]) -> LabelRows:
    """The labels of ``scene_ids`` (scenes whose labels are withheld contribute nothing)."""
    columns: dict[str, list[np.ndarray]] = {name: [] for name in
                                            ("scene", "timestamp_ns", "track_id", "x", "y", "yaw", "ego_yaw")}
    for k, scene_id in enumerate(scene_ids):
        with dataset.open_scene(scene_id) as reader:
            labels = reader.labels()
            if labels is None or len(labels["timestamp_ns"]) == 0:
                continue
            poses = reader.ego_poses()
            stamps, inverse = np.unique(labels["timestamp_ns"], return_inverse=True)
            ego_yaw = np.array([_heading(poses.enu_T_ego(int(t)).rotation) for t in stamps])[inverse]
        columns["scene"].append(np.full(len(labels["timestamp_ns"]), k, dtype=np.int64))
        columns["ego_yaw"].append(ego_yaw)
        for name in ("timestamp_ns", "track_id", "x", "y", "yaw"):
            columns[name].append(np.asarray(labels[name]))
    joined = {name: np.concatenate(parts) if parts else np.zeros(0) for name, parts in columns.items()}
    return LabelRows(
        tuple(scene_ids), joined["scene"].astype(np.int64), joined["timestamp_ns"].astype(np.int64),
        joined["track_id"].astype(np.int64), joined["x"].astype(np.float64), joined["y"].astype(np.float64),
        joined["yaw"].astype(np.float64), joined["ego_yaw"].astype(np.float64),
    )


def _heading(rotation: np.ndarray) -> float:
    """Heading (rad, from x towards y) of a body whose axes ``rotation`` [3, 3] expresses."""
    return float(np.arctan2(rotation[1, 0], rotation[0, 0]))


def motion_kind(yaw_rad: np.ndarray, ego_yaw_rad: np.ndarray) -> str:
    """The kind of motion of one car from its labelled frames, in time order (see the module docstring).

    Parameters
    ----------
    yaw_rad
        float64 (T,): the car's heading relative to the ego's x axis, radians.
    ego_yaw_rad
        float64 (T,): the ego's heading over ground at the same frames, radians.
    """
    course = np.unwrap(yaw_rad + ego_yaw_rad)
    if np.ptp(course) >= TURN_SPAN_RAD:
        return "turning"
    relative = abs(float(np.angle(np.mean(np.exp(1j * yaw_rad)))))
    if relative <= HEADING_TOLERANCE_RAD:
        return "ahead"
    if relative >= np.pi - HEADING_TOLERANCE_RAD:
        return "oncoming"
    return "crossing"


def distinct_cars(rows: LabelRows) -> dict[str, dict[str, Any]]:
    """Distinct cars per band of the evaluator, with their kinds of motion.

    Returns
    -------
    dict
        ``{band: {"cars": int, "by_kind": {kind: int}}}`` for every band of
        :data:`~zendar_dataset.eval.protocol.BAND_NAMES`; a car counts once in each band it enters.
    """
    r_m = range_m(rows.x_m, rows.y_m)
    order = np.lexsort((rows.timestamp_ns, rows.track_id, rows.scene))
    car_key = np.stack([rows.scene[order], rows.track_id[order]], axis=1)
    starts = np.flatnonzero(np.r_[True, np.any(car_key[1:] != car_key[:-1], axis=1)]) if len(order) else np.zeros(0, int)
    ends = np.r_[starts[1:], len(order)]
    counts = {band: {"cars": 0, "by_kind": dict.fromkeys(KINDS, 0)} for band in BAND_NAMES}
    for start, end in zip(starts, ends):
        rows_of_car = order[start:end]
        kind = motion_kind(rows.yaw_rad[rows_of_car], rows.ego_yaw_rad[rows_of_car])
        for band in BAND_NAMES:
            if np.any(in_band(r_m[rows_of_car], band)):
                counts[band]["cars"] += 1
                counts[band]["by_kind"][kind] += 1
    return counts


def split_car_counts(dataset: DatasetIndex, labelled_scene_ids: tuple[str, ...] | list[str]) -> dict[str, Any]:
    """:func:`distinct_cars` of the training split's labelled part (``labelled_scene_ids``), the training,
    validation and test splits: ``{"train_labelled", "train", "val", "test"}``."""
    train = read_label_rows(dataset, dataset.scene_ids("train"))
    return {
        "train_labelled": distinct_cars(train.of_scenes(labelled_scene_ids)),
        "train": distinct_cars(train),
        "val": distinct_cars(read_label_rows(dataset, dataset.scene_ids("val"))),
        "test": distinct_cars(read_label_rows(dataset, dataset.scene_ids("test"))),
    }


def markdown_car_counts(counts_by_split: dict[str, dict[str, dict[str, Any]]]) -> str:
    """A Markdown table: one line per split, per band the distinct cars (ahead/oncoming/crossing/turning)."""
    lines = [
        "| split | " + " | ".join(BAND_NAMES) + " |",
        "|---|" + "--:|" * len(BAND_NAMES),
    ]
    for split, counts in counts_by_split.items():
        cells = [f"{counts[band]['cars']} ({'/'.join(str(counts[band]['by_kind'][k]) for k in KINDS)})"
                 for band in BAND_NAMES]
        lines.append(f"| {split} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + f"\n\nDistinct labelled cars per band (by kind: {'/'.join(KINDS)}).\n"
