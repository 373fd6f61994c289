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
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.radar import FmcwParams, detect, detections_to_points, estimate_azimuth
from zendar_dataset.radar.cfar import cell_spacing

CFAR_PFA = 1e-4
# A detection is "moving" when its radial velocity is this far from the static-world value:
# about two Doppler bins of the demo profile, above the spread that DOA errors cause on clutter.
MIN_RADIAL_SPEED_MPS = 1.5
CLUSTER_EPS_M = 1.5  # about half a car length: one car's scatterers chain into one cluster
VELOCITY_HALF_STEP_NS = 50_000_000  # central difference over +-50 ms of tracklog


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


def mount_velocity_ego(poses: EgoPoses, point_ego: np.ndarray, timestamp_ns: int) -> np.ndarray:
    """Velocity over ground [3] (m/s, ego axes at ``timestamp_ns``) of a point fixed to the car.

    A central difference of interpolated poses, so it includes the yaw rate's
    contribution at the radar's mounting point.
    """
    start, end = poses.tracklog.span_ns
    t0 = max(start, timestamp_ns - VELOCITY_HALF_STEP_NS)
    t1 = min(end, timestamp_ns + VELOCITY_HALF_STEP_NS)
    displacement_ecef = poses.ego_to_ecef(point_ego, t1) - poses.ego_to_ecef(point_ego, t0)
    velocity_ecef = displacement_ecef / ((t1 - t0) * 1e-9)
    return poses.ecef_T_ego(timestamp_ns).inverse().rotate_vectors(velocity_ecef)


def locate_cells(
    cube: np.ndarray, range_bin: np.ndarray, doppler_bin: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses
) -> tuple[np.ndarray, np.ndarray]:
    """Where range-Doppler cells of one cube ``[R, D, A]`` lie, and their Doppler-test residual.

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex range-Doppler cube.
    range_bin, doppler_bin : numpy.ndarray
        ``[N]`` int cell indices (Doppler bin ``D // 2`` is zero velocity), e.g. CFAR peaks or the
        cells of a predicted mask.
    timestamp_ns : int
        The cube's timestamp.
    calibration
        The radar's calibration record (``format.RadarCalibration``).
    poses : EgoPoses
        The scene's ego poses.

    Returns
    -------
    points_ego : numpy.ndarray
        ``[N, 3]`` float64 metres, ego frame at ``timestamp_ns`` (Bartlett DOA of each cell's antenna
        vector, on the radar's plane).
    residual_mps : numpy.ndarray
        ``[N]`` float64 measured radial velocity minus a static point's at that azimuth (m/s, wrapped
        onto the unambiguous Doppler span).
    """
    params = FmcwParams.from_calibration(calibration, n_samples=cube.shape[0], n_chirps=cube.shape[1])
    range_bin_m, doppler_bin_mps = cell_spacing(params, cube.shape[0], cube.shape[1])
    range_bin = np.asarray(range_bin, np.int64)
    doppler_bin = np.asarray(doppler_bin, np.int64)
    range_m = range_bin * float(range_bin_m)
    velocity_mps = (doppler_bin - cube.shape[1] // 2) * float(doppler_bin_mps)
    snapshots = cube[range_bin, doppler_bin]  # [N, A]
    azimuth_rad = estimate_azimuth(snapshots, params.rx_positions_m, params.wavelength_m)
    ego_T_radar = ego_T_sensor(calibration)
    points_ego = detections_to_points(range_m, azimuth_rad, ego_T_radar)

    # A static point's range changes at -(line of sight . radar velocity).
    radar_velocity_ego = mount_velocity_ego(poses, ego_T_radar.translation, timestamp_ns)
    line_of_sight_radar = np.stack([np.cos(azimuth_rad), np.sin(azimuth_rad), np.zeros_like(azimuth_rad)], axis=1)
    static_mps = -ego_T_radar.rotate_vectors(line_of_sight_radar) @ radar_velocity_ego
    # Doppler is ambiguous modulo D bins: compare velocities on that circle.
    span_mps = cube.shape[1] * params.doppler_bin_mps
    residual_mps = (velocity_mps - static_mps + span_mps / 2) % span_mps - span_mps / 2
    return points_ego, residual_mps


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


def cluster_labels(points_xy: np.ndarray, eps_m: float = CLUSTER_EPS_M) -> np.ndarray:
    """``[N]`` int DBSCAN cluster of each point ``[N, 2]`` (metres), every point in one (min_samples=1).

    With one sample per core point, DBSCAN's clusters are the connected components of the graph
    joining points at most ``eps_m`` apart, numbered in order of their first point, as
    ``sklearn.cluster.DBSCAN(eps=eps_m, min_samples=1)`` numbers them; a k-d tree finds the pairs
    (a few times faster than DBSCAN's set-up for the hundreds of points of a frame).
    """
    points_xy = np.asarray(points_xy, np.float64)
    n = len(points_xy)
    if n == 0:
        return np.zeros(0, np.int64)
    pairs = cKDTree(points_xy).query_pairs(eps_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


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
