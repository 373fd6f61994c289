"""Distinct labelled cars per range band: how many independent cars a split's scores rest on.

Frames of one car are strongly correlated, so what decides whether two methods can be told apart
in a band is how many *different* cars are labelled there, not how many label rows. A car counts
in a band when it is labelled there (centre range ``r = sqrt(x² + y²)`` in the ego frame, the
evaluator's half-open bands, :data:`~zendar_dataset.eval.protocol.BANDS_M`) in at least one frame;
one car can count in several bands. A car is a ``(scene id, track id)`` pair.

Each car also gets a kind of motion, read from its labels alone (the labels carry no kind):
``turning`` when its heading over ground changes by more than :data:`TURN_MIN_RAD` over its
labelled frames, otherwise by its heading relative to the ego's (median over its frames):
``ahead`` (same direction, within 45°), ``oncoming`` (opposite, within 45°) or ``crossing``.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BAND_NAMES, BANDS_M
from zendar_dataset.format.reader import DatasetIndex, SceneReader, open_dataset

#: Kinds of motion, in the order the simulator's traffic draws them.
MOTION_KINDS: tuple[str, ...] = ("ahead", "oncoming", "crossing", "turning")

#: A car whose heading over ground turns by more than this over its labelled frames is ``turning``
#: (the simulator's turning cars make a quarter turn; road curves turn a car ahead by less than
#: this over the few seconds it is labelled).
TURN_MIN_RAD = np.pi / 4

#: Relative headings within this of 0 (π) are ``ahead`` (``oncoming``); the rest ``crossing``.
SAME_DIRECTION_RAD = np.pi / 4


@dataclass(frozen=True)
class SceneLabels:
    """One scene's labels, as the counting needs them.

    Attributes
    ----------
    scene_id : str
    labels : mapping of str to ndarray
        The ``labels/moving_cars`` fields, each ``[N]``: at least ``x``, ``y`` (ego frame at the
        frame time, metres), ``yaw`` (relative to the ego's heading, radians) and ``track_id``.
    ego_yaw_rad : ndarray or None
        ``[N]`` float64, the ego's heading in the scene's local ENU frame at each row's timestamp
        (radians). None leaves every car's kind ``None``.
    keep : ndarray or None
        ``[N]`` bool: the rows that count (e.g. a labelled part's segments); None keeps every row.
        Kinds are read from all rows, so a car keeps its kind whichever of its frames count.
    """

    scene_id: str
    labels: Mapping[str, np.ndarray]
    ego_yaw_rad: np.ndarray | None = None
    keep: np.ndarray | None = None


@dataclass(frozen=True)
class CarCounts:
    """Distinct labelled cars per band.

    Attributes
    ----------
    cars : dict of str to int
        Band name (every name of :data:`BAND_NAMES`) -> distinct cars labelled there.
    label_rows : dict of str to int
        Band name -> labelled car-frames (rows) there.
    by_kind : dict of str to dict of str to int
        Band name -> kind (:data:`MOTION_KINDS`, plus ``"unknown"`` for cars without ego headings)
        -> distinct cars; kinds with no car are left out.
    """

    cars: dict[str, int]
    label_rows: dict[str, int]
    by_kind: dict[str, dict[str, int]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """``{"cars": ..., "label_rows": ..., "by_kind": ...}`` (plain JSON)."""
        return {"cars": dict(self.cars), "label_rows": dict(self.label_rows),
                "by_kind": {band: dict(kinds) for band, kinds in self.by_kind.items()}}

    def shortfall(self, minimum: int, bands: Iterable[str]) -> dict[str, int]:
        """Bands among ``bands`` with fewer than ``minimum`` distinct cars -> their count."""
        return {band: self.cars[band] for band in bands if self.cars[band] < minimum}


def _wrap(angle_rad: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(angle_rad, dtype=np.float64)))


def track_motion_kinds(labels: Mapping[str, np.ndarray], ego_yaw_rad: np.ndarray) -> dict[int, str]:
    """The kind of motion of every track of one scene's labels (module docstring).

    Parameters
    ----------
    labels
        ``timestamp_ns``, ``yaw`` (relative to the ego, radians) and ``track_id``, each ``[N]``.
    ego_yaw_rad
        ``[N]`` float64, the ego's heading over ground at each row's time, radians.

    Returns
    -------
    dict of int to str
        Track id -> one of :data:`MOTION_KINDS`.
    """
    track_ids = np.asarray(labels["track_id"])
    relative = _wrap(labels["yaw"])
    ground = _wrap(relative + np.asarray(ego_yaw_rad, dtype=np.float64))
    order = np.argsort(np.asarray(labels["timestamp_ns"]), kind="stable")
    kinds = {}
    for track_id in np.unique(track_ids):
        rows = order[track_ids[order] == track_id]
        heading = np.unwrap(ground[rows])
        if heading.max() - heading.min() > TURN_MIN_RAD:
            kinds[int(track_id)] = "turning"
            continue
        # The median of the relative heading, taken on the circle around its first value.
        offset = float(np.median(_wrap(relative[rows] - relative[rows[0]])) + relative[rows[0]])
        offset = abs(float(_wrap(offset)))
        kinds[int(track_id)] = ("ahead" if offset < SAME_DIRECTION_RAD
                                else "oncoming" if offset > np.pi - SAME_DIRECTION_RAD else "crossing")
    return kinds


def count_distinct_cars(scenes: Iterable[SceneLabels]) -> CarCounts:
    """Distinct labelled cars (and label rows) per band over ``scenes``, with their kinds.

    Raises
    ------
    ZendarError
        When a scene's ``keep`` or ``ego_yaw_rad`` does not have one entry per label row.
    """
    cars: dict[str, set[tuple[str, int]]] = {band: set() for band in BAND_NAMES}
    rows_per_band = dict.fromkeys(BAND_NAMES, 0)
    kind_of: dict[tuple[str, int], str] = {}
    for scene in scenes:
        track_ids = np.asarray(scene.labels["track_id"]).astype(np.int64)
        n = track_ids.shape[0]
        for name, value in (("keep", scene.keep), ("ego_yaw_rad", scene.ego_yaw_rad)):
            if value is not None and np.shape(value) != (n,):
                raise ZendarError(f"{scene.scene_id}: {name}: expected one entry per label row ({n}), "
                                  f"found shape {np.shape(value)}")
        keep = np.ones(n, bool) if scene.keep is None else np.asarray(scene.keep, bool)
        if scene.ego_yaw_rad is not None and n:
            for track_id, kind in track_motion_kinds(scene.labels, scene.ego_yaw_rad).items():
                kind_of[(scene.scene_id, track_id)] = kind
        range_m = np.hypot(np.asarray(scene.labels["x"], np.float64), np.asarray(scene.labels["y"], np.float64))
        for band, (low, high) in BANDS_M.items():
            inside = keep & (range_m >= low) & (range_m < high)
            rows_per_band[band] += int(np.count_nonzero(inside))
            cars[band].update((scene.scene_id, int(t)) for t in np.unique(track_ids[inside]))
    by_kind = {}
    for band, members in cars.items():
        tally: dict[str, int] = {}
        for car in members:
            kind = kind_of.get(car, "unknown")
            tally[kind] = tally.get(kind, 0) + 1
        by_kind[band] = {kind: tally[kind] for kind in (*MOTION_KINDS, "unknown") if kind in tally}
    return CarCounts({band: len(members) for band, members in cars.items()}, rows_per_band, by_kind)


def scene_labels(reader: SceneReader,
                 keep_timestamps_ns: Callable[[np.ndarray], np.ndarray] | None = None) -> SceneLabels | None:
    """The :class:`SceneLabels` of an open scene (with the ego's headings), or None without labels.

    Parameters
    ----------
    reader : SceneReader
    keep_timestamps_ns : callable, optional
        ``timestamps_ns [N] int64 -> [N] bool``: which label rows count (by their frame time).
    """
    labels = reader.labels()
    if labels is None:
        return None
    poses = reader.ego_poses()
    stamps = labels["timestamp_ns"]
    yaw_at = {}
    for stamp in np.unique(stamps).tolist():
        rotation = poses.enu_T_ego(int(stamp)).rotation
        yaw_at[stamp] = float(np.arctan2(rotation[1, 0], rotation[0, 0]))
    ego_yaw = np.array([yaw_at[s] for s in stamps.tolist()], np.float64)
    keep = None if keep_timestamps_ns is None else np.asarray(keep_timestamps_ns(stamps), bool)
    return SceneLabels(reader.scene_id, labels, ego_yaw, keep)


def scenes_car_counts(index: DatasetIndex, scene_ids: Iterable[str],
                      keep_times: Callable[[str], Callable[[np.ndarray], np.ndarray]] | None = None) -> CarCounts:
    """Distinct labelled cars per band over some scenes of an opened dataset (scenes without labels add nothing).

    Parameters
    ----------
    keep_times
        ``scene_id -> (timestamps_ns [N] int64 -> [N] bool)``: the label rows that count, by their
        frame time (e.g. a labelled part's segments); every row when None.
    """
    tables = []
    for scene_id in scene_ids:
        with index.open_scene(scene_id) as reader:
            table = scene_labels(reader, None if keep_times is None else keep_times(scene_id))
        if table is not None:
            tables.append(table)
    return count_distinct_cars(tables)


def dataset_car_counts(root: str | os.PathLike | DatasetIndex, splits: Iterable[str] | None = None) -> dict[str, CarCounts]:
    """Distinct labelled cars per band of each split of a dataset.

    Parameters
    ----------
    root : str, path-like or DatasetIndex
        Dataset root (local path or fsspec URL), or the dataset already opened.
    splits : iterable of str, optional
        Default: every split the dataset lists. Scenes without labels (withheld) add nothing.

    Returns
    -------
    dict of str to CarCounts
        Split name -> its counts.
    """
    index = root if isinstance(root, DatasetIndex) else open_dataset(os.fspath(root) if isinstance(root, os.PathLike) else root)
    names = list(index.splits) if splits is None else list(splits)
    return {split: scenes_car_counts(index, index.scene_ids(split)) for split in names}


__all__ = [
    "MOTION_KINDS",
    "CarCounts",
    "SceneLabels",
    "count_distinct_cars",
    "dataset_car_counts",
    "scene_labels",
    "scenes_car_counts",
    "track_motion_kinds",
]
