"""Per-cube range-Doppler masks: the CNNs' targets (paper §2.3, Fig. 2).

A mask is uint8 ``[R, D]`` of the classes of :mod:`zendar_baselines.labels.mask_classes`: ``BACKGROUND``,
``MOVING`` or ``UNCERTAIN`` (a cell the loss should not count).

- **automatic** (:func:`auto_label_mask`, pretraining; the paper's): the cube's CA-CFAR peaks go through
  the detection chain (DOA, SAR static-scene test) and are clustered (DBSCAN, per cube); each chosen
  peak grows into its *segment* (:func:`grow_segments`), the cells around it that belong to the same
  response, so that the target covers a peak's main lobe and not one cell. A cluster whose points
  the SAR test calls all dynamic is MOVING; a cluster mixing dynamic and not-dynamic points is
  UNCERTAIN (Fig. 2's blue points); a cluster without dynamic points stays BACKGROUND. Where a MOVING
  segment and an UNCERTAIN one overlap, the cell is UNCERTAIN: the overlap says the response is
  shared with points the SAR image calls static, and a wrong MOVING target costs more than a
  skipped cell.
- **manual** (:func:`label_mask`, fine-tuning and the supervised rows), two kinds
  (:attr:`MaskParams.manual_targets`):

  - ``"boxes"`` (default, :func:`box_label_mask`): each labelled box is projected into the map
    (:func:`zendar_baselines.labels.box_targets.box_footprints`: its range extent from the radar and
    the Doppler its points show relative to the radar). The car's cells are that footprint and the
    windows' main lobe around it (:data:`LOBE_BINS`, as the automatic labels' segments keep a peak's
    main lobe); those whose power rises :attr:`MaskParams.floor_margin_db` above the CFAR noise
    estimate are MOVING. The car's other cells, the ring one bin further out (range and Doppler
    error: the label's velocity, the ego's from the tracklog, a turning car's yaw rate) and the cells
    of a box's parts outside the radar's field of view are UNCERTAIN; background elsewhere. A car's
    cells count whether CFAR found a peak there or not.
  - ``"cfar-peaks"`` (:func:`cfar_peak_label_mask`, the ablation's CFAR-gated target): a CFAR peak
    whose point falls inside a labelled box grown by :attr:`MaskParams.box_margin_m`, with the
    radial velocity the box's car would show there, is MOVING; a peak inside a box with another
    velocity (the ground or a facade seen through the box's margin, a wheel's micro-Doppler), or
    within :attr:`MaskParams.near_margin_m` of a box, is UNCERTAIN; the peaks grow into segments.
    Every cell of a car that CFAR missed is BACKGROUND: a CNN trained on it learns to copy CFAR.

  In both, MOVING wins an overlap: the box is the truth, the uncertain cells only a tolerance.

Wheels: a rim point moves over the ground at anything from 0 to twice the car's speed, so wheel
returns fall anywhere between the static scene's Doppler and twice the body's radial velocity over
the ground, a different place in every cube. The box target gives them no Doppler guard band: a band
that wide would cover the static clutter at the car's range (the negatives the CNN most needs to
learn), and the simulated rim points (0.05 m² each, ``Imperfections.wheel_rcs_m2``) are 12 dB below
a body scatterer's median (0.8 m²); the main lobe kept around the footprint takes the spill of the
body's own returns.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.ndimage
from tqdm import tqdm

from zendar_baselines.labels.box_targets import box_footprints
from zendar_baselines.labels.mask_classes import BACKGROUND, MASK_DTYPE, MOVING, UNCERTAIN
from zendar_dataset.detection import (
    ON_CAR_MARGIN_M,
    ChainParams,
    CubePoints,
    LabelBoxes,
    RadarCells,
    cfar_map,
    cluster_labels,
    cube_points,
    cube_power,
    frame_timestamps,
    locate_cells,
    nearest_label_frame,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import SceneReader
from zendar_dataset.geometry.frames import EgoPoses, ego_T_sensor
from zendar_dataset.radar import FmcwParams
from zendar_dataset.sar.frames import SarFrames

KINDS = ("auto", "labels")
#: The kinds of manual-label target (:attr:`MaskParams.manual_targets`).
MANUAL_TARGETS = ("boxes", "cfar-peaks")

# A Hann-windowed point response falls 10 dB below its peak 1.27 bins out, so a 10 dB drop keeps
# a peak's main lobe and the neighbouring peaks of the same car, not the sidelobes (-32 dB).
DEFAULT_DROP_DB = 10.0
# Segments stay within +-3 range and Doppler bins of their seed: a car spans several range bins,
# each with its own CFAR peak, so a small window suffices and a ridge cannot leak far.
DEFAULT_HALF_WINDOW = (3, 3)
# Cells within this of a box (beyond box_margin_m) are uncertain: about two range bins of the demo
# profile plus the DOA error at far range (1 deg at 60 m is 1 m).
DEFAULT_NEAR_MARGIN_M = 2.5
# A peak inside a box must show the box's radial velocity within this: two Doppler bins of the demo
# profile (0.625 m/s) plus the spread DOA errors cause (the classical detector's Doppler test margin).
DEFAULT_MAX_VELOCITY_ERROR_MPS = 1.5
# A box target's cell is MOVING when its power is this far above the CFAR noise estimate. The power
# of a cell summed over A = 4 antennas is, on noise alone, Gamma(4) distributed: it exceeds 5 dB over
# its mean in 0.14 % of cells (3 dB: 4.3 %, 4 dB: 1.0 %), so a car's footprint of a few tens of cells
# holds a noise cell marked MOVING about once in twenty footprints, while a return at 5 dB SNR is
# below the 12.8 dB a CFAR peak needs (Pfa 1e-4) and counts.
DEFAULT_FLOOR_MARGIN_DB = 5.0
# A car's returns spread over the windows' main lobe around its footprint: a Hann-windowed point
# response is 6 dB down one bin out and 10 dB down 1.27 bins out (DEFAULT_DROP_DB's segments).
LOBE_BINS = 1
# Beyond the main lobe, one more bin is uncertain: Doppler errors of the label's and the ego's
# velocity (a few tenths of a m/s) and the range bin a scatterer at a box's edge rounds into.
ERROR_BINS = 1


@dataclass(frozen=True)
class MaskParams:
    """Settings of both kinds of mask.

    Attributes
    ----------
    chain : ChainParams
        CFAR, SAR test and clustering (automatic masks).
    drop_db : float
        A segment keeps cells within this of its seed's power (dB).
    half_window : tuple of int
        ``(range, Doppler)`` bins a segment may reach on each side of its seed.
    box_margin_m : float
        Manual masks: a box grows by this on every side before a point counts as inside (range bin
        plus the DOA error at mid range; the fidelity report's margin).
    near_margin_m : float
        Manual masks: points outside the grown box but within this of the box are uncertain.
    max_velocity_error_mps : float
        Manual masks: largest difference between a point's measured radial velocity over the ground
        and the one its box's car would show there.
    manual_targets : {"boxes", "cfar-peaks"}
        Manual masks: the labelled boxes projected into the map, or the CFAR peaks on the boxes (the
        CFAR-gated target, kept for the ablation); module docstring.
    floor_margin_db : float
        ``"boxes"``: a footprint cell is MOVING when its power is this far above the CFAR noise
        estimate (dB).
    """

    chain: ChainParams = field(default_factory=ChainParams)
    drop_db: float = DEFAULT_DROP_DB
    half_window: tuple[int, int] = DEFAULT_HALF_WINDOW
    box_margin_m: float = ON_CAR_MARGIN_M
    near_margin_m: float = DEFAULT_NEAR_MARGIN_M
    max_velocity_error_mps: float = DEFAULT_MAX_VELOCITY_ERROR_MPS
    manual_targets: str = "boxes"
    floor_margin_db: float = DEFAULT_FLOOR_MARGIN_DB

    def __post_init__(self) -> None:
        problems = []
        if not self.drop_db >= 0:
            problems.append(f"drop_db must be >= 0 dB, got {self.drop_db!r}")
        if len(self.half_window) != 2 or any(int(h) != h or h < 0 for h in self.half_window):
            problems.append(f"half_window must be two non-negative integers, got {self.half_window!r}")
        if not 0 <= self.box_margin_m <= self.near_margin_m:
            problems.append(f"need 0 <= box_margin_m <= near_margin_m, got {self.box_margin_m!r} and {self.near_margin_m!r}")
        if not self.max_velocity_error_mps > 0:
            problems.append(f"max_velocity_error_mps must be > 0, got {self.max_velocity_error_mps!r}")
        if self.manual_targets not in MANUAL_TARGETS:
            problems.append(f"manual_targets must be one of {MANUAL_TARGETS}, got {self.manual_targets!r}")
        margin = self.floor_margin_db
        if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not (math.isfinite(margin) and margin >= 0):
            problems.append(f"floor_margin_db must be a finite number >= 0 dB, got {self.floor_margin_db!r}")
        if problems:
            raise ZendarError("invalid MaskParams: " + "; ".join(problems))

    def with_sar_threshold(self, threshold_db: float | None) -> MaskParams:
        """These settings with the SAR static-scene test's threshold at ``threshold_db`` (None: unchanged)."""
        if threshold_db is None:
            return self
        return replace(self, chain=replace(self.chain, sar=replace(self.chain.sar, threshold_db=threshold_db)))


def grow_segments(
    power_db: np.ndarray, seed_range_bin: np.ndarray, seed_doppler_bin: np.ndarray, drop_db: float, *,
    floor_db: np.ndarray | float = -np.inf, half_window: tuple[int, int] = DEFAULT_HALF_WINDOW,
) -> np.ndarray:
    """The segments around seed cells of a range-Doppler power map.

    A seed's segment is the 4-connected component (``scipy.ndimage.label``) holding the seed, among
    the cells of the window ``seed ± half_window`` whose power is at least the seed's power minus
    ``drop_db`` and above ``floor_db``. The Doppler axis is circular (the DFT's), so windows wrap
    around it; range windows stop at the map's edges. The seed belongs to its segment whatever its
    power.

    Parameters
    ----------
    power_db : numpy.ndarray
        ``[R, D]`` float power in dB.
    seed_range_bin, seed_doppler_bin : numpy.ndarray
        ``[S]`` int seed cells.
    drop_db : float
        How far below its seed a segment's cell may be (dB).
    floor_db : numpy.ndarray or float
        ``[R, D]`` or scalar: cells must lie strictly above it (e.g. the CFAR noise estimate in dB).
    half_window : tuple of int
        ``(range, Doppler)`` bins on each side of the seed.

    Returns
    -------
    numpy.ndarray
        ``[R, D]`` bool, the union of the seeds' segments.
    """
    power_db = np.asarray(power_db, np.float64)
    if power_db.ndim != 2:
        raise ZendarError(f"grow_segments: power_db must be [R, D], got shape {power_db.shape}")
    seeds_r = np.asarray(seed_range_bin, np.int64).reshape(-1)
    seeds_d = np.asarray(seed_doppler_bin, np.int64).reshape(-1)
    n_r, n_d = power_db.shape
    if seeds_r.shape != seeds_d.shape or np.any((seeds_r < 0) | (seeds_r >= n_r) | (seeds_d < 0) | (seeds_d >= n_d)):
        raise ZendarError(f"grow_segments: seeds must be pairs of cells inside the [{n_r}, {n_d}] map")
    allowed = power_db > np.broadcast_to(np.asarray(floor_db, np.float64), power_db.shape)
    half_r = int(half_window[0])
    half_d = min(int(half_window[1]), (n_d - 1) // 2)  # a window wider than the axis would see cells twice
    out = np.zeros(power_db.shape, bool)
    for r, d in zip(seeds_r.tolist(), seeds_d.tolist()):
        rows = np.arange(max(0, r - half_r), min(n_r, r + half_r + 1))
        cols = np.arange(d - half_d, d + half_d + 1) % n_d
        window = np.ix_(rows, cols)
        keep = allowed[window] & (power_db[window] >= power_db[r, d] - drop_db)
        seed = (r - rows[0], half_d)
        keep[seed] = True
        components, _count = scipy.ndimage.label(keep)
        out[window] |= components == components[seed]
    return out


def _power_db_and_floor(cube: np.ndarray, params: MaskParams):
    power = cube_power(cube)
    cells, noise = cfar_map(power, params.chain)
    with np.errstate(divide="ignore"):
        return cells, 10.0 * np.log10(power), 10.0 * np.log10(noise)


def _paint(mask: np.ndarray, power_db: np.ndarray, floor_db: np.ndarray, range_bin, doppler_bin, value: int, params: MaskParams) -> None:
    if len(range_bin):
        mask[grow_segments(power_db, range_bin, doppler_bin, params.drop_db, floor_db=floor_db, half_window=params.half_window)] = value


@dataclass(frozen=True)
class AutoLabelPoints:
    """One cube's points and the automatic labels' verdict on each (:func:`auto_label_points`).

    Attributes
    ----------
    points : CubePoints
        The chain's points of the cube's CFAR peaks (DOA, SAR test).
    cluster_size : numpy.ndarray
        ``[N]`` int: the number of points in each point's cluster.
    moving, uncertain : numpy.ndarray
        ``[N]`` bool: the point's cluster is all dynamic (its segment is MOVING), or mixes dynamic and
        not-dynamic points (UNCERTAIN).
    power_db, floor_db : numpy.ndarray
        ``[R, D]`` the cube's power and CFAR noise estimate, dB (the segments grow in them).
    """

    points: CubePoints
    cluster_size: np.ndarray
    moving: np.ndarray
    uncertain: np.ndarray
    power_db: np.ndarray
    floor_db: np.ndarray


def auto_label_points(
    cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses, sar: SarFrames, params: MaskParams | None = None
) -> AutoLabelPoints:
    """The automatic labels' verdict on each CFAR peak of one cube (module docstring), before the
    segments are grown. Parameters as :func:`auto_label_mask`."""
    params = MaskParams() if params is None else params
    cells, power_db, floor_db = _power_db_and_floor(cube, params)
    points = cube_points(cube, cells, timestamp_ns, calibration, poses, sar, params.chain)
    if len(points) == 0:
        none = np.zeros(0, bool)
        return AutoLabelPoints(points, np.zeros(0, np.int64), none, none, power_db, floor_db)
    clusters = cluster_labels(points.points_ego[:, :2], params.chain.cluster_eps_m)
    n_dynamic = np.bincount(clusters, weights=points.dynamic.astype(np.float64))
    n_points = np.bincount(clusters)
    return AutoLabelPoints(points, n_points[clusters], (n_dynamic == n_points)[clusters],
                           ((n_dynamic > 0) & (n_dynamic < n_points))[clusters], power_db, floor_db)


def auto_label_mask(
    cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses, sar: SarFrames, params: MaskParams | None = None
) -> np.ndarray:
    """The automatic label of one cube (module docstring).

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex cube.
    timestamp_ns : int
        The cube's timestamp.
    calibration
        The radar's calibration record.
    poses : EgoPoses
        The scene's ego poses.
    sar : SarFrames
        The scene's SAR images.
    params : MaskParams, optional

    Returns
    -------
    numpy.ndarray
        ``[R, D]`` uint8 of the classes of :mod:`zendar_baselines.labels.mask_classes`.
    """
    params = MaskParams() if params is None else params
    labelled = auto_label_points(cube, timestamp_ns, calibration, poses, sar, params)
    mask = np.full(labelled.power_db.shape, BACKGROUND, MASK_DTYPE)
    points = labelled.points
    for verdict, value in ((labelled.moving, MOVING), (labelled.uncertain, UNCERTAIN)):
        _paint(mask, labelled.power_db, labelled.floor_db, points.range_bin[verdict], points.doppler_bin[verdict], value, params)
    return mask


def label_mask(
    cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses, boxes_ego_at_cube_time: LabelBoxes,
    params: MaskParams | None = None,
) -> np.ndarray:
    """The manual-label target of one cube, of the kind :attr:`MaskParams.manual_targets` names.

    Parameters
    ----------
    cube : numpy.ndarray
        ``[R, D, A]`` complex cube.
    timestamp_ns : int
        The cube's timestamp.
    calibration
        The radar's calibration record.
    poses : EgoPoses
        The scene's ego poses (the radar's own velocity for the radial velocities).
    boxes_ego_at_cube_time : LabelBoxes
        Labelled cars in the ego frame at the cube's time (:meth:`LabelBoxes.moved_to`).
    params : MaskParams, optional

    Returns
    -------
    numpy.ndarray
        ``[R, D]`` uint8 of the classes of :mod:`zendar_baselines.labels.mask_classes`.
    """
    params = MaskParams() if params is None else params
    make = box_label_mask if params.manual_targets == "boxes" else cfar_peak_label_mask
    return make(cube, timestamp_ns, calibration, poses, boxes_ego_at_cube_time, params)


def box_label_mask(
    cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses, boxes_ego_at_cube_time: LabelBoxes,
    params: MaskParams | None = None,
) -> np.ndarray:
    """The box target of one cube: the labelled boxes projected into the map (module docstring).

    Parameters and return value as :func:`label_mask`.
    """
    params = MaskParams() if params is None else params
    _cells, power_db, floor_db = _power_db_and_floor(cube, params)
    mask = np.full(power_db.shape, BACKGROUND, MASK_DTYPE)
    if len(boxes_ego_at_cube_time) == 0:
        return mask
    footprints = box_footprints(boxes_ego_at_cube_time, calibration, poses, timestamp_ns, *power_db.shape)
    car = _grown(footprints.in_fov.any(axis=0), LOBE_BINS)
    mask[_grown(car | footprints.outside_fov.any(axis=0), ERROR_BINS)] = UNCERTAIN
    mask[car & (power_db > floor_db + params.floor_margin_db)] = MOVING
    return mask


def _grown(cells: np.ndarray, bins: int) -> np.ndarray:
    """``[R, D]`` bool: ``cells`` grown by ``bins`` in range and Doppler (square; the Doppler axis wraps)."""
    return scipy.ndimage.maximum_filter(cells, size=2 * bins + 1, mode=["nearest", "wrap"])


def cfar_peaks_on_boxes(
    cube: np.ndarray, cells: RadarCells, timestamp_ns: int, calibration, poses: EgoPoses,
    boxes_ego_at_cube_time: LabelBoxes, params: MaskParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Which of a cube's CFAR peaks lie on the labelled cars: the seeds of the CFAR-gated target.

    Parameters
    ----------
    cells : RadarCells
        The cube's CFAR peaks, ``[N]`` (:func:`~zendar_dataset.detection.cfar_map` with ``params.chain``).

    The others as :func:`label_mask`.

    Returns
    -------
    on_car : numpy.ndarray
        ``[N]`` bool: the peak's point lies inside a box grown by :attr:`MaskParams.box_margin_m`
        and its radial velocity over the ground is that box's car's within
        :attr:`MaskParams.max_velocity_error_mps` (Doppler compared modulo its span).
    near_car : numpy.ndarray
        ``[N]`` bool: not ``on_car`` but within :attr:`MaskParams.near_margin_m` of a box.
    """
    params = MaskParams() if params is None else params
    boxes = boxes_ego_at_cube_time
    if len(cells) == 0 or len(boxes) == 0:
        return np.zeros(len(cells), bool), np.zeros(len(cells), bool)
    points_ego, residual_mps = locate_cells(cube, cells.range_bin, cells.doppler_bin, timestamp_ns, calibration, poses)
    inside = boxes.contains(points_ego[:, :2], params.box_margin_m)  # [P, B]
    near = boxes.contains(points_ego[:, :2], params.near_margin_m).any(axis=1)
    # The radial velocity over the ground a point on box b shows: line of sight . the car's velocity.
    line_of_sight = points_ego[:, :2] - np.asarray(ego_T_sensor(calibration).translation)[:2]
    line_of_sight /= np.maximum(np.linalg.norm(line_of_sight, axis=1, keepdims=True), 1e-9)
    expected_mps = line_of_sight @ np.stack([boxes.vx, boxes.vy])  # [P, B]
    fmcw = FmcwParams.from_calibration(calibration, n_samples=cube.shape[0], n_chirps=cube.shape[1])
    span_mps = cube.shape[1] * fmcw.doppler_bin_mps  # Doppler is ambiguous modulo D bins
    error_mps = np.abs((residual_mps[:, None] - expected_mps + span_mps / 2) % span_mps - span_mps / 2)
    on_car = (inside & (error_mps <= params.max_velocity_error_mps)).any(axis=1)
    return on_car, near & ~on_car


def cfar_peak_label_mask(
    cube: np.ndarray, timestamp_ns: int, calibration, poses: EgoPoses, boxes_ego_at_cube_time: LabelBoxes,
    params: MaskParams | None = None,
) -> np.ndarray:
    """The CFAR-gated target of one cube: the CFAR peaks on the cars, grown (module docstring).

    Parameters and return value as :func:`label_mask`.
    """
    params = MaskParams() if params is None else params
    cells, power_db, floor_db = _power_db_and_floor(cube, params)
    mask = np.full(power_db.shape, BACKGROUND, MASK_DTYPE)
    on_car, near_car = cfar_peaks_on_boxes(cube, cells, timestamp_ns, calibration, poses, boxes_ego_at_cube_time, params)
    _paint(mask, power_db, floor_db, cells.range_bin[near_car], cells.doppler_bin[near_car], UNCERTAIN, params)
    _paint(mask, power_db, floor_db, cells.range_bin[on_car], cells.doppler_bin[on_car], MOVING, params)
    return mask


def cubes_with_boxes(reader: SceneReader, radar: str, labels: dict[str, np.ndarray],
                     poses: EgoPoses) -> Iterator[tuple[int, np.ndarray, LabelBoxes]]:
    """Each cube of one radar, in time order: ``(timestamp_ns, cube [R, D, A], boxes)``, the boxes those
    of the label frame nearest the cube's time moved to it (ego poses and each car's velocity)."""
    frames_ns = frame_timestamps(reader)
    cubes = reader.array(f"radar/{radar}/cube")
    for k, cube_ns in enumerate(reader.timestamps(f"radar/{radar}").tolist()):
        yield cube_ns, np.asarray(cubes[k]), LabelBoxes.of_frame(labels, nearest_label_frame(frames_ns, cube_ns)).moved_to(cube_ns, poses)


def scene_masks(
    reader: SceneReader, radar: str, kind: str = "auto", sar: SarFrames | None = None, params: MaskParams | None = None,
    progress: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Masks of every cube of one radar of one scene.

    Parameters
    ----------
    reader : SceneReader
        The scene.
    radar : str
        A radar of the scene.
    kind : {"auto", "labels"}
        Automatic labels (SAR test) or the manual labels' target (of the kind
        ``params.manual_targets``). For ``"labels"`` each cube takes the boxes of the label frame
        nearest its time, moved to that time (ego poses and each car's velocity).
    sar : SarFrames, optional
        The scene's SAR images when already built (``"auto"``).
    params : MaskParams, optional
    progress : bool
        Show a progress bar over the cubes.

    Returns
    -------
    timestamp_ns : numpy.ndarray
        ``[N]`` int64 the cubes' timestamps.
    masks : numpy.ndarray
        ``[N, R, D]`` uint8.

    Raises
    ------
    ZendarError
        For an unknown kind or radar, or ``"labels"`` on a scene without labels.
    """
    if kind not in KINDS:
        raise ZendarError(f"scene_masks: kind must be one of {KINDS}, got {kind!r}")
    radars = reader.sensors("radar")
    if radar not in radars:
        raise ZendarError(f"{reader.scene_id}: no radar {radar!r}; the scene's radars are {radars}")
    params = MaskParams() if params is None else params
    labels = None
    if kind == "labels":
        labels = reader.labels()
        if labels is None:
            raise ZendarError(f"{reader.scene_id}: has no labels (withheld), so it has no manual-label masks")
        frames_ns = frame_timestamps(reader)
    elif sar is None:
        sar = SarFrames(reader)
    poses = reader.ego_poses()
    calibration = reader.calibration.sensors[radar]
    timestamps = reader.timestamps(f"radar/{radar}")
    cubes = reader.array(f"radar/{radar}/cube")
    masks = np.full((timestamps.size, *cubes.shape[1:3]), BACKGROUND, MASK_DTYPE)
    for k in tqdm(range(timestamps.size), desc=f"{reader.scene_id} {radar} {kind} masks", unit="cube", disable=not progress):
        cube = np.asarray(cubes[k])
        cube_ns = int(timestamps[k])
        if labels is None:
            masks[k] = auto_label_mask(cube, cube_ns, calibration, poses, sar, params)
        else:
            boxes = LabelBoxes.of_frame(labels, nearest_label_frame(frames_ns, cube_ns)).moved_to(cube_ns, poses)
            masks[k] = label_mask(cube, cube_ns, calibration, poses, boxes, params)
    return timestamps.astype(np.int64), masks
