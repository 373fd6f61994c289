"""Which radar serial is the left one: the image attitude's answer, checked against the path driven.

SAR and detection files name radars by serial, range-Doppler files (``left_rd.pbs``) and format v1's
radar poses by side.  The release does not say which serial is which side.  Two readings answer it:

- **the attitude**: each image centre moved into the vehicle frame with the image's own
  ``Image.attitude``, taken as IMU (forward, right, down) -> ECEF (paper §3.3).  An attitude of
  another convention (x forward, y left, z up) gives the same numbers with left and right swapped;
- **the path driven** (independent of any attitude): the direction of travel from the tracklog's
  positions (else the images' own vehicle positions) and the local vertical give "left of the
  path"; a left radar's image centres and detections lie there.

:func:`decide_sides` takes a side only when the readings that say anything agree, and refuses
(:class:`~zendar_dataset.errors.ZendarFormatError`, every radar's evidence listed) when they do
not, unless the user stated the sides (``--sides SERIAL=left,SERIAL=right``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np

from zendar_dataset.errors import ZendarError, ZendarFormatError
from zendar_dataset.geometry import local_up_ecef, quat_wxyz_to_matrix
from zendar_dataset.release import records as rec
from zendar_dataset.release.decoded import OpenedStream, decoded_records
from zendar_dataset.release.wire import WireError

SIDES = ("left", "right")
#: Frames read per radar and reading (the first ones that say something) ...
EVIDENCE_FRAMES = 50
#: ... among at most this many (a long stop at the start says nothing and costs decoding).
MAX_FRAMES_EXAMINED = 2000
#: The direction of travel at time t: the path's displacement over [t - window, t + window].
TRAVEL_WINDOW_S = 0.5
#: Slower than this the direction of travel says nothing (a stop; GPS noise).
MIN_SPEED_MPS = 1.0
#: A reading decides when at least this share of its frames put the radar on one side.
DECISIVE_SHARE = 0.75


@dataclass
class SideVotes:
    """Frames of one radar that put it on the left or on the right, by one reading."""

    left: int = 0
    right: int = 0
    lateral_m: list[float] = field(default_factory=list)  # to the left, per frame

    def add(self, lateral_left_m: float) -> None:
        self.lateral_m.append(lateral_left_m)
        if lateral_left_m > 0:
            self.left += 1
        elif lateral_left_m < 0:
            self.right += 1

    @property
    def frames(self) -> int:
        return self.left + self.right

    @property
    def side(self) -> str | None:
        """The side of at least :data:`DECISIVE_SHARE` of the frames; None without frames or a clear majority."""
        if not self.frames:
            return None
        if self.left >= DECISIVE_SHARE * self.frames:
            return "left"
        if self.right >= DECISIVE_SHARE * self.frames:
            return "right"
        return None

    def describe(self) -> str:
        """``"left in 20 of 20 frames (median 10.0 m)"``, or ``"no usable frame"``."""
        if not self.frames:
            return "no usable frame"
        median = float(np.median(self.lateral_m))
        counts = f"left in {self.left}, right in {self.right} of {self.frames} frames"
        if self.side is not None:
            counts = f"{self.side} in {max(self.left, self.right)} of {self.frames} frames"
        return f"{counts} (median {abs(median):.1f} m to the {'left' if median > 0 else 'right'})"


@dataclass
class RadarSideEvidence:
    """Everything that says which side one radar (a serial) is on.

    Attributes
    ----------
    serial : str
    attitude : SideVotes
        Its SAR image centres in the vehicle frame of ``Image.attitude`` taken as forward-right-down.
    images, detections : SideVotes
        Its SAR image centres and its detections (per-frame median) relative to the path driven.
    """

    serial: str
    attitude: SideVotes = field(default_factory=SideVotes)
    images: SideVotes = field(default_factory=SideVotes)
    detections: SideVotes = field(default_factory=SideVotes)

    @property
    def path_side(self) -> str | None:
        """The side the path driven gives (images and detections agreeing), else None."""
        found = {votes.side for votes in (self.images, self.detections)} - {None}
        return found.pop() if len(found) == 1 else None

    def readings(self) -> dict[str, str]:
        """Reading -> the side it decides, for the readings that decide one."""
        named = {"attitude": self.attitude, "path (images)": self.images, "path (detections)": self.detections}
        return {name: votes.side for name, votes in named.items() if votes.side is not None}

    def describe(self) -> str:
        """Every reading, for the summary and for the error listing the evidence."""
        return (
            f"Image.attitude (as forward-right-down -> ECEF) puts its images {self.attitude.describe()}; "
            f"the path driven puts its images {self.images.describe()} and its detections {self.detections.describe()}"
        )


class EgoPath:
    """The vehicle's path: ECEF positions over GPS seconds, for "left of the direction of travel".

    Parameters
    ----------
    times_s : ndarray, [K]
        GPS seconds (any order; non-finite entries are dropped).
    positions_ecef : ndarray, [K, 3]
    """

    def __init__(self, times_s: np.ndarray, positions_ecef: np.ndarray) -> None:
        times_s = np.asarray(times_s, np.float64).reshape(-1)
        positions_ecef = np.asarray(positions_ecef, np.float64).reshape(-1, 3)
        usable = np.isfinite(times_s) & np.all(np.isfinite(positions_ecef), axis=1)
        times_s, order = np.unique(times_s[usable], return_index=True)
        self.t0_s = float(times_s[0]) if times_s.size else 0.0
        self.times_s = times_s - self.t0_s  # small numbers: interpolating near 1.3e9 s would lose microseconds
        self.positions_ecef = positions_ecef[usable][order]

    def _at(self, t_s: np.ndarray) -> np.ndarray:
        """``[T, 3]`` positions at the ``[T]`` times (seconds after ``t0_s``), interpolated linearly."""
        return np.stack([np.interp(t_s, self.times_s, self.positions_ecef[:, axis]) for axis in range(3)], axis=-1)

    def lateral_left_m(self, timestamp_s: float, points_ecef: np.ndarray) -> float | None:
        """Median distance of ``points_ecef`` to the left of the direction of travel at ``timestamp_s``.

        None when the path does not cover the time, the vehicle moves slower than
        :data:`MIN_SPEED_MPS` there, or no point is finite.
        """
        points = np.asarray(points_ecef, np.float64).reshape(-1, 3)
        points = points[np.all(np.isfinite(points), axis=1)]
        t = timestamp_s - self.t0_s
        if self.times_s.size < 2 or not points.size or not self.times_s[0] <= t <= self.times_s[-1]:
            return None
        start, end = max(t - TRAVEL_WINDOW_S, self.times_s[0]), min(t + TRAVEL_WINDOW_S, self.times_s[-1])
        at_start, at_end, here = self._at(np.array([start, end, t]))
        travel = at_end - at_start
        distance = float(np.linalg.norm(travel))
        if end - start <= 0 or distance < MIN_SPEED_MPS * (end - start):
            return None
        left = np.cross(local_up_ecef(here), travel / distance)
        return float(np.median((points - here) @ left))


def tracklog_poses(opened: OpenedStream) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ``Position`` stream's ``[K]`` GPS seconds, ``[K, 3]`` ECEF positions and ``[K, 4]`` wxyz
    attitudes (read here without touching its summary; NaN where absent)."""
    _, offsets, lengths = opened.stream.spans()
    try:
        return rec.poses(opened.stream.buffer, offsets, lengths, {})
    except WireError:
        decoded = [rec.pose(record) for record in decoded_records(opened, probe=True)]
        return (np.array([d.timestamp_s for d in decoded]), np.array([d.position_ecef for d in decoded]).reshape(-1, 3),
                np.array([d.attitude_wxyz for d in decoded]).reshape(-1, 4))


def tracklog_path(seconds: np.ndarray, position_ecef: np.ndarray) -> EgoPath | None:
    """The path of a tracklog's poses (:func:`tracklog_poses`), or None with fewer than two positions."""
    path = EgoPath(seconds, position_ecef)
    return path if path.times_s.size >= 2 else None


def frames_path(frames: Iterable[rec.SarFrame]) -> EgoPath:
    """The path of the vehicle positions the SAR images carry (when the scene has no tracklog)."""
    stamped = [(f.timestamp_s, f.position_ecef) for f in frames]
    return EgoPath(np.array([t for t, _ in stamped]), np.array([p for _, p in stamped]).reshape(-1, 3))


def _image_centre(frame: rec.SarFrame) -> np.ndarray:
    return frame.origin_ecef + frame.rows / 2 * frame.di_ecef + frame.cols / 2 * frame.dj_ecef


def _attitude_lateral_left_m(frame: rec.SarFrame) -> float | None:
    centre, q = _image_centre(frame), frame.attitude_wxyz
    if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(q)) and np.all(np.isfinite(frame.position_ecef))):
        return None
    norm = np.linalg.norm(q)
    if norm == 0:
        return None
    offset_imu = quat_wxyz_to_matrix(q / norm).T @ (centre - frame.position_ecef)
    return -float(offset_imu[1])  # forward-right-down: +y is right


def _fill(votes: SideVotes, laterals: Iterator[float | None]) -> None:
    for lateral in itertools.islice(laterals, MAX_FRAMES_EXAMINED):
        if lateral is not None:
            votes.add(lateral)
            if len(votes.lateral_m) >= EVIDENCE_FRAMES:
                return


def gather_evidence(
    images: Mapping[str, OpenedStream], points: Mapping[str, OpenedStream], path: EgoPath | None,
    sar_frames: Callable[[OpenedStream], Iterator[rec.SarFrame]],
) -> dict[str, RadarSideEvidence]:
    """Every radar's evidence: the attitude reading and the path readings of its images and detections.

    Parameters
    ----------
    images, points
        Serial -> its ``Image`` and ``TrackerState`` streams.
    path
        The path driven, or None (no tracklog and no image positions).
    sar_frames
        ``sar_frames(opened)``: a fresh iterator over a stream's SAR frames (look-ahead, nothing counted).
    """
    evidence: dict[str, RadarSideEvidence] = {}
    for serial in sorted(set(images) | set(points)):
        found = evidence[serial] = RadarSideEvidence(serial)
        if serial in images:
            _fill(found.attitude, (_attitude_lateral_left_m(f) for f in sar_frames(images[serial])))
            if path is not None:
                _fill(found.images, (path.lateral_left_m(f.timestamp_s, _image_centre(f)) for f in sar_frames(images[serial])))
        if serial in points and path is not None:
            frames = decoded_records(points[serial], rec.detections, probe=True)
            _fill(found.detections, (path.lateral_left_m(d.timestamp_s, d.columns["position_ecef"]) for d in frames))
    return evidence


def decide_sides(scene_id: str, evidence: Mapping[str, RadarSideEvidence], stated: Mapping[str, str],
                 assumed: list[str]) -> dict[str, str]:
    """Serial -> ``"left"``/``"right"`` for one scene's radars, or {} when they keep their serials.

    With ``stated`` naming any radar of the scene, the stated sides are taken and the other radars
    keep their serials.  Otherwise each radar takes the side every deciding reading agrees on; sides
    are used as names only when every radar has one and no side is taken twice.

    Parameters
    ----------
    scene_id
        Names the scene in the sentences and the error.
    evidence
        :func:`gather_evidence`'s.
    stated
        Serial -> side the user stated (``--sides``); serials of other scenes are ignored here.
    assumed
        Where the decision and its evidence are recorded.

    Raises
    ------
    ZendarFormatError
        When the readings of some radar disagree and the user stated no side for the scene: one
        problem per radar with its evidence, and one saying how to state the sides.
    """
    mine = {serial: side for serial, side in stated.items() if serial in evidence}
    if mine:
        for serial, item in sorted(evidence.items()):
            if serial in mine:
                assumed.append(f"serial {serial} -> {mine[serial]!r}: stated with --sides (evidence: {item.describe()})")
            else:
                assumed.append(f"serial {serial}: not named in --sides, so it keeps its serial as its name")
        return dict(mine)
    disagreeing = [serial for serial, item in evidence.items() if len(set(item.readings().values())) > 1]
    if disagreeing:
        problems = [f"{scene_id}: radar {serial}: {item.describe()}" for serial, item in sorted(evidence.items())]
        hint = ",".join(f"{serial}={item.path_side}" for serial, item in sorted(evidence.items()) if item.path_side)
        problems.append(
            f"{scene_id}: left and right are not guessed when Image.attitude and the path driven disagree "
            f"(radars {', '.join(sorted(disagreeing))}; an attitude of x forward, y left, z up swaps them); "
            "state the sides with --sides SERIAL=left,SERIAL=right"
            + (f" (the path's answer: --sides {hint})" if hint else "")
        )
        raise ZendarFormatError(problems[-1], problems)
    sides = {serial: next(iter(item.readings().values())) for serial, item in evidence.items() if item.readings()}
    if len(sides) != len(evidence) or len(set(sides.values())) != len(sides):
        described = "; ".join(f"{serial}: {item.describe()}" for serial, item in sorted(evidence.items()))
        assumed.append(f"serial -> side: not decidable ({described}); radars keep their serials as names")
        return {}
    for serial, side in sorted(sides.items()):
        item = evidence[serial]
        readings = set(item.readings())
        if "attitude" in readings and len(readings) > 1:
            how = "Image.attitude and the path driven agree"
        elif "attitude" in readings:
            how = "Image.attitude alone, not checked (the path driven says nothing: no motion or no positions)"
        else:
            how = "the path driven alone (Image.attitude says nothing)"
        assumed.append(f"serial {serial} -> {side!r}: {how}; {item.describe()}")
    return sides


def parse_stated_sides(text: str) -> dict[str, str]:
    """``"A=left,B=right"`` -> ``{"A": "left", "B": "right"}`` (``--sides``).

    Raises
    ------
    ZendarError
        A malformed entry, a side other than left/right, a serial or a side given twice.
    """
    stated: dict[str, str] = {}
    for entry in (part.strip() for part in text.split(",")):
        serial, equals, side = entry.partition("=")
        serial, side = serial.strip(), side.strip().lower()
        if not equals or not serial or side not in SIDES:
            raise ZendarError(f"--sides: expected SERIAL=left or SERIAL=right, got {entry!r}")
        if serial in stated:
            raise ZendarError(f"--sides: serial {serial} is given twice")
        stated[serial] = side
    if len(set(stated.values())) != len(stated):
        raise ZendarError(f"--sides: one side is given to more than one serial ({text})")
    return stated
