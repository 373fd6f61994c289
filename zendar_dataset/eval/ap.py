"""Average precision over one band's true and false positives.

Written here rather than taken from scikit-learn: ``average_precision_score`` integrates the raw
precision (no envelope) and needs every ground truth as a scored sample, which a detection
benchmark with misses does not have.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PrecisionRecall:
    """A precision-recall curve, one point per distinct score (descending).

    Attributes
    ----------
    score
        float64 (K,): the distinct scores, descending; point n counts detections with score ≥ score[n].
    recall, precision
        float64 (K,): recall and raw precision at each point.
    precision_envelope
        float64 (K,): max of precision over this and all higher recalls.
    """

    score: np.ndarray
    recall: np.ndarray
    precision: np.ndarray
    precision_envelope: np.ndarray

    def __post_init__(self) -> None:
        shapes = {a.shape for a in (self.score, self.recall, self.precision, self.precision_envelope)}
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise ValueError(f"curve arrays must share one 1-D shape, got {sorted(shapes)}")


def group_ends(sorted_score: np.ndarray) -> np.ndarray:
    """int64 (K,): the last index of each run of equal values in a sorted score array (N,)."""
    if len(sorted_score) == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.append(sorted_score[1:] != sorted_score[:-1], True))


def sort_by_score(score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Descending order of ``score`` and the positions (in that order) where a run of equal scores ends.

    Returns
    -------
    (order, group_ends)
        int64 (N,) permutation and int64 (K,) last index of each distinct-score group.
    """
    order = np.argsort(-score, kind="stable")
    return order, group_ends(score[order])


def curve_from_cumulative(
    tp_cumulative: np.ndarray, fp_cumulative: np.ndarray, n_gt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Recall, precision, envelope and AP from cumulative TP/FP counts at each step.

    Parameters
    ----------
    tp_cumulative, fp_cumulative
        float64 or int (K,): TP and FP counts with score ≥ each step's score; every step holds at
        least one detection.
    n_gt
        Number of ground truths (> 0).

    Returns
    -------
    (recall, precision, precision_envelope, ap)
    """
    recall = tp_cumulative / n_gt
    precision = tp_cumulative / (tp_cumulative + fp_cumulative)
    envelope = np.maximum.accumulate(precision[::-1])[::-1]
    recall_step = np.diff(recall, prepend=0.0)
    return recall, precision, envelope, float(np.sum(recall_step * envelope))


def average_precision(
    score: np.ndarray, is_tp: np.ndarray, n_gt: int, *, presorted: bool = False
) -> tuple[float | None, PrecisionRecall]:
    """AP of one band: ties form one step, precision envelope, AP = Σ (Rₙ − Rₙ₋₁)·P_env(Rₙ).

    Parameters
    ----------
    score
        float64 (N,): scores of the band's TP and FP detections, over all frames, any order.
    is_tp
        bool (N,).
    n_gt
        Ground truths in the band.
    presorted
        ``score`` is already in descending order (saves a sort when many bands share one).

    Returns
    -------
    (ap, curve)
        ``ap`` in [0, 1], or None when ``n_gt`` is 0 (the curve is then empty).
    """
    if n_gt == 0:
        empty = np.zeros(0)
        return None, PrecisionRecall(empty, empty, empty, empty)
    if not presorted:
        order = np.argsort(-score, kind="stable")
        score, is_tp = score[order], is_tp[order]
    ends = group_ends(score)
    tp_cumulative = np.cumsum(is_tp)[ends]
    fp_cumulative = (ends + 1) - tp_cumulative
    recall, precision, envelope, ap = curve_from_cumulative(
        tp_cumulative.astype(np.float64), fp_cumulative.astype(np.float64), float(n_gt)
    )
    return ap, PrecisionRecall(score[ends], recall, precision, envelope)
