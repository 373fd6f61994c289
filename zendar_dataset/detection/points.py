"""Cells of a cube placed in the ego frame and put to the SAR test; a cube's points moved to a frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.detection.cells import RadarCells, cfar_map, cube_power
from zendar_dataset.detection.locate import locate_cells
from zendar_dataset.detection.params import ChainParams
from zendar_dataset.detection.static_scene import SarTestParams, is_dynamic, sar_db_at
from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.sar.frames import SarFrames


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
        :func:`zendar_dataset.detection.locate.locate_cells`).
    sar_db : numpy.ndarray
        float64 SAR value, dB (:func:`zendar_dataset.detection.static_scene.sar_db_at`: the SAR reading
        minus the cell's range-Doppler SNR), NaN where no image covers.
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
        float64 SAR values, dB (:func:`zendar_dataset.detection.static_scene.sar_db_at`; NaN where
        no image covers the point).
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
        """The same points with the SAR test's verdict under another threshold (``sar.threshold_db``
        alone: the values were read with the settings the points were made with)."""
        return FramePoints(self.points_xy, self.radar_xy, self.score, self.sar_db, is_dynamic(self.sar_db, sar))


def cell_snr_db(cube: np.ndarray, cells: RadarCells, params: ChainParams | None = None) -> np.ndarray:
    """Each cell's range-Doppler SNR: its power over the CA-CFAR noise estimate around it, dB.

    The same power and noise estimate as :func:`zendar_dataset.detection.cells.cfar_cells`, so for
    CFAR cells it is ``10·log10(score)``; a CNN's cells (score = probability) get theirs from the
    cube too. It is the range-Doppler half of the SAR test's value
    (:func:`zendar_dataset.detection.static_scene.sar_db_at`).

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex cube.
    cells : RadarCells
        The cells.
    params : ChainParams, optional
        ``cfar_pfa`` (the noise estimate does not depend on it; the CFAR runs with the chain's).

    Returns
    -------
    numpy.ndarray
        ``[N]`` float64 dB; -inf for a cell of zero power, +inf where the noise estimate is zero.
    """
    if len(cells) == 0:
        return np.zeros(0)
    if cells.snr_db is not None:  # CFAR cells: the same power and noise estimate, computed once
        return np.asarray(cells.snr_db, np.float64)
    power = cube_power(cube)
    noise = cfar_map(power, params)[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return 10.0 * np.log10(power[cells.range_bin, cells.doppler_bin] / noise[cells.range_bin, cells.doppler_bin])


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
        ``sar`` settings (the SNR is subtracted unless ``params.sar.subtract_rd_snr`` is False).
    """
    params = ChainParams() if params is None else params
    points_ego, residual_mps = locate_cells(cube, cells.range_bin, cells.doppler_bin, timestamp_ns, calibration, poses)
    ecef_T_ego = poses.ecef_T_ego(int(timestamp_ns))
    rd_snr_db = cell_snr_db(cube, cells, params) if params.sar.subtract_rd_snr else np.zeros(cells.score.shape)
    radar_ego = np.asarray(ego_T_sensor(calibration).translation, np.float64)
    sar_db = sar_db_at(sar, ecef_T_ego.transform_points(points_ego), timestamp_ns, rd_snr_db=rd_snr_db,
                       max_frame_gap_ns=params.sar.max_frame_gap_ns, radar_ecef=ecef_T_ego.transform_points(radar_ego[None])[0],
                       shadow_margin_m=params.sar.shadow_margin_m, search_radius_m=params.sar.search_radius_m)
    return CubePoints(
        int(timestamp_ns), ecef_T_ego, radar_ego, cells.range_bin, cells.doppler_bin,
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
