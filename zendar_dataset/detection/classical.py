"""A simple classical moving-car detector on range-Doppler cubes: CFAR, DOA, a Doppler test, DBSCAN.

The detector of ``examples/end_to_end.py`` (and of the fidelity report, which measures it per range
band).  It is *not* the paper's baseline (CFAR + SAR-mask auto-labels + CNN, see ``baselines/``).
Per cube it

1. finds peaks with CA-CFAR and their azimuth with Bartlett beamforming;
2. compares each detection's radial velocity with what a static point at that azimuth would show
   given the radar's own velocity from the tracklog (the *plain Doppler test*);
3. keeps the detections that differ by more than :data:`MIN_RADIAL_SPEED_MPS`, and
4. clusters them (DBSCAN), one car per cluster.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.detection.clusters import cluster_labels
from zendar_dataset.detection.locate import locate_cells
from zendar_dataset.detection.params import CFAR_PFA
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.radar import FmcwParams, detect

# A detection is "moving" when its radial velocity is this far from the static-world value:
# about two Doppler bins of the demo profile, above the spread that DOA errors cause on clutter.
MIN_RADIAL_SPEED_MPS = 1.5


@dataclass(frozen=True)
class RadarPoints:
    """CFAR detections of one cube, placed in the ego frame at the cube's time.

    Attributes
    ----------
    points_ego : numpy.ndarray
        ``[N, 3]`` float64 metres (ego frame at the cube's timestamp, on the radar's plane).
    range_m : numpy.ndarray
        ``[N]`` range from the radar, metres.
    snr : numpy.ndarray
        ``[N]`` linear SNR over the CFAR noise estimate.
    residual_mps : numpy.ndarray
        ``[N]`` measured radial velocity minus a static point's at that azimuth (m/s, wrapped onto
        the unambiguous Doppler span): the plain Doppler test's statistic.
    """

    points_ego: np.ndarray
    range_m: np.ndarray
    snr: np.ndarray
    residual_mps: np.ndarray

    @property
    def moving(self) -> np.ndarray:
        """``[N]`` bool: the Doppler test calls the detection moving."""
        return np.abs(self.residual_mps) > MIN_RADIAL_SPEED_MPS


def radar_points(cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses) -> RadarPoints:
    """Every CFAR detection of one cube ``[R, D, A]`` with its Doppler-test residual.

    ``calibration`` is the radar's calibration record (``format.RadarCalibration``); ``poses`` the
    scene's ego poses.
    """
    params = FmcwParams.from_calibration(calibration, n_samples=cube.shape[0], n_chirps=cube.shape[1])
    found = detect(cube, params, method="ca", pfa=CFAR_PFA)
    points_ego, residual_mps = locate_cells(cube, found.range_bin, found.doppler_bin, timestamp_ns, calibration, poses)
    return RadarPoints(points_ego, np.asarray(found.range_m, np.float64), 10.0 ** (found.snr_db / 10.0), residual_mps)


def moving_points(cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses) -> tuple[np.ndarray, np.ndarray]:
    """Moving detections of one cube [R, D, A]: points_ego [M, 3] at the cube's time and SNR [M] (linear)."""
    found = radar_points(cube, timestamp_ns, calibration, poses)
    return found.points_ego[found.moving], found.snr[found.moving]


def cluster_cars(points_ego: np.ndarray, snr: np.ndarray) -> list[dict[str, float]]:
    """One prediction per DBSCAN cluster: SNR-weighted centre, score = summed linear SNR."""
    if len(points_ego) == 0:
        return []
    labels = cluster_labels(points_ego[:, :2])
    cars = []
    for label in np.unique(labels):
        members = labels == label
        centre = np.average(points_ego[members, :2], axis=0, weights=snr[members])
        cars.append({"x": float(centre[0]), "y": float(centre[1]), "score": float(snr[members].sum())})
    return cars
