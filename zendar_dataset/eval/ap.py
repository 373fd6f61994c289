"""Average precision over one band's true and false positives.

Written here rather than taken from scikit-learn: ``average_precision_score`` integrates the raw
precision (no envelope) and needs every ground truth as a scored sample, which a detection
benchmark with misses does not have.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
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
        return curve_from_steps(np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64), 0)
    if not presorted:
        order = np.argsort(-score, kind="stable")
        score, is_tp = score[order], is_tp[order]
    ends = group_ends(score)
    tp_cumulative = np.cumsum(is_tp)[ends]
    return curve_from_steps(score[ends], tp_cumulative, (ends + 1) - tp_cumulative, n_gt)


def curve_from_steps(
    step_score: np.ndarray, tp_cumulative: np.ndarray, fp_cumulative: np.ndarray, n_gt: int
) -> tuple[float | None, PrecisionRecall]:
    """AP and curve from a band's steps (one per distinct score, descending) and cumulative counts.

    Parameters
    ----------
    step_score
        float64 (K,): the distinct scores, descending.
    tp_cumulative, fp_cumulative
        int64 (K,): TP and FP counts with score ≥ each step's score.
    n_gt
        Ground truths in the band.

    Returns
    -------
    (ap, curve)
        As from :func:`average_precision`.
    """
    if n_gt == 0:
        empty = np.zeros(0)
        return None, PrecisionRecall(empty, empty, empty, empty)
    recall, precision, envelope, ap = curve_from_cumulative(
        tp_cumulative.astype(np.float64), fp_cumulative.astype(np.float64), float(n_gt)
    )
    return ap, PrecisionRecall(step_score, recall, precision, envelope)


@numba.njit(cache=True, nogil=True)
def _partition_scores(score, category, n_categories):
    # Counting sort by category (linear): the scores of category c end up in
    # out[offsets[c]:offsets[c + 1]], in input order.
    offsets = np.zeros(n_categories + 1, dtype=np.int64)
    for i in range(len(category)):
        offsets[category[i] + 1] += 1
    for c in range(n_categories):
        offsets[c + 1] += offsets[c]
    fill = offsets[:-1].copy()
    out = np.empty(len(score), dtype=np.float64)
    for i in range(len(score)):
        c = category[i]
        out[fill[c]] = score[i]
        fill[c] += 1
    return out, offsets


@numba.njit(cache=True, nogil=True)
def _descending_steps(sorted_score, offsets, categories, category_is_tp):
    # Merge the ascending runs of the given categories from their top ends, one step per distinct
    # score, counting TP and FP as they go.
    k = len(categories)
    start = np.empty(k, dtype=np.int64)
    position = np.empty(k, dtype=np.int64)
    total = 0
    for j in range(k):
        start[j] = offsets[categories[j]]
        position[j] = offsets[categories[j] + 1] - 1
        total += offsets[categories[j] + 1] - offsets[categories[j]]
    step_score = np.empty(total, dtype=np.float64)
    tp_cumulative = np.empty(total, dtype=np.int64)
    fp_cumulative = np.empty(total, dtype=np.int64)
    n_steps = 0
    tp = 0
    fp = 0
    while True:
        found = False
        top = 0.0
        for j in range(k):
            if position[j] >= start[j] and (not found or sorted_score[position[j]] > top):
                top = sorted_score[position[j]]
                found = True
        if not found:
            break
        for j in range(k):
            while position[j] >= start[j] and sorted_score[position[j]] == top:
                if category_is_tp[j]:
                    tp += 1
                else:
                    fp += 1
                position[j] -= 1
        step_score[n_steps] = top
        tp_cumulative[n_steps] = tp
        fp_cumulative[n_steps] = fp
        n_steps += 1
    return step_score[:n_steps], tp_cumulative[:n_steps], fp_cumulative[:n_steps]


def band_steps(
    score: np.ndarray, is_tp: np.ndarray, band_bits: np.ndarray, n_bands: int
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Each band's steps (distinct scores, descending) with cumulative TP and FP counts.

    Equivalent to masking each band and calling :func:`sort_by_score`, but with no index sort:
    detections are split by (bands, TP) in one linear pass, each group's scores are sorted by
    value (several times faster than an argsort of the whole array), and each band merges the
    groups it contains.

    Parameters
    ----------
    score
        float64 (N,), any order.
    is_tp
        bool (N,).
    band_bits
        uint8 (N,): bit b set when the detection counts in band b.
    n_bands
        B ≤ 8.

    Returns
    -------
    list
        Per band: ``(step_score, tp_cumulative, fp_cumulative)``, float64 and int64 (K_b,).
    """
    n_categories = 2 << n_bands
    category = band_bits.astype(np.int64) * 2 + is_tp
    sorted_score, offsets = _partition_scores(
        np.ascontiguousarray(score, dtype=np.float64), category, n_categories
    )
    occupied = np.flatnonzero(np.diff(offsets))
    for c in occupied:
        if c >= 2:  # categories 0 and 1 are in no band and never read
            sorted_score[offsets[c] : offsets[c + 1]].sort()
    steps = []
    for b in range(n_bands):
        categories = occupied[((occupied >> 1) >> b) & 1 == 1]
        steps.append(_descending_steps(sorted_score, offsets, categories, (categories & 1) == 1))
    return steps
