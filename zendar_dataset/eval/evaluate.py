"""Score predictions against ground truth: validation, matching, banding, AP, bootstrap.

:func:`evaluate_record` returns the typed :class:`~zendar_dataset.eval.records.MetricsRecord`;
:func:`evaluate` returns its ``to_json()``, exactly what ``zendar-eval`` writes to ``metrics.json``.
"""

from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import PredictionsError, ZendarError
from zendar_dataset.eval.ap import PrecisionRecall, band_steps, curve_from_steps
from zendar_dataset.eval.bootstrap import BandDetections, bootstrap_intervals, distinct_resamples, frame_blocks
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
    if document is None and problems:
        return CheckedInput(None, None, problems)
    checked = read_ground_truth_document(document)
    if problems:  # keys given twice: the rest of the document is still checked
        checked.problems[:0] = problems
        checked.table = None
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


@dataclass(frozen=True)
class MatchedDetections:
    """One predictions file matched to the ground truth, per frame: what AP and the bootstrap read.

    Attributes
    ----------
    frame_ids : tuple of str
        The ground truth's frame ids (F,), ``"<scene_id>/<timestamp_ns>"``.
    evaluated_frame : numpy.ndarray
        bool (F,): the frame is evaluated (every frame unless ``partial``).
    score : numpy.ndarray
        float64 (P,): each prediction's score.
    is_tp : numpy.ndarray
        bool (P,): matched to a ground truth (protocol §2).
    band_bits : numpy.ndarray
        uint8 (P,): bit b set when the prediction counts in band ``BAND_NAMES[b]`` (protocol §3).
    pred_frame : numpy.ndarray
        int64 (P,): ground-truth frame index of each prediction.
    gt_frame : numpy.ndarray
        int64 (G,): frame index of each ground truth.
    gt_in_band : dict of str to numpy.ndarray
        Band → bool (G,): the ground truth counts in the band (its range in it, its frame evaluated).
    """

    frame_ids: tuple[str, ...]
    evaluated_frame: np.ndarray
    score: np.ndarray
    is_tp: np.ndarray
    band_bits: np.ndarray
    pred_frame: np.ndarray
    gt_frame: np.ndarray
    gt_in_band: dict[str, np.ndarray]

    def band_detections(self, frame_unit: np.ndarray) -> dict[str, BandDetections]:
        """Each band's detections and ground truths tagged with the resampling unit of their frame.

        Parameters
        ----------
        frame_unit
            int64 (F,): unit of each ground-truth frame (from :func:`frame_units`).
        """
        pred_unit = frame_unit[self.pred_frame]
        gt_unit = frame_unit[self.gt_frame]
        bands = {}
        for b, band in enumerate(BAND_NAMES):
            d_in = (self.band_bits >> b) & 1 == 1
            bands[band] = BandDetections(
                self.score[d_in], self.is_tp[d_in], pred_unit[d_in], gt_unit[self.gt_in_band[band]]
            )
        return bands


def match_tables(predictions: DetectionTable, ground_truth: DetectionTable, *, partial: bool = False) -> MatchedDetections:
    """Match validated tables once, per frame over all ranges, and band every detection.

    Parameters
    ----------
    predictions, ground_truth
        Validated detection tables (every prediction frame is a ground-truth frame).
    partial
        Evaluate only the ground-truth frames present in the predictions.
    """
    if predictions.frame_ids == ground_truth.frame_ids:  # the usual case: files listed in one order
        pred_gt_frame = np.arange(len(ground_truth.frame_ids), dtype=np.int64)
    else:
        gt_position = {frame_id: g for g, frame_id in enumerate(ground_truth.frame_ids)}
        pred_gt_frame = np.array([gt_position[f] for f in predictions.frame_ids], dtype=np.int64)
    if partial:
        evaluated_frame = np.zeros(len(ground_truth.frame_ids), dtype=bool)
        evaluated_frame[pred_gt_frame] = True
    else:
        evaluated_frame = np.ones(len(ground_truth.frame_ids), dtype=bool)
    gt_evaluated = evaluated_frame[ground_truth.frame_of_row]
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
    gt_range_m = range_m(ground_truth.x_m, ground_truth.y_m)
    return MatchedDetections(
        frame_ids=tuple(ground_truth.frame_ids),
        evaluated_frame=evaluated_frame,
        score=predictions.score,
        is_tp=matched != UNMATCHED,
        band_bits=band_bits,
        pred_frame=np.repeat(pred_gt_frame, predictions.counts),
        gt_frame=np.asarray(ground_truth.frame_of_row, dtype=np.int64),
        gt_in_band={band: in_band(gt_range_m, band) & gt_evaluated for band in BAND_NAMES},
    )


def frame_units(
    frame_ids: tuple[str, ...] | list[str], evaluated_frame: np.ndarray, block_s: float | None = None
) -> tuple[np.ndarray, int]:
    """The bootstrap's resampling unit of each frame: its scene, or its scene's time block.

    Parameters
    ----------
    frame_ids
        (F,) frame ids ``"<scene_id>/<timestamp_ns>"``.
    evaluated_frame
        bool (F,): frames that are resampled; the others get unit -1.
    block_s
        None: scenes (in sorted order of their ids). Else each scene's frames cut into blocks of this
        many seconds (:func:`~zendar_dataset.eval.bootstrap.frame_blocks`), which needs each frame
        id's part after the last ``/`` to be an integer timestamp in nanoseconds.

    Returns
    -------
    (frame_unit, n_units)
        int64 (F,) and the number of units.

    Raises
    ------
    ZendarError
        With ``block_s``, naming a frame id without an integer timestamp.
    """
    evaluated = [f for f, keep in zip(frame_ids, evaluated_frame) if keep]
    scenes = sorted({scene_of(f) for f in evaluated})
    scene_index = {name: k for k, name in enumerate(scenes)}
    frame_unit = np.full(len(frame_ids), -1, dtype=np.int64)
    where = np.flatnonzero(evaluated_frame)
    scene_of_frame = np.array([scene_index[scene_of(f)] for f in evaluated], dtype=np.int64)
    if block_s is None:
        frame_unit[where] = scene_of_frame
        return frame_unit, len(scenes)
    timestamps = [_timestamp_ns(f) for f in evaluated]
    blocks, n_blocks = frame_blocks(scene_of_frame, np.array(timestamps, dtype=np.int64), block_s)
    frame_unit[where] = blocks
    return frame_unit, n_blocks


#: The largest timestamp a frame id may carry: time blocks compute in int64 nanoseconds.
_MAX_TIMESTAMP_NS = np.iinfo(np.int64).max


def _timestamp_ns(frame_id: str) -> int:
    """The integer timestamp after a frame id's last ``/``.

    Raises
    ------
    ZendarError
        Naming the frame when that part is not ASCII digits (``isdigit`` alone would let
        superscripts and other scripts' digits through) or is beyond int64.
    """
    stamp = frame_id.rpartition("/")[2]
    if not (stamp.isascii() and stamp.isdigit()):
        raise ZendarError(
            f"bootstrap over time blocks needs frame ids '<scene_id>/<timestamp_ns>': "
            f"frame {frame_id!r} has no integer timestamp after its last '/'"
        )
    if len(stamp) > len(str(_MAX_TIMESTAMP_NS)) or int(stamp) > _MAX_TIMESTAMP_NS:  # int() refuses 4,301 digits
        raise ZendarError(
            f"bootstrap over time blocks needs timestamps of at most {_MAX_TIMESTAMP_NS} ns: "
            f"frame {frame_id!r} has a larger one"
        )
    return int(stamp)


def score_tables(
    predictions: DetectionTable,
    ground_truth: DetectionTable,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
    split: str | None = None,
    meta: dict[str, Any] | None = None,
    bootstrap_block_s: float | None = None,
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
        Number of resamples for confidence intervals (0: none).
    seed
        Seed for the resampling.
    split, meta
        Recorded as they are: the ground truth's split, the predictions' ``meta`` (default ``{}``).
    bootstrap_block_s
        None: the bootstrap resamples scenes. Else it resamples each scene's time blocks of this many
        seconds (:func:`frame_units`).

    Returns
    -------
    MetricsRecord
    """
    matched = match_tables(predictions, ground_truth, partial=partial)
    ap_by_band: dict[str, float | None] = {}
    counts: dict[str, BandCounts] = {}
    pr_curves: dict[str, PRCurve] = {}
    # Per band, one step per distinct score with cumulative TP/FP counts (ties form one step).
    steps = band_steps(matched.score, matched.is_tp, matched.band_bits, len(BAND_NAMES))
    for band, (step_score, tp_cumulative, fp_cumulative) in zip(BAND_NAMES, steps):
        n_gt = int(matched.gt_in_band[band].sum())
        ap_by_band[band], curve = curve_from_steps(step_score, tp_cumulative, fp_cumulative, n_gt)
        n_tp = int(tp_cumulative[-1]) if len(tp_cumulative) else 0
        n_fp = int(fp_cumulative[-1]) if len(fp_cumulative) else 0
        counts[band] = BandCounts(gt=n_gt, tp=n_tp, fp=n_fp)
        pr_curves[band] = _curve_record(curve)

    evaluated_ids = predictions.frame_ids if partial else ground_truth.frame_ids
    n_scenes = len({scene_of(frame_id) for frame_id in evaluated_ids})
    protocol = protocol_dict(bootstrap_block_s if bootstrap else None)
    intervals = None
    if bootstrap:
        frame_unit, n_units = frame_units(matched.frame_ids, matched.evaluated_frame, bootstrap_block_s)
        bands = matched.band_detections(frame_unit)
        intervals = {
            band: BootstrapInterval(**interval)
            for band, interval in bootstrap_intervals(bands, n_units, bootstrap, seed).items()
        }
        if bootstrap_block_s is not None:  # with scenes as units, n_scenes already says how many
            protocol["bootstrap"]["n_units"] = n_units
            protocol["bootstrap"]["distinct_resamples"] = distinct_resamples(n_units)
    return MetricsRecord(
        ap=ap_by_band,
        counts=counts,
        protocol=protocol,
        partial=bool(partial),
        n_frames=len(predictions.frame_ids) if partial else len(ground_truth.frame_ids),
        n_frames_ground_truth=len(ground_truth.frame_ids),
        n_scenes=n_scenes,
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


def _block_argument(block_s: Any) -> float | None:
    """``block_s`` as a positive finite float, or None."""
    if block_s is None:
        return None
    if isinstance(block_s, (bool, np.bool_)) or not isinstance(block_s, (int, float, np.integer, np.floating)):
        raise ZendarError(f"bootstrap_block_s must be a number of seconds, got {type(block_s).__name__} {block_s!r}")
    if not (math.isfinite(block_s) and block_s > 0):
        raise ZendarError(f"bootstrap_block_s must be a positive number of seconds, got {block_s}")
    return float(block_s)


def _checked_tables(
    predictions: Any, ground_truth: Any, *, partial: bool, split: str | None, max_bytes: int
) -> tuple[CheckedInput, CheckedInput]:
    """Both inputs read and validated; PredictionsError listing every problem of either."""
    pred_document, problems = load_document(predictions, what="predictions", max_bytes=max_bytes)
    read = pred_document is not None or not problems  # null is a document, refused by read_predictions
    pred = read_predictions(pred_document) if read else CheckedInput(None, None, [])
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
    return pred, gt


def matched_detections(
    predictions: Any, ground_truth: Any, *, split: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES
) -> MatchedDetections:
    """The evaluator's matching of a predictions file over every ground-truth frame, before any AP.

    What two detectors' paired comparisons resample (:mod:`zendar_dataset.eval.paired`): the same
    frames, matched and banded exactly as :func:`evaluate` scores them.

    Parameters
    ----------
    predictions, ground_truth, split, max_bytes
        As for :func:`evaluate` (every ground-truth frame must be in the predictions).

    Raises
    ------
    PredictionsError
        Listing every problem found in either input.
    """
    max_bytes = _count_argument("max_bytes", max_bytes, 1, None)
    pred, gt = _checked_tables(predictions, ground_truth, partial=False, split=split, max_bytes=max_bytes)
    return match_tables(pred.table, gt.table)


def evaluate_record(
    predictions: Any,
    ground_truth: Any,
    *,
    partial: bool = False,
    bootstrap: int = 0,
    seed: int = 0,
    split: str | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
    bootstrap_block_s: float | None = None,
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
    bootstrap_block_s = _block_argument(bootstrap_block_s)
    pred, gt = _checked_tables(predictions, ground_truth, partial=partial, split=split, max_bytes=max_bytes)
    return score_tables(
        pred.table, gt.table, partial=partial, bootstrap=bootstrap, seed=seed, split=gt.split, meta=pred.meta,
        bootstrap_block_s=bootstrap_block_s,
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
    bootstrap_block_s: float | None = None,
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
        Number of resamples for 95% confidence intervals (0: none; at most
        ``MAX_BOOTSTRAP_RESAMPLES``); the unit resampled is the scene unless ``bootstrap_block_s``.
    seed
        Seed for the resampling (0 or more).
    split
        Split of a dataset root (default: ``test`` when labelled, else ``val``).
    max_bytes
        Files larger than this are refused before parsing.
    bootstrap_block_s
        Resample each scene's time blocks of this many seconds instead of whole scenes
        (``protocol.bootstrap`` then says ``"unit": "scene_time_block"`` and ``"block_s"``).

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
        For an argument out of range (``bootstrap``, ``seed``, ``max_bytes``, ``bootstrap_block_s``),
        or time blocks asked of frame ids without an integer timestamp.

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
        bootstrap_block_s=bootstrap_block_s,
    ).to_json()
