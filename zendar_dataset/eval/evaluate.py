"""Score predictions against ground truth: validation, matching, banding, AP, bootstrap.

:func:`evaluate_record` returns the typed :class:`~zendar_dataset.eval.records.MetricsRecord`;
:func:`evaluate` returns its ``to_json()``, exactly what ``zendar-eval`` writes to ``metrics.json``.
"""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import PredictionsError, ZendarError
from zendar_dataset.eval.ap import PrecisionRecall, band_steps, curve_from_steps
from zendar_dataset.eval.bootstrap import BandDetections, bootstrap_intervals
from zendar_dataset.eval.matching import UNMATCHED, match_and_band
from zendar_dataset.eval.protocol import (
    BAND_NAMES,
    BANDS_M,
    DEFAULT_MAX_BYTES,
    MAX_BOOTSTRAP_RESAMPLES,
    MAX_PR_CURVE_POINTS,
    in_band,
    protocol_dict,
    range_m,
)
from zendar_dataset.eval.records import BandCounts, BootstrapInterval, MetricsRecord, PRCurve
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

    # By default, the first split whose scenes carry labels (the format raises for one without).
    candidates = [split] if split is not None else list(DEFAULT_SPLITS)
    reasons = []
    for candidate in candidates:
        try:
            frames = ground_truth_frames(root, candidate)
        except ZendarError as exc:
            reasons.append(f"split {candidate!r}: {exc}")
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


def _curve_record(curve: PrecisionRecall) -> PRCurve:
    n = len(curve.score)
    keep = slice(None)
    if n > MAX_PR_CURVE_POINTS:
        keep = np.unique(np.linspace(0, n - 1, MAX_PR_CURVE_POINTS).round().astype(np.int64))
    return PRCurve(
        recall=tuple(curve.recall[keep].tolist()),
        precision=tuple(curve.precision[keep].tolist()),
        precision_envelope=tuple(curve.precision_envelope[keep].tolist()),
        score=tuple(curve.score[keep].tolist()),
    )


def scene_of(frame_id: str) -> str:
    """The scene id of a frame id ``"<scene_id>/<timestamp_ns>"``."""
    return frame_id.rpartition("/")[0]


def score_tables(
    predictions: DetectionTable,
    ground_truth: DetectionTable,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
    split: str | None = None,
    meta: dict[str, Any] | None = None,
) -> MetricsRecord:
    """Score validated tables (every prediction frame is a ground-truth frame).

    Parameters
    ----------
    predictions, ground_truth
        Validated detection tables.
    partial
        Evaluate only the ground-truth frames present in the predictions; otherwise every
        ground-truth frame must be in the predictions.
    bootstrap
        Number of scene resamples for confidence intervals (0: none).
    seed
        Seed for the resampling.
    split, meta
        Recorded as they are: the ground truth's split, the predictions' ``meta`` (default ``{}``).

    Returns
    -------
    MetricsRecord
    """
    if predictions.frame_ids == ground_truth.frame_ids:  # the usual case: files listed in one order
        pred_gt_frame = np.arange(len(ground_truth.frame_ids), dtype=np.int64)
    else:
        gt_position = {frame_id: g for g, frame_id in enumerate(ground_truth.frame_ids)}
        pred_gt_frame = np.array([gt_position[f] for f in predictions.frame_ids], dtype=np.int64)
    if partial:
        evaluated_frame = np.zeros(len(ground_truth.frame_ids), dtype=bool)
        evaluated_frame[pred_gt_frame] = True
        gt_evaluated = evaluated_frame[ground_truth.frame_of_row]
    else:
        gt_evaluated = np.ones(len(ground_truth.x_m), dtype=bool)
    band_low_m = np.array([BANDS_M[b][0] for b in BAND_NAMES])
    band_high_m = np.array([BANDS_M[b][1] for b in BAND_NAMES])
    # A TP lives in its ground truth's band, an FP in its own: this is what keeps a correct
    # detection straddling a band edge from scoring one FP plus one miss.
    matched, band_bits = match_and_band(
        predictions.x_m,
        predictions.y_m,
        predictions.score,
        predictions.offsets,
        pred_gt_frame,
        ground_truth.x_m,
        ground_truth.y_m,
        ground_truth.offsets,
        band_low_m,
        band_high_m,
    )
    is_tp = matched != UNMATCHED
    gt_range_m = range_m(ground_truth.x_m, ground_truth.y_m)

    ap_by_band: dict[str, float | None] = {}
    counts: dict[str, BandCounts] = {}
    pr_curves: dict[str, PRCurve] = {}
    gt_masks = {}
    # Per band, one step per distinct score with cumulative TP/FP counts (ties form one step).
    steps = band_steps(predictions.score, is_tp, band_bits, len(BAND_NAMES))
    for band, (step_score, tp_cumulative, fp_cumulative) in zip(BAND_NAMES, steps):
        gt_in = in_band(gt_range_m, band) & gt_evaluated
        gt_masks[band] = gt_in
        n_gt = int(gt_in.sum())
        ap_by_band[band], curve = curve_from_steps(step_score, tp_cumulative, fp_cumulative, n_gt)
        n_tp = int(tp_cumulative[-1]) if len(tp_cumulative) else 0
        n_fp = int(fp_cumulative[-1]) if len(fp_cumulative) else 0
        counts[band] = BandCounts(gt=n_gt, tp=n_tp, fp=n_fp)
        pr_curves[band] = _curve_record(curve)

    evaluated_ids = predictions.frame_ids if partial else ground_truth.frame_ids
    scenes = sorted({frame_id.rpartition("/")[0] for frame_id in evaluated_ids})
    intervals = None
    if bootstrap:
        scene_index = {name: k for k, name in enumerate(scenes)}
        gt_frame_scene = np.array(
            [scene_index.get(scene_of(f), -1) for f in ground_truth.frame_ids], dtype=np.int64
        )
        gt_scene = gt_frame_scene[ground_truth.frame_of_row]
        pred_scene = np.repeat(gt_frame_scene[pred_gt_frame], predictions.counts)
        bands = {}
        for b, band in enumerate(BAND_NAMES):
            d_in = (band_bits >> b) & 1 == 1
            bands[band] = BandDetections(
                predictions.score[d_in], is_tp[d_in], pred_scene[d_in], gt_scene[gt_masks[band]]
            )
        intervals = {
            band: BootstrapInterval(**interval)
            for band, interval in bootstrap_intervals(bands, len(scenes), bootstrap, seed).items()
        }
    return MetricsRecord(
        ap=ap_by_band,
        counts=counts,
        protocol=protocol_dict(),
        partial=bool(partial),
        n_frames=len(predictions.frame_ids) if partial else len(ground_truth.frame_ids),
        n_frames_ground_truth=len(ground_truth.frame_ids),
        n_scenes=len(scenes),
        n_predictions=len(predictions.score),
        meta={} if meta is None else copy.deepcopy(meta),
        pr_curves=pr_curves,
        bootstrap=intervals,
        split=split,
    )


def _count_argument(name: str, value: Any, low: int, high: int | None) -> int:
    """``value`` as an int in ``[low, high]`` (numpy integers accepted, bool refused)."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ZendarError(f"{name} must be an integer, got {type(value).__name__} {value!r}")
    if value < low or (high is not None and value > high):
        bounds = f"between {low:,} and {high:,}" if high is not None else f"{low} or more"
        raise ZendarError(f"{name} must be {bounds}, got {value}")
    return int(value)


def evaluate_record(
    predictions: Any,
    ground_truth: Any,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
    split: str | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> MetricsRecord:
    """Score a predictions file against ground truth under the official protocol, as a typed record.

    Takes the arguments of :func:`evaluate` and raises the same errors; ``to_json()`` of the
    result is what :func:`evaluate` returns.

    Returns
    -------
    MetricsRecord

    Examples
    --------
    >>> gt = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}
    >>> preds = {"meta": {"method": "demo"}, "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    >>> record = evaluate_record(preds, gt)
    >>> record.ap["near"], record.counts["near"]
    (1.0, BandCounts(gt=1, tp=1, fp=0))
    """
    bootstrap = _count_argument("bootstrap", bootstrap, 0, MAX_BOOTSTRAP_RESAMPLES)
    seed = _count_argument("seed", seed, 0, None)
    max_bytes = _count_argument("max_bytes", max_bytes, 1, None)
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
    return score_tables(
        pred.table, gt.table, partial=partial, bootstrap=bootstrap, seed=seed, split=gt.split, meta=pred.meta
    )


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
        Number of scene resamples for 95% confidence intervals (0: none; at most
        ``MAX_BOOTSTRAP_RESAMPLES``).
    seed
        Seed for the resampling (0 or more).
    split
        Split of a dataset root (default: ``test`` when labelled, else ``val``).
    max_bytes
        Files larger than this are refused before parsing.

    Returns
    -------
    dict
        The ``metrics.json`` structure: ``ap`` (band → value in [0, 1] or None), ``counts``
        (band → gt/tp/fp), ``pr_curves``, ``protocol``, ``partial``, ``n_frames``, ``split`` when
        known, ``bootstrap`` when asked, and ``meta`` from the predictions. It is
        ``evaluate_record(...).to_json()``; :func:`evaluate_record` gives the typed record.

    Raises
    ------
    PredictionsError
        Listing every problem found in either input.
    ZendarError
        For an argument out of range (``bootstrap``, ``seed``, ``max_bytes``).

    Examples
    --------
    >>> gt = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}
    >>> preds = {"meta": {"method": "demo"}, "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    >>> evaluate(preds, gt)["ap"]
    {'near': 1.0, 'mid': None, 'far': None, 'all': 1.0}
    """
    return evaluate_record(
        predictions,
        ground_truth,
        partial=partial,
        bootstrap=bootstrap,
        seed=seed,
        split=split,
        max_bytes=max_bytes,
    ).to_json()
