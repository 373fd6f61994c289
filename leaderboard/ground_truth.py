"""The hidden test split: its labels, their checksum, and its public and private parts.

The split is divided so that live scores (public part) say nothing about the frames that decide
the final ranking (private part):

- with two scenes or more, whole scenes: scenes ordered by the SHA-256 of their id, the first half
  (rounded up) public. Consecutive frames of a scene see the same cars, so a frame-level division
  would let public scores speak about private frames;
- with a single scene, its frames in time order, the first half (rounded up) public.

The rule is public and deterministic: knowing which frames are public does not reveal a label.
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import orjson

from zendar_dataset.errors import PredictionsError, ZendarError
from zendar_dataset.eval.evaluate import load_ground_truth, scene_of
from zendar_dataset.eval.validation import load_document

PARTS = ("public", "private")


@dataclass(frozen=True)
class TestSplit:
    """The hidden labels a leaderboard scores against.

    Attributes
    ----------
    frames
        ``{frame_id: [{"x", "y", ...}, ...]}``, ego frame, metres (the evaluator's ground truth).
    split
        The split's name when known (``"test"``), else None.
    sha256
        Hex SHA-256 of the frames as canonical JSON (sorted keys): identical labels give the same
        checksum whether they came from a dataset root or an ``export-gt`` file.
    public_frame_ids, private_frame_ids
        The two parts, in the frames' order; together they are every frame.
    """

    frames: dict[str, list[dict]]
    split: str | None
    sha256: str
    public_frame_ids: tuple[str, ...]
    private_frame_ids: tuple[str, ...]

    def part_frame_ids(self, part: str) -> tuple[str, ...]:
        """Frame ids of ``part`` (``"public"`` or ``"private"``)."""
        if part not in PARTS:
            raise ValueError(f"part must be one of {PARTS}, got {part!r}")
        return self.public_frame_ids if part == "public" else self.private_frame_ids

    def part_ground_truth(self, part: str) -> dict[str, Any]:
        """The evaluator's ground-truth document ``{"frames": {...}}`` of one part."""
        return {"frames": {frame_id: self.frames[frame_id] for frame_id in self.part_frame_ids(part)}}


def _timestamp_key(frame_id: str) -> tuple[int, str]:
    timestamp = frame_id.rpartition("/")[2]
    return (int(timestamp), frame_id) if timestamp.isdigit() else (0, frame_id)


def divide_frames(frame_ids: list[str]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Split frame ids ``"<scene_id>/<timestamp_ns>"`` into (public, private) parts.

    Parameters
    ----------
    frame_ids
        Every frame of the test split.

    Returns
    -------
    (public, private)
        Tuples of frame ids, each in the order of ``frame_ids``.

    Examples
    --------
    >>> divide_frames(["s/30", "s/10", "s/20"])
    (('s/10', 's/20'), ('s/30',))
    """
    scenes = sorted({scene_of(f) for f in frame_ids}, key=lambda s: hashlib.sha256(s.encode()).hexdigest())
    if len(scenes) >= 2:
        public_scenes = set(scenes[: math.ceil(len(scenes) / 2)])
        public = {f for f in frame_ids if scene_of(f) in public_scenes}
    else:
        in_time = sorted(frame_ids, key=_timestamp_key)
        public = set(in_time[: math.ceil(len(in_time) / 2)])
    return (
        tuple(f for f in frame_ids if f in public),
        tuple(f for f in frame_ids if f not in public),
    )


def frames_sha256(frames: dict[str, list[dict]]) -> str:
    """Hex SHA-256 of ``frames`` as canonical JSON (sorted keys, no whitespace)."""
    return hashlib.sha256(orjson.dumps(frames, option=orjson.OPT_SORT_KEYS)).hexdigest()


def load_test_split(source: str | os.PathLike, split: str | None = None) -> TestSplit:
    """Read and check the hidden labels from an ``export-gt`` file or a dataset root.

    Parameters
    ----------
    source
        A ground-truth JSON file ``{"frames": {...}}`` or a dataset root directory.
    split
        The split of a dataset root (default as in the evaluator: ``test`` when labelled, else ``val``).

    Raises
    ------
    PredictionsError
        Listing every problem in the labels (``problems``).
    ZendarError
        When the labels hold no frame.
    """
    checked = load_ground_truth(source, split=split)
    if checked.problems:  # each already names the file or dataset
        raise PredictionsError("; ".join(checked.problems[:5]), checked.problems)
    if Path(source).is_dir():
        from zendar_dataset.format.ground_truth import ground_truth_frames

        frames = ground_truth_frames(source, checked.split)
    else:
        document, _ = load_document(source, what="ground truth")
        frames = document["frames"]
    if not frames:
        raise ZendarError(f"ground truth {str(source)!r} holds no frames: nothing to score against")
    public, private = divide_frames(list(frames))
    return TestSplit(frames, checked.split, frames_sha256(frames), public, private)
