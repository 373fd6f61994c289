"""The detection chain shared by the CFAR baseline, the automatic labels and the CNN rows (paper §2.3, §4.3).

Per radar cube::

    range-Doppler cells (CFAR peaks, or the cells of a CNN's mask)      cfar_cells / mask_cells
      -> DOA per cell -> points in the ego frame at the cube's time      cube_points
      -> SAR static-scene test per point                                 (zendar_baselines.sar_test)

and per evaluator frame, with every radar's points moved into the frame's ego frame (each point
also moved along its line of sight by its radial velocity over the cube-to-frame time, :func:`to_frame`)::

      -> DBSCAN clusters of all points -> one detection per cluster      frame_detections
         holding dynamic points

A cluster is formed from static and dynamic points alike (paper Fig. 2: a cluster mixing both is
*uncertain*); its detection is placed at the score-weighted centre of its dynamic points and scored
by their summed score times the cluster's dynamic share, so that clusters the SAR test calls wholly
dynamic rank above mixed ones.

The radar sees a car's near face (the far side is occluded), so the centre of a cluster lies short
of the car's centre along the line of sight. Each detection is pushed away from the radars by
:attr:`ChainParams.centre_offset_m`, measured on the training split
(:mod:`zendar_baselines.chain_fit`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from zendar_baselines.sar_test import SarTestParams, is_dynamic, sar_db_at
from zendar_dataset.classical_detector import CFAR_PFA, CLUSTER_EPS_M, cluster_labels, locate_cells
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import SceneReader
from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.radar.cfar import cfar_2d, local_maxima
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.sync import resolve_reference

# Along the line of sight, labelled centres lie this far beyond the clusters' centres: the median
# over the clusters of the demo training split (the dataset and command of
# zendar_baselines.sar_test.DEFAULT_THRESHOLD_DB) with a label within 4 m. About half a car's
# length: most cars are seen from behind or ahead, in the ego's own street.
DEFAULT_CENTRE_OFFSET_M = 2.02


@dataclass(frozen=True)
class ChainParams:
    """Settings of the detection chain.

    Attributes
    ----------
    cfar_pfa : float
        False-alarm probability of the CA-CFAR (the classical detector's).
    sar : SarTestParams
        The static-scene test.
    cluster_eps_m : float
        DBSCAN neighbourhood, metres (about half a car length: one car's scatterers chain into one
        cluster).
    centre_offset_m : float
        Each detection moves this far along the line of sight away from the radars.
    """

    cfar_pfa: float = CFAR_PFA
    sar: SarTestParams = field(default_factory=SarTestParams)
    cluster_eps_m: float = CLUSTER_EPS_M
    centre_offset_m: float = DEFAULT_CENTRE_OFFSET_M

    def __post_init__(self) -> None:
        if not 0.0 < self.cfar_pfa < 1.0:
            raise ZendarError(f"ChainParams.cfar_pfa must lie in (0, 1), got {self.cfar_pfa!r}")
        if not self.cluster_eps_m > 0.0:
            raise ZendarError(f"ChainParams.cluster_eps_m must be > 0 m, got {self.cluster_eps_m!r}")
        if not np.isfinite(self.centre_offset_m):
            raise ZendarError(f"ChainParams.centre_offset_m must be a finite number of metres, got {self.centre_offset_m!r}")

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (recorded in the predictions' ``meta``)."""
        return {**asdict(self), "sar": self.sar.to_json(), "cfar": "CA, local maxima"}


@dataclass(frozen=True)
class RadarCells:
    """Cells of one range-Doppler map; every field ``[N]``.

    Attributes
    ----------
    range_bin, doppler_bin : numpy.ndarray
        int64 indices (Doppler bin ``D // 2`` is zero velocity).
    score : numpy.ndarray
        float64 weight of each cell: linear SNR over the CFAR noise estimate (CFAR), or the
        predicted probability (a CNN's mask).
    """

    range_bin: np.ndarray
    doppler_bin: np.ndarray
    score: np.ndarray

    def __post_init__(self) -> None:
        shapes = {name: np.shape(getattr(self, name)) for name in ("range_bin", "doppler_bin", "score")}
        if len(set(shapes.values())) != 1 or len(shapes["score"]) != 1:
            raise ZendarError(f"RadarCells fields must all be [N] arrays, got shapes {shapes}")

    def __len__(self) -> int:
        return int(np.shape(self.score)[0])


@dataclass(frozen=True)
class CubePoints:
    """Cells of one cube placed in the ego frame at the cube's time and put to the SAR test; fields ``[N]``.

    Attributes
    ----------
    timestamp_ns : int
        The cube's timestamp (the ego frame of ``points_ego``).
    ecef_T_ego : SE3
        The ego pose at ``timestamp_ns``.
    radar_ego : numpy.ndarray
        ``[3]`` float64 the radar's position, metres, ego frame.
    range_bin, doppler_bin : numpy.ndarray
        int64 cell indices.
    points_ego : numpy.ndarray
        ``[N, 3]`` float64 metres.
    score : numpy.ndarray
        float64, the cells' scores.
    residual_mps : numpy.ndarray
        float64 radial velocity over the ground (measured minus a static point's, m/s,
        :func:`zendar_dataset.classical_detector.locate_cells`).
    sar_db : numpy.ndarray
        float64 SAR value (:func:`zendar_baselines.sar_test.sar_db_at`), NaN where no image covers.
    dynamic : numpy.ndarray
        bool, the SAR test's verdict.
    """

    timestamp_ns: int
    ecef_T_ego: SE3
    radar_ego: np.ndarray
    range_bin: np.ndarray
    doppler_bin: np.ndarray
    points_ego: np.ndarray
    score: np.ndarray
    residual_mps: np.ndarray
    sar_db: np.ndarray
    dynamic: np.ndarray

    def __len__(self) -> int:
        return int(np.shape(self.score)[0])


@dataclass(frozen=True)
class FramePoints:
    """Points of one or more cubes in one frame's ego frame; fields ``[N]`` (``[N, 2]`` for positions).

    Attributes
    ----------
    points_xy : numpy.ndarray
        float64 metres.
    radar_xy : numpy.ndarray
        float64 metres, the position of the radar that saw each point.
    score : numpy.ndarray
        float64 cell scores.
    sar_db : numpy.ndarray
        float64 SAR values (NaN where no image covers the point).
    dynamic : numpy.ndarray
        bool, the SAR test's verdict.
    """

    points_xy: np.ndarray
    radar_xy: np.ndarray
    score: np.ndarray
    sar_db: np.ndarray
    dynamic: np.ndarray

    _FIELDS = ("points_xy", "radar_xy", "score", "sar_db", "dynamic")

    def __len__(self) -> int:
        return int(np.shape(self.score)[0])

    @classmethod
    def concatenate(cls, parts: list[FramePoints]) -> FramePoints:
        """All points of ``parts`` in one record (an empty one for no parts)."""
        if not parts:
            return cls(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0, bool))
        return cls(*(np.concatenate([getattr(p, name) for p in parts]) for name in cls._FIELDS))

    def retested(self, sar: SarTestParams) -> FramePoints:
        """The same points with the SAR test's verdict under other settings."""
        return FramePoints(self.points_xy, self.radar_xy, self.score, self.sar_db, is_dynamic(self.sar_db, sar))


def cube_power(cube: np.ndarray) -> np.ndarray:
    """``[R, D]`` float64 power summed over antennas (non-coherent) of a cube ``[R, D, A]``."""
    cube = np.asarray(cube)
    if cube.ndim != 3 or not np.iscomplexobj(cube):
        raise ZendarError(f"expected a complex range-Doppler cube [R, D, A], got {cube.dtype} of shape {cube.shape}")
    return np.einsum("rda,rda->rd", cube, cube.conj()).real


def cfar_map(power: np.ndarray, params: ChainParams | None = None) -> tuple[RadarCells, np.ndarray]:
    """CA-CFAR peaks of a power map and the noise estimate everywhere.

    Parameters
    ----------
    power : numpy.ndarray
        ``[R, D]`` float64 power (:func:`cube_power`).
    params : ChainParams, optional
        ``cfar_pfa``.

    Returns
    -------
    cells : RadarCells
        Cells over the threshold that are local maxima (one per peak), score = linear SNR.
    noise_power : numpy.ndarray
        ``[R, D]`` float64 CA noise estimate (training-cell mean), power units.
    """
    params = ChainParams() if params is None else params
    result = cfar_2d(power, method="ca", pfa=params.cfar_pfa)
    r_idx, d_idx = np.nonzero(result.mask & local_maxima(power))
    noise = result.noise_power
    with np.errstate(divide="ignore"):
        snr = power[r_idx, d_idx] / noise[r_idx, d_idx]
    return RadarCells(r_idx.astype(np.int64), d_idx.astype(np.int64), snr), noise


def cfar_cells(cube: np.ndarray, params: ChainParams | None = None) -> RadarCells:
    """CA-CFAR peaks of a cube ``[R, D, A]`` (the classical detector's CFAR), score = linear SNR."""
    return cfar_map(cube_power(cube), params)[0]


def mask_cells(probability: np.ndarray, threshold: float = 0.5) -> RadarCells:
    """The cells of a predicted moving-object mask.

    Parameters
    ----------
    probability : numpy.ndarray
        ``[R, D]`` float per-cell probability of a moving object.
    threshold : float
        Cells with probability at or above this are kept.

    Returns
    -------
    RadarCells
        Score = the probability.
    """
    probability = np.asarray(probability, np.float64)
    if probability.ndim != 2:
        raise ZendarError(f"mask_cells: probability must be [R, D], got shape {probability.shape}")
    r_idx, d_idx = np.nonzero(probability >= threshold)
    return RadarCells(r_idx.astype(np.int64), d_idx.astype(np.int64), probability[r_idx, d_idx])


def cube_points(
    cube: np.ndarray, cells: RadarCells, timestamp_ns: int, calibration, poses: EgoPoses, sar: SarFrames,
    params: ChainParams | None = None,
) -> CubePoints:
    """Place cells of one cube and put them to the SAR test.

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex cube.
    cells : RadarCells
        The cells to place.
    timestamp_ns : int
        The cube's timestamp.
    calibration
        The radar's calibration record.
    poses : EgoPoses
        The scene's ego poses.
    sar : SarFrames
        The scene's SAR images.
    params : ChainParams, optional
        ``sar`` settings.
    """
    params = ChainParams() if params is None else params
    points_ego, residual_mps = locate_cells(cube, cells.range_bin, cells.doppler_bin, timestamp_ns, calibration, poses)
    ecef_T_ego = poses.ecef_T_ego(int(timestamp_ns))
    sar_db = sar_db_at(sar, ecef_T_ego.transform_points(points_ego), timestamp_ns, max_frame_gap_ns=params.sar.max_frame_gap_ns)
    return CubePoints(
        int(timestamp_ns), ecef_T_ego, np.asarray(ego_T_sensor(calibration).translation, np.float64), cells.range_bin, cells.doppler_bin,
        points_ego, cells.score, residual_mps, sar_db, is_dynamic(sar_db, params.sar),
    )


def to_frame(points: CubePoints, poses: EgoPoses, frame_ns: int) -> FramePoints:
    """A cube's points in the ego frame at ``frame_ns`` (the evaluator's frame).

    Static points keep their place in the world. A moving car goes on moving between the cube and
    the frame (up to a cube interval, 0.1 s: 1.5 m at 15 m/s); the cube measures the radial part of
    its velocity, so each point moves along its line of sight by ``residual_mps`` times the time
    difference (about zero for static points).
    """
    if len(points) == 0:
        return FramePoints.concatenate([])
    line_of_sight = points.points_ego - points.radar_ego
    distance = np.linalg.norm(line_of_sight, axis=1, keepdims=True)
    line_of_sight = np.divide(line_of_sight, distance, out=np.zeros_like(line_of_sight), where=distance > 0)
    dt_s = (int(frame_ns) - points.timestamp_ns) * 1e-9
    ahead_ego = points.points_ego + line_of_sight * (points.residual_mps * dt_s)[:, None]
    frame_T_cube = poses.ecef_T_ego(int(frame_ns)).inverse().compose(points.ecef_T_ego)
    moved = frame_T_cube.transform_points(ahead_ego)
    radar = frame_T_cube.transform_points(points.radar_ego[None])
    return FramePoints(moved[:, :2], np.repeat(radar[:, :2], len(points), axis=0), points.score, points.sar_db, points.dynamic)


@dataclass(frozen=True)
class Cluster:
    """One DBSCAN cluster of a frame's points that holds dynamic points, before the centre correction.

    Attributes
    ----------
    centre_xy : numpy.ndarray
        ``[2]`` float64 metres, score-weighted centre of the dynamic members.
    radar_xy : numpy.ndarray
        ``[2]`` float64 metres, score-weighted position of the radars that saw them.
    score : float
        Summed score of the dynamic members times the dynamic share.
    n_points, n_dynamic : int
        Members, and members the SAR test calls dynamic.
    """

    centre_xy: np.ndarray
    radar_xy: np.ndarray
    score: float
    n_points: int
    n_dynamic: int

    def corrected_centre(self, offset_m: float) -> np.ndarray:
        """``[2]`` the centre moved ``offset_m`` along the line of sight away from the radars."""
        line_of_sight = self.centre_xy - self.radar_xy
        distance = float(np.hypot(*line_of_sight))
        return self.centre_xy + offset_m * line_of_sight / distance if distance > 0 else self.centre_xy


def frame_clusters(points: FramePoints, params: ChainParams | None = None) -> list[Cluster]:
    """DBSCAN over all of a frame's points; the clusters holding dynamic points (module docstring).

    Parameters
    ----------
    points : FramePoints
        Every radar's points of the frame (:meth:`FramePoints.concatenate` of :func:`to_frame`).
    params : ChainParams, optional
        ``cluster_eps_m``.
    """
    params = ChainParams() if params is None else params
    if not np.any(points.dynamic):
        return []
    labels = cluster_labels(points.points_xy, params.cluster_eps_m)
    n_clusters = int(labels.max()) + 1
    moving = points.dynamic
    n_points = np.bincount(labels, minlength=n_clusters)
    n_dynamic = np.bincount(labels[moving], minlength=n_clusters)
    score = np.bincount(labels[moving], weights=points.score[moving], minlength=n_clusters)
    # Placement needs positive finite weights: a cluster whose scores are not falls back to equal ones.
    finite = np.isfinite(points.score[moving])
    usable = (np.bincount(labels[moving], weights=~finite, minlength=n_clusters) == 0) & (score > 0)
    weights = np.where(usable[labels[moving]], np.where(finite, points.score[moving], 0.0), 1.0)
    total = np.bincount(labels[moving], weights=weights, minlength=n_clusters)
    centre = np.stack([np.bincount(labels[moving], weights=weights * points.points_xy[moving, axis], minlength=n_clusters)
                       for axis in (0, 1)], axis=1)
    radar = np.stack([np.bincount(labels[moving], weights=weights * points.radar_xy[moving, axis], minlength=n_clusters)
                      for axis in (0, 1)], axis=1)
    return [
        Cluster(centre[c] / total[c], radar[c] / total[c], float(score[c] * n_dynamic[c] / n_points[c]), int(n_points[c]), int(n_dynamic[c]))
        for c in np.flatnonzero(n_dynamic).tolist()
    ]


def frame_detections(points: FramePoints, params: ChainParams | None = None) -> list[dict[str, float]]:
    """One scored detection per cluster holding dynamic points, its centre corrected for occlusion.

    Parameters
    ----------
    points : FramePoints
        Every radar's points of the frame.
    params : ChainParams, optional
        ``cluster_eps_m`` and ``centre_offset_m``.

    Returns
    -------
    list of dict
        ``{"x", "y", "score"}`` in the points' ego frame, metres; the evaluator's format.
    """
    params = ChainParams() if params is None else params
    detections = []
    for cluster in frame_clusters(points, params):
        x, y = cluster.corrected_centre(params.centre_offset_m)
        detections.append({"x": float(x), "y": float(y), "score": cluster.score})
    return detections


def latest_cube(cube_timestamps_ns: np.ndarray, frame_ns: int) -> int | None:
    """Index of the latest cube at or before ``frame_ns`` (the loader's rule), or None."""
    k = int(np.searchsorted(cube_timestamps_ns, frame_ns, side="right")) - 1
    return k if k >= 0 else None


def frame_timestamps(reader: SceneReader) -> np.ndarray:
    """``[F]`` int64 the scene's frames: its first SAR stream's timestamps (docs/format.md)."""
    return reader.timestamps(resolve_reference(reader, "sar"))


def frame_cube_points(
    reader: SceneReader, cells_of: Callable[[str, int, np.ndarray], RadarCells], params: ChainParams | None = None, *,
    poses: EgoPoses | None = None, sar: SarFrames | None = None,
) -> Iterator[tuple[int, list[CubePoints]]]:
    """Per frame of a scene, each radar's latest cube at or before it, its cells placed and SAR-tested.

    Parameters
    ----------
    reader : SceneReader
        The scene.
    cells_of : callable
        ``cells_of(radar, cube_index, cube) -> RadarCells``: the cells of a cube ``[R, D, A]``
        (e.g. ``lambda radar, k, cube: cfar_cells(cube, params)``).
    params : ChainParams, optional
        SAR test settings.
    poses, sar : optional
        The scene's ego poses and SAR images when already built.

    Yields
    ------
    frame_ns : int
        The frame's timestamp.
    points : list of CubePoints
        One per radar with a cube at or before the frame (a cube shared by consecutive frames is
        processed once).
    """
    params = ChainParams() if params is None else params
    poses = reader.ego_poses() if poses is None else poses
    sar = SarFrames(reader) if sar is None else sar
    radars = reader.sensors("radar")
    cube_times = {radar: reader.timestamps(f"radar/{radar}") for radar in radars}
    cubes = {radar: reader.array(f"radar/{radar}/cube") for radar in radars}
    calibration = reader.calibration.sensors
    last: dict[str, tuple[int, CubePoints]] = {}
    for frame_ns in frame_timestamps(reader).tolist():
        found = []
        for radar in radars:
            k = latest_cube(cube_times[radar], frame_ns)
            if k is None:
                continue
            if radar not in last or last[radar][0] != k:
                cube = np.asarray(cubes[radar][k])
                cells = cells_of(radar, k, cube)
                last[radar] = (k, cube_points(cube, cells, int(cube_times[radar][k]), calibration[radar], poses, sar, params))
            found.append(last[radar][1])
        yield int(frame_ns), found
