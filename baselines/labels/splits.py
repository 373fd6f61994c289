"""The semi-supervised split: time segments of the training scenes with manual labels, and the rest.

The paper pretrains on many automatic labels and fine-tunes on few manual ones (§4.1: 10,000 manual
against 400,000 automatic labels). To reproduce that on a dataset whose every training frame is
labelled, the training scenes' timelines are cut into *segments* of :data:`DEFAULT_SEGMENT_FRAMES`
label frames, and a seeded draw across all training scenes puts a fraction of the segments in a
*labelled* part, whose manual labels a model may see; everything else is seen only through automatic
labels. Drawing segments rather than whole scenes spreads the few manual labels over many more
distinct cars (a car counts once, however many of its frames are labelled). Validation and test scenes
are never in either part.

A segment is a half-open span ``[start_ns, end_ns)`` of GPS time around consecutive label frames,
cut between frames so that every instant belongs to the segment of its nearest label frame (the
earlier one on a tie, as :func:`~zendar_dataset.detection.boxes.nearest_label_frame`): a radar cube
inside a labelled segment takes its manual-label boxes from a labelled frame.

The split is written as a small versioned JSON file with a SHA-256 of its canonical content, so a
hand edit (moving a segment into the labelled part) is caught when the file is read back, and it
names the dataset (the SHA-256 of its ``dataset.json``) it was drawn from. Version 1 files (whole
scenes) are still read: each labelled scene is one segment spanning all time.
"""

from __future__ import annotations

import itertools
import json
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.atomic_files import prepare_out_dir, write_json_atomic
from zendar_dataset.detection.scene import frame_timestamps
from zendar_dataset.eval.car_counts import scenes_car_counts
from zendar_dataset.eval.protocol import BAND_NAMES, RANGE_BANDS
from zendar_dataset.format.reader import DatasetIndex, SceneReader
from zendar_dataset.output_location import refuse_output_inside

from zendar_baselines.fingerprints import SHA256_HEX, canonical_json_sha256, dataset_fingerprint, dataset_index, dataset_location

FORMAT_NAME = "zendar-semisupervised-split"
FORMAT_VERSION = 2
#: Versions :func:`read_split` reads: 1 (whole scenes) and the current one.
READABLE_VERSIONS = (1, FORMAT_VERSION)
TRAIN_SPLIT = "train"
_OTHER_SPLITS = ("val", "test")
#: Label frames per segment: half a second at the simulator's 10 Hz, much shorter than a car stays in
#: view, so the labelled part samples many cars rather than many frames of few.
DEFAULT_SEGMENT_FRAMES = 5
#: The one segment of a labelled scene of a version-1 file: all of GPS time.
WHOLE_SCENE: tuple[int, int] = (0, 2**63 - 1)

Segment = tuple[int, int]


class SplitError(ZendarError):
    """A split cannot be made or read; ``problems`` lists every problem found."""


class ManualLabelLeakError(ZendarError):
    """Manual labels outside the labelled part were about to be used."""


def scene_segments(frame_timestamps_ns: np.ndarray, frames_per_segment: int) -> list[Segment]:
    """Cut one scene's timeline into segments of ``frames_per_segment`` consecutive label frames.

    Parameters
    ----------
    frame_timestamps_ns : numpy.ndarray
        ``[F]`` int64 sorted, distinct label-frame (SAR) timestamps, GPS nanoseconds.
    frames_per_segment : int
        Frames per segment (the last segment holds the remainder).

    Returns
    -------
    list of (int, int)
        ``[start_ns, end_ns)`` per segment, contiguous: each boundary lies one nanosecond after the
        midpoint of the two frames it separates, so an instant belongs to the segment of its nearest
        frame (the earlier one on a tie). The first segment starts and the last ends half a frame
        spacing beyond the outer frames (one nanosecond around a single frame).
    """
    stamps = np.asarray(frame_timestamps_ns, np.int64)
    if stamps.size == 0:
        return []
    if stamps.size == 1:
        return [(int(stamps[0]), int(stamps[0]) + 1)]
    inner = (stamps[:-1] + (stamps[1:] - stamps[:-1]) // 2 + 1).tolist()  # boundary after frame i
    first = int(stamps[0] - (stamps[1] - stamps[0]) // 2)
    last = int(stamps[-1] + (stamps[-1] - stamps[-2]) // 2 + 1)
    bounds = [first, *inner, last]
    return [(bounds[i], bounds[min(i + frames_per_segment, stamps.size)]) for i in range(0, stamps.size, frames_per_segment)]


def _in_segments(segments: Iterable[Segment], timestamps_ns: np.ndarray) -> np.ndarray:
    stamps = np.asarray(timestamps_ns, np.int64)
    inside = np.zeros(stamps.shape, bool)
    for start_ns, end_ns in segments:
        inside |= (stamps >= start_ns) & (stamps < end_ns)
    return inside


class _LabelledView:
    """A scene whose :meth:`labels` hold only the rows of its labelled segments; all else as the scene's."""

    def __init__(self, reader: SceneReader, split: SemiSupervisedSplit) -> None:
        self._reader = reader
        self._split = split

    def labels(self) -> dict[str, np.ndarray] | None:
        return self._split.manual_labels(self._reader)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._reader, name)


@dataclass(frozen=True)
class SemiSupervisedSplit:
    """The training scenes' time segments divided into a labelled and an unlabelled part.

    Attributes
    ----------
    labelled : tuple of str
        Scene ids with at least one labelled segment, in the dataset's training order.
    unlabelled : tuple of str
        Training scene ids without any labelled segment (seen only through automatic labels), in
        the dataset's training order. Together with ``labelled``: every training scene.
    labelled_fraction : float
        The share of training segments asked for in the labelled part (the part holds
        ``round(fraction * n_segments)`` segments, at least 1 and at most ``n_segments - 1``).
    seed : int
        Seed of the ``numpy.random.Generator`` permutation that drew the labelled segments.
    dataset_fingerprint : str
        SHA-256 (hex) of the ``dataset.json`` bytes of the dataset split.
    labelled_segments : dict of str to tuple of (int, int)
        Scene id (each of ``labelled``) -> its labelled ``[start_ns, end_ns)`` spans, GPS
        nanoseconds, in time order.
    frames_per_segment : int
        Label frames per segment (:func:`scene_segments`); 0 for a version-1 split of whole scenes.
    n_segments : int
        Segments of all training scenes the labelled ones were drawn from.
    labelled_cars : dict of str to int
        Band (:data:`~zendar_dataset.eval.protocol.BAND_NAMES`) -> distinct cars labelled there in
        the labelled segments; empty for a version-1 split.
    """

    labelled: tuple[str, ...]
    unlabelled: tuple[str, ...]
    labelled_fraction: float
    seed: int
    dataset_fingerprint: str
    labelled_segments: dict[str, tuple[Segment, ...]] = field(default_factory=dict)
    frames_per_segment: int = 0
    n_segments: int = 0
    labelled_cars: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The file's content without its ``sha256`` (what the checksum covers); a split of whole scenes
        read from a version-1 file is written as version 1 again."""
        if self.frames_per_segment == 0:
            return {"format": FORMAT_NAME, "format_version": 1, "labelled": list(self.labelled),
                    "unlabelled": list(self.unlabelled), "labelled_fraction": self.labelled_fraction, "seed": self.seed,
                    "dataset_fingerprint": self.dataset_fingerprint}
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "labelled": list(self.labelled),
            "unlabelled": list(self.unlabelled),
            "labelled_segments": {scene_id: [list(span) for span in spans] for scene_id, spans in self.labelled_segments.items()},
            "frames_per_segment": self.frames_per_segment,
            "n_segments": self.n_segments,
            "labelled_cars": dict(self.labelled_cars),
            "labelled_fraction": self.labelled_fraction,
            "seed": self.seed,
            "dataset_fingerprint": self.dataset_fingerprint,
        }

    def is_labelled(self, scene_id: str, timestamps_ns: np.ndarray) -> np.ndarray:
        """``[N]`` bool: which of ``timestamps_ns`` ``[N]`` (GPS ns) fall in a labelled segment of ``scene_id``."""
        return _in_segments(self.labelled_segments.get(scene_id, ()), timestamps_ns)

    def check_manual_label_use(self, scene_ids: Iterable[str]) -> None:
        """Guard the promise that no model sees the manual labels of a scene without a labelled segment.

        Call it with the scenes whose manual labels are about to be read (for training targets,
        fine-tuning, or label-quality figures that feed a choice); within those scenes, read them
        through :meth:`manual_labels` or check their times with :meth:`check_manual_label_times`.

        Raises
        ------
        ManualLabelLeakError
            Naming every training scene among ``scene_ids`` that has no labelled segment.
        """
        unlabelled = set(self.unlabelled)
        leaked = [scene_id for scene_id in dict.fromkeys(scene_ids) if scene_id in unlabelled]
        if leaked:
            raise ManualLabelLeakError(
                f"manual labels of {len(leaked)} scene(s) of the unlabelled part were about to be used: {leaked}; "
                "the semi-supervised split allows manual labels of the labelled part only"
            )

    def check_manual_label_times(self, scene_id: str, timestamps_ns: np.ndarray) -> None:
        """Guard that manual labels (or targets made from them) at ``timestamps_ns`` lie in labelled segments.

        Raises
        ------
        ManualLabelLeakError
            Naming the scene, how many of the times fall outside its labelled segments, and the first.
        """
        stamps = np.asarray(timestamps_ns, np.int64)
        outside = stamps[~self.is_labelled(scene_id, stamps)]
        if outside.size:
            raise ManualLabelLeakError(
                f"manual labels of {scene_id} at {outside.size} time(s) outside its labelled segments were about to be "
                f"used (first at {int(outside[0])} ns); the semi-supervised split allows manual labels of the labelled "
                "segments only"
            )

    def manual_labels(self, reader: SceneReader) -> dict[str, np.ndarray] | None:
        """The scene's manual labels restricted to its labelled segments (every field, rows in file order).

        Raises
        ------
        ManualLabelLeakError
            When the scene has no labelled segment.
        """
        self.check_manual_label_use([reader.scene_id])
        labels = reader.labels()
        if labels is None:
            return None
        keep = self.is_labelled(reader.scene_id, labels["timestamp_ns"])
        return {name: values[keep] for name, values in labels.items()}

    def labelled_view(self, reader: SceneReader) -> SceneReader:
        """``reader`` seen through the split: its ``labels()`` are :meth:`manual_labels`, all else unchanged.

        Raises
        ------
        ManualLabelLeakError
            When the scene has no labelled segment.
        """
        self.check_manual_label_use([reader.scene_id])
        return _LabelledView(reader, self)  # type: ignore[return-value]


def _labelled_count(labelled_fraction: float, n_segments: int) -> int:
    # Half up rather than Python's round-half-even, so 0.5 of 5 segments gives 3 on every platform.
    return min(max(math.floor(labelled_fraction * n_segments + 0.5), 1), n_segments - 1)


def _format_counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{band} {counts[band]}" for band in RANGE_BANDS)


def make_split(dataset_root: DatasetIndex | str | os.PathLike, labelled_fraction: float, seed: int, *,
               frames_per_segment: int = DEFAULT_SEGMENT_FRAMES, min_cars_per_band: int = 0) -> SemiSupervisedSplit:
    """Draw the labelled segments of a dataset's training scenes.

    Parameters
    ----------
    dataset_root
        Dataset root (local path or fsspec URL), or the dataset already opened.
    labelled_fraction
        Share of the training scenes' segments to put in the labelled part, in (0, 1).
    seed
        Non-negative integer; the same seed and dataset give the same split.
    frames_per_segment
        Label frames per segment (:func:`scene_segments`), at least 1.
    min_cars_per_band
        The labelled part must hold at least this many distinct labelled cars in each range band
        (near, mid, far); 0 checks nothing.

    Raises
    ------
    SplitError
        When the fraction, seed, segment length or minimum is invalid, the training scenes have
        fewer than 2 segments (each part needs one), a training scene is also listed in ``val`` or
        ``test``, or the labelled part holds fewer than ``min_cars_per_band`` cars in a band (the
        message gives the counts of the labelled part and of the whole training split).
    """
    problems = []
    if isinstance(labelled_fraction, bool) or not isinstance(labelled_fraction, int | float) or not 0.0 < labelled_fraction < 1.0:
        problems.append(f"labelled_fraction: expected a number in (0, 1), found {labelled_fraction!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        problems.append(f"seed: expected an integer >= 0, found {seed!r}")
    for name, value, low in (("frames_per_segment", frames_per_segment, 1), ("min_cars_per_band", min_cars_per_band, 0)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            problems.append(f"{name}: expected an integer >= {low}, found {value!r}")
    dataset = dataset_index(dataset_root)
    where = dataset_location(dataset_root)
    train = dataset.scene_ids(TRAIN_SPLIT)
    for split in _OTHER_SPLITS:
        shared = [scene_id for scene_id in train if scene_id in dataset.splits.get(split, [])]
        if shared:
            problems.append(f"{where}: scenes {shared} are in both the {TRAIN_SPLIT} and the {split} split")
    if problems:
        raise SplitError("; ".join(problems), problems)
    segments = []  # (scene id, segment) in training order
    for scene_id in train:
        with dataset.open_scene(scene_id) as reader:
            segments += [(scene_id, span) for span in scene_segments(frame_timestamps(reader), int(frames_per_segment))]
    if len(segments) < 2:
        raise SplitError(
            f"{where}: the {TRAIN_SPLIT} split has {len(segments)} segment(s) of {frames_per_segment} label frames; "
            "a semi-supervised split needs at least 2 (1 labelled and 1 unlabelled)"
        )
    order = np.random.default_rng(int(seed)).permutation(len(segments))
    chosen = sorted(order[: _labelled_count(float(labelled_fraction), len(segments))].tolist())
    labelled_segments: dict[str, tuple[Segment, ...]] = {}
    for i in chosen:
        scene_id, span = segments[i]
        labelled_segments[scene_id] = (*labelled_segments.get(scene_id, ()), span)
    split = SemiSupervisedSplit(
        labelled=tuple(scene_id for scene_id in train if scene_id in labelled_segments),
        unlabelled=tuple(scene_id for scene_id in train if scene_id not in labelled_segments),
        labelled_fraction=float(labelled_fraction),
        seed=int(seed),
        dataset_fingerprint=dataset_fingerprint(dataset),
        labelled_segments=labelled_segments,
        frames_per_segment=int(frames_per_segment),
        n_segments=len(segments),
    )
    counts = scenes_car_counts(dataset, split.labelled, lambda scene_id: lambda stamps: split.is_labelled(scene_id, stamps))
    short = counts.shortfall(int(min_cars_per_band), RANGE_BANDS)
    if short:
        everything = scenes_car_counts(dataset, train)
        problem = (
            f"{where}: too few labelled cars for labelled_fraction {labelled_fraction:g}: its "
            f"{len(chosen)} of {len(segments)} training segments (seed {seed}) hold {_format_counts(counts.cars)} distinct "
            f"labelled cars per band, at least {min_cars_per_band} per band are needed (the whole {TRAIN_SPLIT} split "
            f"holds {_format_counts(everything.cars)}); raise the labelled fraction, or simulate more training scenes"
        )
        raise SplitError(problem, [problem])
    return replace(split, labelled_cars=dict(counts.cars))


def write_split(split: SemiSupervisedSplit, path: str | os.PathLike, *, dataset_root: DatasetIndex | str | os.PathLike | None = None) -> Path:
    """Write ``split`` as versioned JSON with a ``sha256`` of its canonical content (atomic).

    Parameters
    ----------
    split
        From :func:`make_split`.
    path
        The JSON file to write.
    dataset_root
        When given, ``path`` may not lie inside it.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    if dataset_root is not None:
        refuse_output_inside(path, datasets=(dataset_location(dataset_root),), what="split file")
    content = split.to_json()
    document = {**content, "sha256": canonical_json_sha256(content)}
    prepare_out_dir(path.parent)
    write_json_atomic(path, document)
    return path


def _scene_list_problems(document: dict, key: str, where: str, *, may_be_empty: bool = False) -> list[str]:
    value = document.get(key)
    if not isinstance(value, list) or not (value or may_be_empty) or not all(isinstance(s, str) for s in value):
        return [f"{where}: {key}: expected a {'' if may_be_empty else 'non-empty '}list of scene ids, found {value!r}"]
    repeated = sorted({s for s in value if value.count(s) > 1})
    return [f"{where}: {key}: expected each scene once, found {repeated} repeated"] if repeated else []


def _is_count(value: Any, low: int = 0) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= low


def _segment_problems(document: dict, where: str) -> list[str]:
    """Problems of a version-2 file's segment keys (labelled segments, their counts)."""
    problems = []
    segments = document.get("labelled_segments")
    if not isinstance(segments, dict):
        return [f"{where}: labelled_segments: expected an object of scene id -> [[start_ns, end_ns], ...], found {segments!r}"]
    if isinstance(document.get("labelled"), list) and set(segments) != set(document["labelled"]):
        problems.append(f"{where}: labelled_segments: expected the scenes of labelled {sorted(document['labelled'])}, "
                        f"found {sorted(segments)}")
    for scene_id, spans in segments.items():
        ok = isinstance(spans, list) and spans and all(
            isinstance(span, list) and len(span) == 2 and all(_is_count(t) for t in span) and span[0] < span[1] for span in spans)
        if not ok or any(a[1] > b[0] for a, b in itertools.pairwise(spans)):
            problems.append(f"{where}: labelled_segments: {scene_id}: expected a non-empty list of [start_ns, end_ns] "
                            f"integers, start < end, in time order and disjoint, found {spans!r}")
    for key, low in (("frames_per_segment", 1), ("n_segments", 2)):
        if not _is_count(document.get(key), low):
            problems.append(f"{where}: {key}: expected an integer >= {low}, found {document.get(key)!r}")
    cars = document.get("labelled_cars")
    if not (isinstance(cars, dict) and set(cars) == set(BAND_NAMES) and all(_is_count(v) for v in cars.values())):
        problems.append(f"{where}: labelled_cars: expected a count >= 0 for each band of {list(BAND_NAMES)}, found {cars!r}")
    return problems


_V1_KEYS = {"format", "format_version", "labelled", "unlabelled", "labelled_fraction", "seed", "dataset_fingerprint", "sha256"}
_V2_KEYS = _V1_KEYS | {"labelled_segments", "frames_per_segment", "n_segments", "labelled_cars"}


def _document_problems(document: Any, where: str) -> list[str]:
    if not isinstance(document, dict):
        return [f"{where}: expected a JSON object, found {type(document).__name__}"]
    if document.get("format") != FORMAT_NAME:
        return [f"{where}: format: expected {FORMAT_NAME!r}, found {document.get('format')!r}"]
    version = document.get("format_version")
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        return [(f"{where}: format_version: expected one of {list(READABLE_VERSIONS)}, found {version!r}; draw the "
                 "split again with make_split (zendar-bench draws a new one in a fresh --out directory)")]
    problems = _scene_list_problems(document, "labelled", where)
    problems += _scene_list_problems(document, "unlabelled", where, may_be_empty=version >= 2)
    if not problems:
        both = sorted(set(document["labelled"]) & set(document["unlabelled"]))
        if both:
            problems.append(f"{where}: expected disjoint parts, found {both} both labelled and unlabelled")
    if version >= 2:
        problems += _segment_problems(document, where)
    fraction = document.get("labelled_fraction")
    if isinstance(fraction, bool) or not isinstance(fraction, int | float) or not 0.0 < fraction < 1.0:
        problems.append(f"{where}: labelled_fraction: expected a number in (0, 1), found {fraction!r}")
    seed = document.get("seed")
    if not _is_count(seed):
        problems.append(f"{where}: seed: expected an integer >= 0, found {seed!r}")
    fingerprint = document.get("dataset_fingerprint")
    if not (isinstance(fingerprint, str) and SHA256_HEX.fullmatch(fingerprint)):
        problems.append(f"{where}: dataset_fingerprint: expected 64 lowercase hex digits, found {fingerprint!r}")
    expected_keys = _V1_KEYS if version == 1 else _V2_KEYS
    unknown = sorted(set(document) - expected_keys)
    if unknown:
        problems.append(f"{where}: expected only the keys {sorted(expected_keys)}, found also {unknown}")
    content = {key: value for key, value in document.items() if key != "sha256"}
    recorded = document.get("sha256")
    try:
        digest = canonical_json_sha256(content)
    except ValueError as exc:
        return problems + [f"{where}: cannot be checksummed ({exc})"]
    if recorded != digest:
        problems.append(
            f"{where}: sha256: the content hashes to {digest}, the file records {recorded!r} "
            "(the file was edited after it was written)"
        )
    return problems


def read_split(path: str | os.PathLike, dataset_root: DatasetIndex | str | os.PathLike | None = None) -> SemiSupervisedSplit:
    """Read a split file written by :func:`write_split` (version 2, or version 1 of whole scenes), checking it.

    Parameters
    ----------
    path
        The split JSON file.
    dataset_root
        When given, the split must have been drawn from this dataset (same ``dataset.json``) and
        every scene of it must be a training scene there.

    Returns
    -------
    SemiSupervisedSplit
        A version-1 file gives each labelled scene one segment, :data:`WHOLE_SCENE`
        (``frames_per_segment`` and ``n_segments`` 0, ``labelled_cars`` empty).

    Raises
    ------
    SplitError
        Naming the file and listing every problem: unreadable, another format or version, a
        checksum that does not match the content, parts not disjoint, segments that are not spans
        of the labelled scenes, another dataset, scenes that are not training scenes.
    """
    where = os.fspath(path)
    try:
        document = json.loads(Path(path).read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise SplitError(f"{where}: expected a semi-supervised split file, found none") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise SplitError(f"{where}: expected the JSON of a semi-supervised split, found unreadable content ({exc})") from None
    problems = _document_problems(document, where)
    if dataset_root is not None and not problems:
        dataset = dataset_index(dataset_root)
        fingerprint = dataset_fingerprint(dataset)
        if document["dataset_fingerprint"] != fingerprint:
            problems.append(
                f"{where}: dataset_fingerprint: drawn from another dataset ({document['dataset_fingerprint'][:12]}...), "
                f"not {dataset_location(dataset_root)} ({fingerprint[:12]}...)"
            )
        train = set(dataset.scene_ids(TRAIN_SPLIT))
        outside = [s for s in document["labelled"] + document["unlabelled"] if s not in train]
        if outside:
            problems.append(f"{where}: scenes {outside} are not in the {TRAIN_SPLIT} split of {dataset_location(dataset_root)}")
    if problems:
        raise SplitError("; ".join(problems), problems)
    common = {"labelled": tuple(document["labelled"]), "unlabelled": tuple(document["unlabelled"]),
              "labelled_fraction": float(document["labelled_fraction"]), "seed": document["seed"],
              "dataset_fingerprint": document["dataset_fingerprint"]}
    if document["format_version"] == 1:
        return SemiSupervisedSplit(**common, labelled_segments={scene_id: (WHOLE_SCENE,) for scene_id in document["labelled"]})
    return SemiSupervisedSplit(
        **common,
        labelled_segments={scene_id: tuple(tuple(span) for span in document["labelled_segments"][scene_id])
                           for scene_id in document["labelled"]},
        frames_per_segment=document["frames_per_segment"],
        n_segments=document["n_segments"],
        labelled_cars=dict(document["labelled_cars"]),
    )


__all__ = [
    "DEFAULT_SEGMENT_FRAMES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "READABLE_VERSIONS",
    "WHOLE_SCENE",
    "ManualLabelLeakError",
    "SemiSupervisedSplit",
    "SplitError",
    "make_split",
    "read_split",
    "scene_segments",
    "write_split",
]
