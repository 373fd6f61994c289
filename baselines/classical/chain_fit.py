"""The detection chain's measured constants, fitted on labels a run may use (never the test split).

    zendar-bench fit-chain ROOT [--split train] [--sweep]
    python -m zendar_baselines.classical.chain_fit ROOT [--split train] [--sweep]   (the same)

``zendar-bench`` fits them in a cached step of every run, per detector: the CFAR row on CFAR peaks,
each CNN row's seed on that model's own probability peaks (different points: a CNN's peaks are not
CFAR's), on the labelled part of the training split only (:mod:`zendar_baselines.bench.chain_step`).
The constants, fitted on the points of the fitting scenes' labelled frames:

1. The SAR test's threshold (:attr:`zendar_dataset.detection.SarTestParams.threshold_db`): the
   test classifies points, so its threshold is the one that best finds the points inside labelled
   boxes among the others by the SAR value: the largest F1 score (harmonic mean of the precision
   and recall of the points it calls dynamic), rounded to 0.5 dB. The automatic labels are judged
   by exactly that precision and recall. Youden's J (true-positive minus false-positive rate) is
   reported too: it ignores that other points outnumber on-car ones about ten to one and so
   accepts many false moving points (docs/baselines.md). A threshold tuned for the detector's AP
   instead would be a different method (``--sweep`` reports the chain's AP over a grid of
   thresholds, for reference). When no threshold does better than chance (Youden's J <= 0:
   on-car points no darker than the others), the fit stops with a ZendarError.
2. The cluster radius (:attr:`zendar_dataset.detection.ChainParams.cluster_eps_m`): the radius of
   :data:`CLUSTER_EPS_GRID_M` whose chain AP (all bands) on the fitting frames is highest, the
   smaller on a tie. No point-level statistic says how far apart one car's points may lie and two
   cars' must, so the radius is chosen by the detections it gives; the grid is short and coarse
   (about half a car length, give or take a metre), so that a few cars cannot tune it finely.
3. The centre offset (:attr:`zendar_dataset.detection.ChainParams.centre_offset_m`), for each radius:
   the radar sees a car's near face, so a cluster's centre falls short of the labelled centre along
   the line of sight. The offset is the median, over clusters whose uncorrected centre lies within
   :data:`OFFSET_MATCH_RADIUS_M` of a label, of the label centre's distance beyond the cluster
   centre along the line of sight from the radars.

The fit is checked on other labelled frames: the validation split's, or, for a dataset without
labelled validation scenes, the last :data:`HELD_OUT_SHARE` of each fitting scene's labelled frames,
held out of the fit (a warning says so, and the summary's ``check.source``). The check reports the
SAR value's ROC AUC on its points and the chain's AP with the fitted constants.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from sklearn.metrics import precision_recall_curve, roc_auc_score, roc_curve
from tqdm import tqdm

from zendar_dataset.detection import (
    ON_CAR_MARGIN_M,
    ChainParams,
    FramePoints,
    LabelBoxes,
    cfar_cells,
    cluster_labels,
    frame_clusters,
    frame_cube_points,
    frame_detections,
    to_frame,
)
from zendar_dataset.detection.scene import CellsOf
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate_record
from zendar_dataset.eval.protocol import BANDS_M, RANGE_BANDS
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import DatasetIndex, SceneReader, open_dataset

from zendar_baselines.classical.kept_scenes import KeptScenes
from zendar_baselines.labels.splits import SemiSupervisedSplit

if TYPE_CHECKING:  # the ranks sharing a loop are the bench's (torchrun); only their two methods are used here
    from zendar_baselines.bench.ranks import SceneShard

# A cluster counts towards the offset when a label lies this close to its uncorrected centre: a car
# length, so that clusters short by half a car's depth (and the lag of a cube up to 0.1 s older than
# the frame) are not cut off, while neighbouring cars (lanes 3.5 m apart) rarely are taken.
OFFSET_MATCH_RADIUS_M = 4.0
# The SAR values of CFAR points on the demo's training split span about -25 to 65 dB (1st to 99th percentile).
THRESHOLD_GRID_DB = np.arange(-40.0, 70.0 + 0.5, 1.0)
#: SAR thresholds tried (dB) when the threshold is chosen by the detections (``threshold_by="detections"``):
#: the span of the values of CFAR and CNN points on the demo config (about -25 to 65 dB) and beyond,
#: where the test lets every point with a SAR reading through.
DETECTION_THRESHOLD_GRID_DB = np.arange(-20.0, 100.0 + 0.5, 4.0)
#: How the SAR threshold is chosen (:func:`fit_on_frames`).
THRESHOLD_CRITERIA = ("points", "detections")
#: DBSCAN radii tried (metres), around :data:`zendar_dataset.detection.CLUSTER_EPS_M`.
CLUSTER_EPS_GRID_M = (1.0, 1.5, 2.0, 2.5, 3.0)
#: Without labelled validation scenes, this share of each fitting scene's labelled frames (its last
#: ones: a time segment, so that the check's frames are not the fit's neighbours) checks the fit.
HELD_OUT_SHARE = 0.25
#: The split whose scenes the chain is never fitted on, nor checked on.
GUARDED_SPLIT = "test"

#: For an open scene, the cells of each of its cubes: ``cells_for(reader)(radar, cube_index, cube)``.
CellsFor = Callable[[SceneReader], CellsOf]


def cfar_cells_for(params: ChainParams) -> CellsFor:
    """The CFAR baseline's cells (CA-CFAR peaks) for any scene."""
    return lambda reader: (lambda radar, k, cube: cfar_cells(cube, params))


@dataclass
class LabelledFrames:
    """Labelled frames with the chain's points and the labels, keyed by frame id.

    Attributes
    ----------
    points : dict of str to FramePoints
        Every radar's points in the frame's ego frame (their SAR values in ``sar_db``).
    labels : dict of str to numpy.ndarray
        ``[B, 2]`` labelled centres, metres, same frame.
    on_car : dict of str to numpy.ndarray
        ``[P]`` bool per point of ``points``: it lies inside a labelled box (moved to its cube's
        time) grown by :data:`zendar_dataset.detection.boxes.ON_CAR_MARGIN_M`.
    range_m : dict of str to numpy.ndarray
        ``[P]`` float64 per point of ``points``: its distance from the ego origin in the frame's ego
        frame, metres (the evaluator's range, which decides its band).
    scene_frames : dict of str to list of str
        Scene id -> its frame ids, in time order.
    """

    points: dict[str, FramePoints]
    labels: dict[str, np.ndarray]
    on_car: dict[str, np.ndarray]
    range_m: dict[str, np.ndarray]
    scene_frames: dict[str, list[str]]

    @property
    def sar_db(self) -> np.ndarray:
        """``[P]`` float64 SAR value of every point of every frame (NaN outside every image)."""
        return np.concatenate([np.zeros(0)] + [points.sar_db for points in self.points.values()])

    @property
    def point_on_car(self) -> np.ndarray:
        """``[P]`` bool, aligned with :attr:`sar_db`."""
        return np.concatenate([np.zeros(0, bool)] + [self.on_car[fid] for fid in self.points])

    @property
    def labels_ahead_only(self) -> bool:
        """Every labelled centre of the frames lies ahead of the ego's front bumper (x > 0), and there
        is one: the labels cover that region only (the simulator's rule), so a detection elsewhere can
        match none (:attr:`zendar_dataset.detection.ChainParams.ahead_only`)."""
        centres = np.concatenate([np.zeros((0, 2))] + [np.asarray(labels, np.float64).reshape(-1, 2) for labels in self.labels.values()])
        return bool(centres.shape[0] and np.all(centres[:, 0] > 0.0))

    @property
    def point_ahead(self) -> np.ndarray:
        """``[P]`` bool, aligned with :attr:`sar_db`: the point lies ahead of the ego's front bumper
        (x > 0 in its frame), where the labels cover every car."""
        return np.concatenate([np.zeros(0, bool)] + [points.points_xy[:, 0] > 0.0 for points in self.points.values()])

    @property
    def point_range_m(self) -> np.ndarray:
        """``[P]`` float64, aligned with :attr:`sar_db`."""
        return np.concatenate([np.zeros(0)] + [self.range_m[fid] for fid in self.points])

    def subset(self, frame_ids: list[str]) -> LabelledFrames:
        """The frames ``frame_ids`` only."""
        keep = set(frame_ids)
        return LabelledFrames(
            {fid: p for fid, p in self.points.items() if fid in keep}, {fid: v for fid, v in self.labels.items() if fid in keep},
            {fid: v for fid, v in self.on_car.items() if fid in keep},
            {fid: v for fid, v in self.range_m.items() if fid in keep},
            {scene: [fid for fid in fids if fid in keep] for scene, fids in self.scene_frames.items() if keep.intersection(fids)},
        )

    @classmethod
    def merged(cls, parts: list[LabelledFrames]) -> LabelledFrames:
        """The frames of ``parts`` (of different scenes) in one, in the parts' order."""
        out = cls({}, {}, {}, {}, {})
        for part in parts:
            for mine, theirs in ((out.points, part.points), (out.labels, part.labels), (out.on_car, part.on_car),
                                 (out.range_m, part.range_m), (out.scene_frames, part.scene_frames)):
                mine.update(theirs)
        return out

    def held_out(self, share: float = HELD_OUT_SHARE) -> tuple[LabelledFrames, LabelledFrames]:
        """``(fit, check)``: the last ``share`` of each scene's frames (at least one) held out, when
        the scene has two frames or more."""
        fit, check = [], []
        for fids in self.scene_frames.values():
            n_check = min(max(math.ceil(share * len(fids)), 1), len(fids) - 1)
            fit += fids[: len(fids) - n_check]
            check += fids[len(fids) - n_check :]
        return self.subset(fit), self.subset(check)


def labelled_frames(index: DatasetIndex, scene_ids: list[str], cells_for: CellsFor, params: ChainParams | None = None,
                    progress: bool = True, description: str = "chain_fit",
                    split: SemiSupervisedSplit | None = None, shard: SceneShard | None = None,
                    scenes: KeptScenes | None = None) -> LabelledFrames:
    """Run the chain up to the SAR values on every labelled frame of ``scene_ids`` (scenes without
    labels are skipped), with the cells ``cells_for`` gives (:func:`cfar_cells_for`, or a CNN's peaks).

    With ``split``, only the frames in its labelled segments are taken, their labels read through
    :meth:`~zendar_baselines.labels.splits.SemiSupervisedSplit.labelled_view` (the split's guard: no
    manual label outside the labelled segments is read). With ``shard`` (torchrun's ranks sharing the
    loop), this process reads its share of the scenes and every rank's frames are gathered: every rank
    returns the frames one process would, in the same order. With ``scenes`` (of ``index``'s dataset),
    the scenes are taken from those kept open for many passes (:class:`KeptScenes`); by default each
    is opened for this call only. The frames do not depend on it.
    """
    params = ChainParams() if params is None else params
    if scenes is None:
        scenes = KeptScenes(index, [], keep=False)
    elif os.path.realpath(scenes.index.root) != os.path.realpath(index.root):
        raise ValueError(f"labelled_frames: scenes of {scenes.index.root} given for {index.root}")
    parts: dict[str, LabelledFrames] = {}
    mine = scene_ids if shard is None else shard.mine(scene_ids)
    for scene_id in tqdm(mine, desc=description, unit="scene", disable=not progress):
        with scenes.opened(scene_id) as scene:
            reader = scene.reader if split is None else split.labelled_view(scene.reader)
            labels = reader.labels()
            if labels is None:
                continue
            poses = scene.poses
            frames = parts[scene_id] = LabelledFrames({}, {}, {}, {}, {})
            frames.scene_frames[scene_id] = []
            for frame_ns, found in frame_cube_points(reader, cells_for(reader), params, poses=poses, sar=scene.sar):
                if split is not None and not split.is_labelled(scene_id, np.array([frame_ns], np.int64))[0]:
                    continue
                boxes = LabelBoxes.of_frame(labels, frame_ns)
                fid = frame_id(scene_id, frame_ns)
                frames.on_car[fid] = np.concatenate([np.zeros(0, bool)] + [
                    boxes.moved_to(cube.timestamp_ns, poses).contains(cube.points_ego[:, :2], ON_CAR_MARGIN_M).any(axis=1)
                    for cube in found])
                frames.points[fid] = FramePoints.concatenate([to_frame(cube, poses, frame_ns) for cube in found])
                frames.range_m[fid] = np.hypot(frames.points[fid].points_xy[:, 0], frames.points[fid].points_xy[:, 1])
                frames.labels[fid] = np.stack([boxes.x, boxes.y], axis=1)
                frames.scene_frames[scene_id].append(fid)
    if shard is not None:
        parts = shard.gather(parts)
    return LabelledFrames.merged([parts[scene_id] for scene_id in scene_ids if scene_id in parts])


def centre_offset_m(frames: LabelledFrames, params: ChainParams,
                    cluster_ids: dict[str, np.ndarray] | None = None) -> float | None:
    """The median along-line-of-sight distance from cluster centres to nearby labels (module docstring).

    None when no cluster has a label within :data:`OFFSET_MATCH_RADIUS_M`. ``cluster_ids``: frame id ->
    its points' cluster labels at ``params.cluster_eps_m`` when already known (:func:`cluster_ids_of`).
    """
    cluster_ids = {} if cluster_ids is None else cluster_ids
    offsets = []
    for fid, points in frames.points.items():
        labels = frames.labels[fid]
        if labels.shape[0] == 0:
            continue
        for cluster in frame_clusters(points.retested(params.sar), params, cluster_ids.get(fid)):
            distance = np.hypot(*(labels - cluster.centre_xy).T)
            nearest = int(np.argmin(distance))
            line_of_sight = cluster.centre_xy - cluster.radar_xy
            norm = float(np.hypot(*line_of_sight))
            if distance[nearest] < OFFSET_MATCH_RADIUS_M and norm > 0:
                offsets.append(float((labels[nearest] - cluster.centre_xy) @ line_of_sight / norm))
    return float(np.median(offsets)) if offsets else None


def cluster_ids_of(frames: LabelledFrames, eps_m: float) -> dict[str, np.ndarray]:
    """Frame id -> ``[P]`` int cluster label of each of its points at radius ``eps_m``
    (:func:`zendar_dataset.detection.cluster_labels`): independent of the SAR test, so a fit trying
    many thresholds clusters every frame once per radius."""
    return {fid: cluster_labels(points.points_xy, eps_m) for fid, points in frames.points.items()}


def chain_ap(frames: LabelledFrames, params: ChainParams,
             cluster_ids: dict[str, np.ndarray] | None = None) -> dict[str, float | None]:
    """AP per band of the chain's detections on the frames, under the official evaluator
    (``cluster_ids`` as :func:`centre_offset_m`)."""
    cluster_ids = {} if cluster_ids is None else cluster_ids
    results = {fid: frame_detections(points.retested(params.sar), params, cluster_ids.get(fid))
               for fid, points in frames.points.items()}
    truth = {fid: [{"x": float(x), "y": float(y)} for x, y in labels] for fid, labels in frames.labels.items()}
    return dict(evaluate_record({"meta": {"method": "chain_fit"}, "results": results}, {"frames": truth}).ap)


def separation_auc(on_car: np.ndarray, sar_db: np.ndarray) -> float | None:
    """ROC AUC of a low SAR value for on-car points against the others; NaN values left out.

    Parameters
    ----------
    on_car : numpy.ndarray
        ``[P]`` bool.
    sar_db : numpy.ndarray
        ``[P]`` float64 SAR values, dB.

    Returns
    -------
    float or None
        None when the finite values are all on cars or all off them.
    """
    keep = np.isfinite(sar_db)
    truth = np.asarray(on_car, bool)[keep]
    if truth.all() or not truth.any():
        return None
    return float(roc_auc_score(truth, -np.asarray(sar_db, np.float64)[keep]))


def point_separation(frames: LabelledFrames) -> dict[str, Any]:
    """How well the SAR value separates the points on labelled cars from the others (:func:`separation_of`),
    over the points in the labels' region: with labels only ahead of the ego's front bumper
    (:attr:`LabelledFrames.labels_ahead_only`), only the points there (x > 0 in the frame), as a car
    beside the ego is then never labelled and its points are no "others"."""
    if not frames.labels_ahead_only:
        return separation_of(frames.point_on_car, frames.sar_db, frames.point_range_m)
    ahead = frames.point_ahead
    return separation_of(frames.point_on_car[ahead], frames.sar_db[ahead], frames.point_range_m[ahead])


def separation_of(on_car: np.ndarray, sar_db: np.ndarray, range_m: np.ndarray) -> dict[str, Any]:
    """How well the SAR value separates on-car from other points, overall and per range band.

    Parameters
    ----------
    on_car : numpy.ndarray
        ``[P]`` bool: the point lies on a labelled car.
    sar_db : numpy.ndarray
        ``[P]`` float64 SAR values, dB (NaN: no image).
    range_m : numpy.ndarray
        ``[P]`` float64 the evaluator's range of each point, metres.

    Returns
    -------
    dict
        ``auc``: ROC AUC over every point with a SAR value (low values say "on a car");
        ``f1_threshold_db``: the value whose "dynamic below it" has the largest F1 score on the
        on-car points (the fitted threshold); ``youden_threshold_db`` and ``youden_j``: the value
        that maximises the true-positive minus false-positive rate, and that rate;
        ``auc_per_band``: band name (:data:`zendar_dataset.eval.protocol.RANGE_BANDS`) -> the AUC
        of the points in that band; ``points_per_band``: band -> ``{"on_car", "other"}`` counts
        of points with a SAR value. An AUC or threshold is None where a set lacks on-car or other
        points.
    """
    on_car = np.asarray(on_car, bool)
    sar_db = np.asarray(sar_db, np.float64)
    range_m = np.asarray(range_m, np.float64)
    finite = np.isfinite(sar_db)
    auc_per_band, points_per_band = {}, {}
    for band in RANGE_BANDS:
        low, high = BANDS_M[band]
        in_band = (range_m >= low) & (range_m < high)
        auc_per_band[band] = separation_auc(on_car[in_band], sar_db[in_band])
        points_per_band[band] = {
            "on_car": int(np.count_nonzero(in_band & finite & on_car)),
            "other": int(np.count_nonzero(in_band & finite & ~on_car)),
        }
    auc = separation_auc(on_car, sar_db)
    youden = youden_j = f1 = None
    if auc is not None:
        truth, value = on_car[finite], sar_db[finite]
        fpr, tpr, thresholds = roc_curve(truth, -value)
        best = int(np.argmax(tpr - fpr))
        youden, youden_j = float(-thresholds[best]), float(tpr[best] - fpr[best])
        precision, recall, cuts = precision_recall_curve(truth, -value)
        score = 2.0 * precision[:-1] * recall[:-1] / np.maximum(precision[:-1] + recall[:-1], np.finfo(float).tiny)
        f1 = float(-cuts[int(np.argmax(score))])
    return {
        "auc": auc, "f1_threshold_db": f1, "youden_threshold_db": youden, "youden_j": youden_j,
        "auc_per_band": auc_per_band, "points_per_band": points_per_band,
    }


def _offset_for(frames: LabelledFrames, params: ChainParams,
                cluster_ids: dict[str, np.ndarray] | None = None) -> ChainParams:
    offset = centre_offset_m(frames, replace(params, centre_offset_m=0.0), cluster_ids)
    return replace(params, centre_offset_m=0.0 if offset is None else round(offset, 2))


def _counts(frames: LabelledFrames) -> dict[str, Any]:
    sar_db = frames.sar_db
    return {"scenes": list(frames.scene_frames), "frames": len(frames.points), "points": int(sar_db.size),
            "on_car_points": int(frames.point_on_car.sum()), "outside_sar": int(np.count_nonzero(~np.isfinite(sar_db)))}


def fit_chain(
    index: DatasetIndex, fit_scene_ids: list[str], check_scene_ids: list[str], cells_for: CellsFor,
    base: ChainParams | None = None, *, detector: str = "CFAR", progress: bool = True,
    split: SemiSupervisedSplit | None = None, threshold_by: str = "points", shard: SceneShard | None = None,
    scenes: KeptScenes | None = None,
) -> tuple[ChainParams, dict[str, Any]]:
    """Fit the SAR threshold, cluster radius and centre offset on one detector's points (module docstring).

    Parameters
    ----------
    index : DatasetIndex
        The dataset.
    fit_scene_ids : list of str
        Scenes whose labels fit the constants.
    check_scene_ids : list of str
        Scenes whose labels check the fit (the validation split); when none of them is labelled,
        the last :data:`HELD_OUT_SHARE` of each fitting scene's frames are held out to check it.
    cells_for : callable
        The detector's cells for a scene (:data:`CellsFor`).
    base : ChainParams, optional
        Everything else of the chain (``cluster_score``, ``cfar_pfa``, ...).
    detector : str
        Named in messages and the summary.
    progress : bool
        Show a progress bar over the scenes.
    split : SemiSupervisedSplit, optional
        When given, the fitting scenes' frames outside its labelled segments are left out and their
        labels never read (:func:`labelled_frames`); the check's scenes are read whole.
    threshold_by : {"points", "detections"}
        How the SAR threshold is chosen (:func:`fit_on_frames`).
    shard : SceneShard, optional
        torchrun's ranks sharing the scenes (:func:`labelled_frames`); every rank fits the same constants.
    scenes : KeptScenes, optional
        The scenes kept open for many passes (:func:`labelled_frames`); the fit does not depend on it.

    Returns
    -------
    params : ChainParams
        ``base`` with the fitted ``sar.threshold_db``, ``cluster_eps_m`` and ``centre_offset_m``, and
        ``ahead_only`` set when every label of ``frames`` lies ahead of the front bumper
        (:attr:`LabelledFrames.labels_ahead_only`).
    summary : dict
        ``detector``, the fitted values, ``fit`` (counts, the point separation, the radius grid's
        AP, the chain's AP on the fitting frames) and ``check`` (``source``: ``"val"`` or
        ``"held-out training frames"``, counts, the SAR value's ROC AUC and the chain's AP).

    Raises
    ------
    ZendarError
        For a scene of the test split, fitting scenes without labelled frames, or points that no SAR
        threshold separates better than chance.
    """
    test_scenes = set(index.scene_ids(GUARDED_SPLIT))
    guarded = sorted(test_scenes.intersection([*fit_scene_ids, *check_scene_ids]))
    if guarded:
        raise ZendarError(f"{index.root}: the detection chain is fitted on training labels, never on split "
                          f"{GUARDED_SPLIT!r} (scenes {guarded})")
    base = ChainParams() if base is None else base
    frames = labelled_frames(index, list(fit_scene_ids), cells_for, base, progress, f"chain fit ({detector})", split,
                             shard, scenes)
    if not frames.points:
        raise ZendarError(f"{index.root}: scenes {list(fit_scene_ids)} have no labelled frame to fit the detection chain on")
    check = labelled_frames(index, list(check_scene_ids), cells_for, base, progress, f"chain check ({detector})",
                            shard=shard, scenes=scenes)
    source = "val"
    if not check.points:
        source = "held-out training frames"
        frames, check = frames.held_out()
        print(f"warning: {index.root}: no labelled validation scene; the {detector} chain fit is checked on the last "
              f"{HELD_OUT_SHARE:.0%} of each fitting scene's frames, held out of the fit", file=sys.stderr, flush=True)
    params, fit = fit_on_frames(frames, base, detector, str(index.root), threshold_by)
    check_separation = point_separation(check)
    summary: dict[str, Any] = {
        "detector": detector, "threshold_db": params.sar.threshold_db, "cluster_eps_m": params.cluster_eps_m,
        "centre_offset_m": params.centre_offset_m, "cluster_score": params.cluster_score, "fit": fit,
        "check": {"source": source, **_counts(check), "auc": check_separation["auc"],
                  "auc_per_band": check_separation["auc_per_band"],
                  "ap": chain_ap(check, params) if check.points else None},
    }
    return params, summary


def fit_on_frames(frames: LabelledFrames, base: ChainParams, detector: str = "CFAR", where: str = "",
                  threshold_by: str = "points") -> tuple[ChainParams, dict[str, Any]]:
    """The constants fitted on ``frames`` (module docstring, steps 1 to 3) and the fit's figures.

    Parameters
    ----------
    threshold_by : {"points", "detections"}
        ``"points"``: the SAR threshold of the largest F1 score on the points (step 1), then the radius
        by the chain's AP. ``"detections"``: threshold and radius together, the pair of
        :data:`DETECTION_THRESHOLD_GRID_DB` x :data:`CLUSTER_EPS_GRID_M` (and the F1 threshold) whose
        chain AP (all bands) on ``frames`` is highest — for a CNN's peaks, which the model has
        already judged moving: among them the SAR value separates cars from the rest barely better
        than chance (ROC AUC about 0.5 on the demo config), so a point-level threshold lands anywhere,
        from one that passes every point to one that drops every car.

    Returns
    -------
    params : ChainParams
        ``base`` with the fitted ``sar.threshold_db``, ``cluster_eps_m`` and ``centre_offset_m``, and
        ``ahead_only`` set when every label of ``frames`` lies ahead of the front bumper
        (:attr:`LabelledFrames.labels_ahead_only`).
    fit : dict
        Counts, ``point_separation`` (:func:`separation_of`), ``threshold_by``, ``radius_grid`` (each
        radius with its offset and AP at the chosen threshold) and the chain's ``ap`` on ``frames``
        with ``params``.

    Raises
    ------
    ZendarError
        For ``"points"``, when no SAR threshold separates the points on labelled cars from the others
        better than chance (or every point, or none, is on a car); for ``"detections"``, when no
        pair finds a labelled car; ``where`` and ``detector`` name the data.
    """
    if threshold_by not in THRESHOLD_CRITERIA:
        raise ZendarError(f"fit_on_frames: threshold_by must be one of {THRESHOLD_CRITERIA}, got {threshold_by!r}")
    counts = _counts(frames)
    base = replace(base, ahead_only=frames.labels_ahead_only)  # the labels' region decides where detections count
    separation = point_separation(frames)
    if threshold_by == "points" and (separation["youden_j"] is None or separation["youden_j"] <= 0.0):
        raise ZendarError(
            f"{where}: no SAR threshold separates the {detector} points on labelled cars from the others "
            f"(scenes {counts['scenes']}: {counts['on_car_points']} of {counts['points']} points on cars, "
            f"ROC AUC {separation['auc']}); the SAR static-scene test cannot be fitted on these labels"
        )
    thresholds_db = [] if separation["f1_threshold_db"] is None else [round(2.0 * separation["f1_threshold_db"]) / 2.0]
    if threshold_by == "detections":
        thresholds_db += [t for t in DETECTION_THRESHOLD_GRID_DB.tolist() if t not in thresholds_db]
    grid = []
    cluster_ids = {eps_m: cluster_ids_of(frames, eps_m) for eps_m in CLUSTER_EPS_GRID_M}
    sar_db = frames.sar_db
    # Points are dynamic below the threshold, so the dynamic sets of two thresholds are nested: as
    # many dynamic points means the same points, the same offset and the same AP (computed once).
    done: dict[tuple[int, float], tuple[float, dict[str, float | None]]] = {}
    for threshold_db in thresholds_db:
        n_dynamic = int(np.count_nonzero(sar_db < threshold_db))
        for eps_m in CLUSTER_EPS_GRID_M:
            trial = replace(base, sar=replace(base.sar, threshold_db=threshold_db), cluster_eps_m=eps_m)
            if (n_dynamic, eps_m) not in done:
                fitted = _offset_for(frames, trial, cluster_ids[eps_m])
                done[n_dynamic, eps_m] = fitted.centre_offset_m, chain_ap(frames, fitted, cluster_ids[eps_m])
            offset_m, ap = done[n_dynamic, eps_m]
            grid.append((replace(trial, centre_offset_m=offset_m), ap))
    if not grid or max((-1.0 if a["all"] is None else a["all"]) for _, a in grid) <= 0.0:
        raise ZendarError(
            f"{where}: no SAR threshold and cluster radius let the {detector} chain find a labelled car "
            f"(scenes {counts['scenes']}: {counts['on_car_points']} of {counts['points']} points on cars); "
            "the chain cannot be fitted on these labels"
        )
    params, ap = max(grid, key=lambda entry: -1.0 if entry[1]["all"] is None else entry[1]["all"])  # first on a tie
    return params, {**counts, "point_separation": separation, "threshold_by": threshold_by, "ap": ap,
                    "radius_grid": [{"cluster_eps_m": t.cluster_eps_m, "centre_offset_m": t.centre_offset_m, "ap_all": a["all"]}
                                    for t, a in grid if t.sar.threshold_db == params.sar.threshold_db]}


def fit_chain_params(
    root: str | os.PathLike, split: str = "train", base: ChainParams | None = None, progress: bool = True,
    sweep: bool = False,
) -> tuple[ChainParams, dict[str, Any]]:
    """Fit the CFAR chain's constants on every scene of ``split``, checked on the validation split
    (``zendar-bench fit-chain``; :func:`fit_chain`).

    Parameters
    ----------
    root : str or path
        Dataset root.
    split : str
        The split whose labels are used; ``"test"`` is refused.
    base : ChainParams, optional
        Everything else of the chain.
    progress : bool
        Show a progress bar over the scenes.
    sweep : bool
        Also run the chain at every threshold of :data:`THRESHOLD_GRID_DB` (AP per band).

    Returns
    -------
    params : ChainParams
        ``base`` with the fitted constants.
    summary : dict
        :func:`fit_chain`'s, with ``root``, ``split`` and the fitting frames' counts at its top
        (``frames``, ``cfar_points``, ``on_car_points``, ``outside_sar``, ``point_separation``,
        ``ap``), and the sweep when asked.

    Raises
    ------
    ZendarError
        For the test split, a split without labels, or labels that leave no threshold to fit.
    """
    if split == GUARDED_SPLIT:
        raise ZendarError(f"{root}: the detection chain is fitted on training labels, never on split {GUARDED_SPLIT!r}")
    base = ChainParams() if base is None else base
    index = open_dataset(root)
    if not index.scene_ids(split):
        raise ZendarError(f"{root}: split {split!r} has no scenes to fit the detection chain on")
    check_ids = index.scene_ids("val") if split != "val" else []
    params, fitted = fit_chain(index, index.scene_ids(split), check_ids, cfar_cells_for(base), base, progress=progress)
    fit = fitted["fit"]
    summary: dict[str, Any] = {
        "root": str(root), "split": split, "frames": fit["frames"], "cfar_points": fit["points"],
        "on_car_points": fit["on_car_points"], "outside_sar": fit["outside_sar"], "point_separation": fit["point_separation"],
        "ap": fit["ap"], **fitted,
    }
    if sweep:
        frames = labelled_frames(index, fit["scenes"], cfar_cells_for(base), base, progress)
        summary["sweep"] = []
        for threshold_db in THRESHOLD_GRID_DB.tolist():
            trial = _offset_for(frames, replace(params, sar=replace(params.sar, threshold_db=threshold_db)))
            summary["sweep"].append({"threshold_db": threshold_db, "centre_offset_m": trial.centre_offset_m, "ap": chain_ap(frames, trial)})
    return params, summary


def main(argv: list[str] | None = None) -> int:
    """``python -m zendar_baselines.classical.chain_fit ROOT ...``: ``zendar-bench fit-chain ROOT ...``."""
    from zendar_baselines.bench.cli import main as zendar_bench_main

    return zendar_bench_main(["fit-chain", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
