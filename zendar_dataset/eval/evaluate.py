"""Score predictions against ground truth: validation, matching, banding, AP, bootstrap.

The returned dict is exactly what ``zendar-eval`` writes to ``metrics.json``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import PredictionsError, ZendarError
from zendar_dataset.eval.ap import PrecisionRecall, average_precision
from zendar_dataset.eval.bootstrap import BandDetections, bootstrap_intervals
from zendar_dataset.eval.matching import UNMATCHED, match_frames
from zendar_dataset.eval.protocol import (
    BANDS_M,
    DEFAULT_MAX_BYTES,
    MAX_PR_CURVE_POINTS,
    in_band,
    protocol_dict,
    range_m,
)
from zendar_dataset.eval.validation import (
    GROUND_TRUTH_REQUIRED,
    CheckedInput,
    DetectionTable,
    frame_set_problems,
    load_document,
    read_frames,
    read_ground_truth_document,
    read_predictions,
)

#: Splits tried, in order, when a dataset root is given without a split.
DEFAULT_SPLITS = ("test", "val")


def _ground_truth_from_dataset(root: Path, split: str | None) -> CheckedInput:
    # Imported here so that scoring JSON files never needs the storage backends.
    from zendar_dataset.format.ground_truth import ground_truth_frames

    candidates = [split] if split is not None else list(DEFAULT_SPLITS)
    reasons = []
    for candidate in candidates:
        try:
            frames = ground_truth_frames(root, candidate)
        except ZendarError as exc:
            reasons.append(f"split {candidate!r}: {exc}")
            continue
        # The default is the first split whose scenes carry labels.
        if split is None and not any(frames.values()):
            reasons.append(f"split {candidate!r} has no labelled objects")
            continue
        checked = read_frames(frames, who="ground truth", required=GROUND_TRUTH_REQUIRED)
        checked.split = candidate
        return checked
    return CheckedInput(
        None, None, [f"no ground truth found in dataset {str(root)!r}: " + "; ".join(reasons)]
    )


def load_ground_truth(
    source: Any, *, split: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES
) -> CheckedInput:
    """Ground truth from a dataset root, a ``{"frames": ...}`` file, or an already-loaded dict.

    Parameters
    ----------
    source
        A dataset root directory (labels of ``split``; by default ``test`` when its scenes carry
        labels, else ``val``), a path to a ground-truth JSON file, or the parsed dict.
    split
        Split to read from a dataset root; for a file, it must agree with the file's ``"split"``
        member when both are given.
    max_bytes
        Size limit of a ground-truth file.

    Returns
    -------
    CheckedInput
        With ``split`` set to the split used, when known.
    """
    if isinstance(source, (str, os.PathLike)) and Path(source).is_dir():
        return _ground_truth_from_dataset(Path(source), split)
    document, problems = load_document(source, what="ground truth", max_bytes=max_bytes)
    if problems:
        return CheckedInput(None, None, problems)
    checked = read_ground_truth_document(document)
    if split is not None and checked.split is not None and split != checked.split:
        checked.problems.append(
            f"ground truth file holds split {checked.split!r} but split {split!r} was asked for"
        )
        checked.table = None
    return checked


def _curve_json(curve: PrecisionRecall) -> dict[str, list[float]]:
    n = len(curve.score)
    keep = slice(None)
    if n > MAX_PR_CURVE_POINTS:
        keep = np.unique(np.linspace(0, n - 1, MAX_PR_CURVE_POINTS).round().astype(np.int64))
    return {
        "recall": curve.recall[keep].tolist(),
        "precision": curve.precision[keep].tolist(),
        "precision_envelope": curve.precision_envelope[keep].tolist(),
        "score": curve.score[keep].tolist(),
    }


def _restrict_ground_truth(
    ground_truth: DetectionTable, frame_ids: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground-truth rows of ``frame_ids`` (a subsequence of the ground truth's frames), with offsets."""
    position = {frame_id: i for i, frame_id in enumerate(frame_ids)}
    evaluated_index = np.array([position.get(f, -1) for f in ground_truth.frame_ids], dtype=np.int64)
    row_frame = evaluated_index[ground_truth.frame_of_row]
    keep = row_frame >= 0
    offsets = np.zeros(len(frame_ids) + 1, dtype=np.int64)
    np.cumsum(np.bincount(row_frame[keep], minlength=len(frame_ids)), out=offsets[1:])
    return ground_truth.x_m[keep], ground_truth.y_m[keep], offsets


def score_tables(
    predictions: DetectionTable,
    ground_truth: DetectionTable,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
) -> dict[str, Any]:
    """Score validated tables (every prediction frame is a ground-truth frame).

    Parameters
    ----------
    predictions, ground_truth
        Validated detection tables.
    partial
        Evaluate only the ground-truth frames present in the predictions.
    bootstrap
        Number of scene resamples for confidence intervals (0: none).
    seed
        Seed for the resampling.

    Returns
    -------
    dict
        ``ap``, ``counts``, ``pr_curves``, ``protocol``, ``partial``, ``n_frames``,
        ``n_frames_ground_truth``, ``n_scenes`` and, when asked, ``bootstrap``.
    """
    if partial:
        present = set(predictions.frame_ids)
        frame_ids = [f for f in ground_truth.frame_ids if f in present]
    else:
        frame_ids = list(ground_truth.frame_ids)
    gt_x_m, gt_y_m, gt_offsets = _restrict_ground_truth(ground_truth, frame_ids)
    position = {frame_id: i for i, frame_id in enumerate(frame_ids)}
    pred_frame_index = np.array([position[f] for f in predictions.frame_ids], dtype=np.int64)
    pred_frame = pred_frame_index[predictions.frame_of_row]
    score = predictions.score

    matched = match_frames(
        predictions.x_m, predictions.y_m, score, pred_frame, gt_x_m, gt_y_m, gt_offsets
    )
    is_tp = matched != UNMATCHED
    gt_range_m = range_m(gt_x_m, gt_y_m)
    # A TP lives in its ground truth's band, an FP in its own: this is what keeps a correct
    # detection straddling a band edge from scoring one FP plus one miss.
    detection_range_m = range_m(predictions.x_m, predictions.y_m)
    detection_range_m[is_tp] = gt_range_m[matched[is_tp]]

    scene_names = [f.rsplit("/", 1)[0] for f in frame_ids]
    scenes = sorted(set(scene_names))
    scene_index = {s: i for i, s in enumerate(scenes)}
    frame_scene = np.array([scene_index[s] for s in scene_names], dtype=np.int64)
    gt_scene = np.repeat(frame_scene, np.diff(gt_offsets))
    pred_scene = frame_scene[pred_frame] if len(frame_scene) else np.zeros(0, np.int64)

    metrics: dict[str, Any] = {"ap": {}, "counts": {}, "pr_curves": {}}
    band_detections = {}
    for band in BANDS_M:
        detection_in = in_band(detection_range_m, band)
        gt_in = in_band(gt_range_m, band)
        n_gt = int(gt_in.sum())
        ap, curve = average_precision(score[detection_in], is_tp[detection_in], n_gt)
        metrics["ap"][band] = ap
        n_tp = int((is_tp & detection_in).sum())
        metrics["counts"][band] = {"gt": n_gt, "tp": n_tp, "fp": int(detection_in.sum()) - n_tp}
        metrics["pr_curves"][band] = _curve_json(curve)
        band_detections[band] = BandDetections(
            score[detection_in], is_tp[detection_in], pred_scene[detection_in], gt_scene[gt_in]
        )
    metrics["protocol"] = protocol_dict()
    metrics["partial"] = bool(partial)
    metrics["n_frames"] = len(frame_ids)
    metrics["n_frames_ground_truth"] = len(ground_truth.frame_ids)
    metrics["n_scenes"] = len(scenes)
    metrics["n_predictions"] = int(len(score))
    if bootstrap:
        metrics["bootstrap"] = bootstrap_intervals(band_detections, len(scenes), bootstrap, seed)
    return metrics


def evaluate(
    predictions: Any,
    ground_truth: Any,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
    split: str | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> dict[str, Any]:
    """Score a predictions file against ground truth under the official protocol.

    Parameters
    ----------
    predictions
        Path to ``{"meta": {...}, "results": {frame_id: [{"x", "y", "score", ...}]}}`` or that dict.
    ground_truth
        Path to a dataset root or a ``{"frames": {frame_id: [{"x", "y", ...}]}}`` file, or that dict.
    partial
        Evaluate only the frames present in the predictions (say so in the output).
    bootstrap
        Number of scene resamples for 95% confidence intervals (0: none).
    seed
        Seed for the resampling.
    split
        Split of a dataset root (default: ``test`` when labelled, else ``val``).
    max_bytes
        Files larger than this are refused before parsing.

    Returns
    -------
    dict
        The ``metrics.json`` structure: ``ap`` (band → value in [0, 1] or None), ``counts``
        (band → gt/tp/fp), ``pr_curves``, ``protocol``, ``partial``, ``n_frames``, ``split`` when
        known, ``bootstrap`` when asked, and ``meta`` from the predictions.

    Raises
    ------
    PredictionsError
        Listing every problem found in either input.

    Examples
    --------
    >>> gt = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}
    >>> preds = {"meta": {"method": "demo"}, "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    >>> evaluate(preds, gt)["ap"]
    {'near': 1.0, 'mid': None, 'far': None, 'all': 1.0}
    """
    if isinstance(bootstrap, bool) or not isinstance(bootstrap, int) or bootstrap < 0:
        raise PredictionsError(f"bootstrap must be a non-negative integer, got {bootstrap!r}")
    pred_document, problems = load_document(predictions, what="predictions", max_bytes=max_bytes)
    pred = read_predictions(pred_document) if not problems else CheckedInput(None, None, [])
    gt = load_ground_truth(ground_truth, split=split, max_bytes=max_bytes)
    problems += pred.problems + gt.problems
    if pred.frame_ids is not None and gt.frame_ids is not None:
        problems += frame_set_problems(pred.frame_ids, gt.frame_ids, partial=partial)
    if problems:
        noun = "problem" if len(problems) == 1 else "problems"
        raise PredictionsError(
            f"{len(problems)} {noun} in the evaluator's input, nothing was scored:\n  "
            + "\n  ".join(problems),
            problems,
        )
    metrics = score_tables(pred.table, gt.table, partial=partial, bootstrap=bootstrap, seed=seed)
    if gt.split is not None:
        metrics["split"] = gt.split
    metrics["meta"] = pred.meta
    return metrics
