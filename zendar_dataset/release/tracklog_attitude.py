"""Whether a tracklog's ``Position.attitude`` is what the import takes it for: IMU (forward, right,
down) vectors rotated into ECEF (paper §3.3; ``release/assumptions.py``).

The ego poses, and with them every sensor's placement, rest on that convention, and the release does
not state it. Two facts that need no attitude check it:

- **the local vertical** at each position: the IMU's third axis (down) points down, i.e. against the
  WGS-84 ellipsoid's normal;
- **the direction of travel** from the positions (over ±:data:`~zendar_dataset.release.sides.TRAVEL_WINDOW_S`,
  where the vehicle moves at least :data:`~zendar_dataset.release.sides.MIN_SPEED_MPS`): the IMU's first
  axis (forward) points along it.

An attitude of another convention (x forward, y left, z up, say, or an IMU mounted backwards) makes
one of them point the other way in nearly every record. When at least
:data:`~zendar_dataset.release.sides.DECISIVE_SHARE` of the records (of the moving ones, for the
forward axis) contradict the convention, :func:`check_attitude` refuses with the evidence; otherwise it
returns the evidence for the import summary. A record's axis contradicts when it lies more than 120°
from the direction it should have (cosine below -0.5); a few records at odd attitudes (a tilted
fixture, a turn) do not decide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.geometry import local_up_ecef, quat_wxyz_to_matrix
from zendar_dataset.release.sides import DECISIVE_SHARE, MIN_SPEED_MPS, TRAVEL_WINDOW_S

#: A record's axis contradicts the convention below this cosine with its expected direction.
CONTRADICTING_COSINE = -0.5
#: Records examined, evenly spaced (an hour at 100 Hz would take a while and say nothing more).
MAX_RECORDS = 2000


@dataclass(frozen=True)
class AxisEvidence:
    """How one IMU axis lies against the direction the convention gives it, over some records."""

    records: int
    contradicting: int
    median_cosine: float

    @property
    def refutes(self) -> bool:
        """At least :data:`DECISIVE_SHARE` of the records contradict the convention."""
        return self.records > 0 and self.contradicting >= DECISIVE_SHARE * self.records

    def describe(self, axis: str, expected: str) -> str:
        if not self.records:
            return f"its {axis} axis: no record to compare with {expected}"
        return (f"its {axis} axis lies against {expected} in {self.contradicting} of {self.records} records "
                f"(median cosine {self.median_cosine:+.2f}; +1 is the convention)")


def _axis_evidence(cosines: np.ndarray) -> AxisEvidence:
    if cosines.size == 0:
        return AxisEvidence(0, 0, float("nan"))
    return AxisEvidence(int(cosines.size), int(np.count_nonzero(cosines < CONTRADICTING_COSINE)), float(np.median(cosines)))


def attitude_evidence(times_s: np.ndarray, positions_ecef: np.ndarray, attitude_wxyz: np.ndarray) -> tuple[AxisEvidence, AxisEvidence]:
    """``(down, forward)``: the IMU's third axis against the local "down", and its first axis against the
    direction of travel (moving records only).

    Parameters
    ----------
    times_s : numpy.ndarray
        ``[K]`` float64 seconds, increasing.
    positions_ecef : numpy.ndarray
        ``[K, 3]`` metres.
    attitude_wxyz : numpy.ndarray
        ``[K, 4]`` quaternions (any norm).
    """
    times_s = np.asarray(times_s, np.float64).reshape(-1)
    positions_ecef = np.asarray(positions_ecef, np.float64).reshape(-1, 3)
    attitude_wxyz = np.asarray(attitude_wxyz, np.float64).reshape(-1, 4)
    if times_s.size == 0:
        empty = _axis_evidence(np.zeros(0))
        return empty, empty
    pick = np.unique(np.linspace(0, times_s.size - 1, min(times_s.size, MAX_RECORDS)).round().astype(np.int64))
    rotation = quat_wxyz_to_matrix(attitude_wxyz[pick])  # IMU -> ECEF: its columns are the IMU's axes
    down = _axis_evidence(np.einsum("ki,ki->k", rotation[:, :, 2], -local_up_ecef(positions_ecef[pick])))
    t = times_s[pick]
    start = np.maximum(t - TRAVEL_WINDOW_S, times_s[0])
    end = np.minimum(t + TRAVEL_WINDOW_S, times_s[-1])
    travel = np.stack([np.interp(end, times_s, positions_ecef[:, a]) - np.interp(start, times_s, positions_ecef[:, a])
                       for a in range(3)], axis=1)
    distance = np.linalg.norm(travel, axis=1)
    moving = (end > start) & (distance >= MIN_SPEED_MPS * (end - start)) & (distance > 0)
    forward = _axis_evidence(np.einsum("ki,ki->k", rotation[moving, :, 0], travel[moving] / distance[moving, None]))
    return down, forward


def check_attitude(scene_id: str, down: AxisEvidence, forward: AxisEvidence) -> str:
    """The evidence as one sentence for the import summary; :class:`ZendarFormatError` (the evidence
    listed) when either axis refutes the convention."""
    text = (f"{down.describe('third (down)', 'the local downward vertical')}; "
            f"{forward.describe('first (forward)', 'the direction of travel')}")
    if down.refutes or forward.refutes:
        problem = (f"{scene_id}: the tracklog's Position.attitude is not IMU (forward, right, down) -> ECEF: {text}. "
                   "The ego poses would be wrong; the import does not guess another convention")
        raise ZendarFormatError(problem, [problem])
    return f"Position.attitude checked against the path: {text}"


__all__ = ["AxisEvidence", "attitude_evidence", "check_attitude"]
