"""The detection chain's two measured numbers, fitted on a split's labels (the training split; never test).

    zendar-bench fit-chain ROOT [--split train] [--sweep]
    python -m zendar_baselines.classical.chain_fit ROOT [--split train] [--sweep]   (the same)

1. The SAR test's threshold (:attr:`zendar_dataset.detection.SarTestParams.threshold_db`): the
   test classifies points, so its threshold is the one that best finds the CFAR points inside
   labelled boxes among the others by the SAR value: the largest F1 score (harmonic mean of the
   precision and recall of the points it calls dynamic), rounded to 0.5 dB. The automatic labels are
   judged by exactly that precision and recall. Youden's J (true-positive minus false-positive
   rate), the criterion before, is reported too: it ignores that other points outnumber on-car ones
   about ten to one and so accepts many false moving points (docs/baselines.md). A threshold tuned
   for the detector's AP instead would be a different method (``--sweep`` reports the chain's AP
   over a grid of thresholds, for reference).
2. The centre offset (:attr:`zendar_dataset.detection.ChainParams.centre_offset_m`): the
   radar sees a car's near face, so a cluster's centre falls short of the labelled centre along the
   line of sight. The offset is the median, over clusters whose uncorrected centre lies within
   :data:`OFFSET_MATCH_RADIUS_M` of a label, of the label centre's distance beyond the cluster
   centre along the line of sight from the radars.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from sklearn.metrics import precision_recall_curve, roc_auc_score, roc_curve
from tqdm import tqdm

from zendar_dataset.detection import (
    ON_CAR_MARGIN_M,
    ChainParams,
    FramePoints,
    LabelBoxes,
    cfar_cells,
    frame_clusters,
    frame_cube_points,
    frame_detections,
    to_frame,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate_record
from zendar_dataset.eval.protocol import BANDS_M, RANGE_BANDS
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import open_dataset

# A cluster counts towards the offset when a label lies this close to its uncorrected centre: a car
# length, so that clusters short by half a car's depth (and the lag of a cube up to 0.1 s older than
# the frame) are not cut off, while neighbouring cars (lanes 3.5 m apart) rarely are taken.
OFFSET_MATCH_RADIUS_M = 4.0
# The SAR values of CFAR points on the demo's training split span about -25 to 65 dB (1st to 99th percentile).
THRESHOLD_GRID_DB = np.arange(-40.0, 70.0 + 0.5, 1.0)


@dataclass
class LabelledFrames:
    """A split's frames with the chain's points and the labels.

    Attributes
    ----------
    points : dict of str to FramePoints
        Frame id -> every radar's CFAR points in the frame's ego frame.
    labels : dict of str to numpy.ndarray
        Frame id -> ``[B, 2]`` labelled centres, metres, same frame.
    sar_db : numpy.ndarray
        ``[P]`` SAR value of every CFAR point (NaN outside every image).
    on_car : numpy.ndarray
        ``[P]`` bool: the point lies inside a labelled box (moved to the cube's time) grown by
        :data:`zendar_dataset.detection.boxes.ON_CAR_MARGIN_M`.
    range_m : numpy.ndarray
        ``[P]`` float64 the point's distance from the ego origin in its frame's ego frame, metres
        (the evaluator's range, which decides its band).
    """

    points: dict[str, FramePoints]
    labels: dict[str, np.ndarray]
    sar_db: np.ndarray
    on_car: np.ndarray
    range_m: np.ndarray


def labelled_frames(root: str | os.PathLike, split: str, params: ChainParams | None = None, progress: bool = True) -> LabelledFrames:
    """Run the chain up to the SAR values on every labelled frame of ``split``.

    Raises
    ------
    ZendarError
        When the split has no labelled scene.
    """
    params = ChainParams() if params is None else params
    index = open_dataset(root)
    points: dict[str, FramePoints] = {}
    labels_xy: dict[str, np.ndarray] = {}
    sar_db, on_car, range_m = [], [], []
    scene_ids = index.scene_ids(split)
    for scene_id in tqdm(scene_ids, desc=f"chain_fit {split}", unit="scene", disable=not progress):
        with index.open_scene(scene_id) as reader:
            labels = reader.labels()
            if labels is None:
                continue
            poses = reader.ego_poses()
            for frame_ns, found in frame_cube_points(reader, lambda radar, k, cube: cfar_cells(cube, params), params, poses=poses):
                boxes = LabelBoxes.of_frame(labels, frame_ns)
                in_frame = [to_frame(cube, poses, frame_ns) for cube in found]
                for cube, moved in zip(found, in_frame):
                    at_cube = boxes.moved_to(cube.timestamp_ns, poses)
                    on_car.append(at_cube.contains(cube.points_ego[:, :2], ON_CAR_MARGIN_M).any(axis=1))
                    sar_db.append(cube.sar_db)
                    range_m.append(np.hypot(moved.points_xy[:, 0], moved.points_xy[:, 1]))
                fid = frame_id(scene_id, frame_ns)
                points[fid] = FramePoints.concatenate(in_frame)
                labels_xy[fid] = np.stack([boxes.x, boxes.y], axis=1)
    if not labels_xy:
        raise ZendarError(f"{root}: split {split!r} has no labelled scene to fit the detection chain on")
    return LabelledFrames(points, labels_xy, np.concatenate(sar_db), np.concatenate(on_car), np.concatenate(range_m))


def centre_offset_m(frames: LabelledFrames, params: ChainParams) -> float | None:
    """The median along-line-of-sight distance from cluster centres to nearby labels (module docstring).

    None when no cluster has a label within :data:`OFFSET_MATCH_RADIUS_M`.
    """
    offsets = []
    for fid, points in frames.points.items():
        labels = frames.labels[fid]
        if labels.shape[0] == 0:
            continue
        for cluster in frame_clusters(points.retested(params.sar), params):
            distance = np.hypot(*(labels - cluster.centre_xy).T)
            nearest = int(np.argmin(distance))
            line_of_sight = cluster.centre_xy - cluster.radar_xy
            norm = float(np.hypot(*line_of_sight))
            if distance[nearest] < OFFSET_MATCH_RADIUS_M and norm > 0:
                offsets.append(float((labels[nearest] - cluster.centre_xy) @ line_of_sight / norm))
    return float(np.median(offsets)) if offsets else None


def chain_ap(frames: LabelledFrames, params: ChainParams) -> dict[str, float | None]:
    """AP per band of the chain's detections on the frames, under the official evaluator."""
    results = {fid: frame_detections(points.retested(params.sar), params) for fid, points in frames.points.items()}
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
    """How well the SAR value separates on-car from other CFAR points, overall and per range band.

    Returns
    -------
    dict
        ``auc``: ROC AUC over every point with a SAR value (low values say "on a car");
        ``f1_threshold_db``: the value whose "dynamic below it" has the largest F1 score on the
        on-car points (the fitted threshold); ``youden_threshold_db``: the value that maximises the
        true-positive minus false-positive rate; ``auc_per_band``: band name
        (:data:`zendar_dataset.eval.protocol.RANGE_BANDS`) ->
        the AUC of the points in that band of the evaluator's range (``frames.range_m``);
        ``points_per_band``: band -> ``{"on_car", "other"}`` counts of points with a SAR value.
        An AUC or threshold is None where a set lacks on-car or other points.
    """
    finite = np.isfinite(frames.sar_db)
    auc_per_band, points_per_band = {}, {}
    for band in RANGE_BANDS:
        low, high = BANDS_M[band]
        in_band = (frames.range_m >= low) & (frames.range_m < high)
        auc_per_band[band] = separation_auc(frames.on_car[in_band], frames.sar_db[in_band])
        points_per_band[band] = {
            "on_car": int(np.count_nonzero(in_band & finite & frames.on_car)),
            "other": int(np.count_nonzero(in_band & finite & ~frames.on_car)),
        }
    auc = separation_auc(frames.on_car, frames.sar_db)
    youden = f1 = None
    if auc is not None:
        fpr, tpr, thresholds = roc_curve(frames.on_car[finite], -frames.sar_db[finite])
        youden = float(-thresholds[int(np.argmax(tpr - fpr))])
        precision, recall, cuts = precision_recall_curve(frames.on_car[finite], -frames.sar_db[finite])
        score = 2.0 * precision[:-1] * recall[:-1] / np.maximum(precision[:-1] + recall[:-1], np.finfo(float).tiny)
        f1 = float(-cuts[int(np.argmax(score))])
    return {
        "auc": auc, "f1_threshold_db": f1, "youden_threshold_db": youden, "auc_per_band": auc_per_band,
        "points_per_band": points_per_band,
    }


def fit_chain_params(
    root: str | os.PathLike, split: str = "train", base: ChainParams | None = None, progress: bool = True,
    sweep: bool = False,
) -> tuple[ChainParams, dict[str, Any]]:
    """Fit the SAR threshold and the centre offset on ``split`` (module docstring).

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
        ``base`` with the fitted ``sar.threshold_db`` and ``centre_offset_m``.
    summary : dict
        The fit's figures: counts, the point separation (ROC AUC overall and per band, F1 and
        Youden thresholds, :func:`point_separation`), the chosen
        values with the chain's AP on the split, and the sweep when asked.

    Raises
    ------
    ZendarError
        For the test split, a split without labels, or labels that leave no threshold to fit.
    """
    if split == "test":
        raise ZendarError(f"{root}: the detection chain is fitted on training labels, never on split 'test'")
    base = ChainParams() if base is None else base
    frames = labelled_frames(root, split, base, progress)
    separation = point_separation(frames)
    if separation["f1_threshold_db"] is None:
        raise ZendarError(f"{root}: split {split!r} needs CFAR points both on and off labelled cars to fit the SAR threshold")
    sar = replace(base.sar, threshold_db=round(2.0 * separation["f1_threshold_db"]) / 2.0)
    offset = centre_offset_m(frames, replace(base, sar=sar, centre_offset_m=0.0))
    params = replace(base, sar=sar, centre_offset_m=0.0 if offset is None else round(offset, 2))
    summary: dict[str, Any] = {
        "root": str(root), "split": split, "frames": len(frames.points), "cfar_points": int(frames.sar_db.size),
        "on_car_points": int(frames.on_car.sum()), "outside_sar": int(np.count_nonzero(~np.isfinite(frames.sar_db))),
        "point_separation": separation, "threshold_db": params.sar.threshold_db, "centre_offset_m": params.centre_offset_m,
        "ap": chain_ap(frames, params),
    }
    if sweep:
        summary["sweep"] = []
        for threshold_db in THRESHOLD_GRID_DB.tolist():
            trial = replace(base, sar=replace(base.sar, threshold_db=threshold_db), centre_offset_m=0.0)
            trial_offset = centre_offset_m(frames, trial)
            trial = replace(trial, centre_offset_m=0.0 if trial_offset is None else round(trial_offset, 2))
            summary["sweep"].append({"threshold_db": threshold_db, "centre_offset_m": trial.centre_offset_m, "ap": chain_ap(frames, trial)})
    return params, summary


def main(argv: list[str] | None = None) -> int:
    """``python -m zendar_baselines.classical.chain_fit ROOT ...``: ``zendar-bench fit-chain ROOT ...``."""
    from zendar_baselines.bench.cli import main as zendar_bench_main

    return zendar_bench_main(["fit-chain", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(main())
