"""Center-distance matching of predictions to ground truth, once per frame over all ranges.

:func:`match_frame` states the rule in a few readable lines; :func:`match_frames` is the same rule
for many frames at once, compiled with numba because greedy matching is sequential within a frame
(each prediction's choice depends on the ones before it) and cannot be written as array operations
without quadratic memory. :func:`match_and_band` adds each prediction's bands in the same
compiled call, which is what the evaluator uses.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from zendar_dataset.eval.protocol import MATCH_DISTANCE_M

UNMATCHED = -1


def match_frame(
    pred_xy_m: np.ndarray,
    pred_score: np.ndarray,
    gt_xy_m: np.ndarray,
    match_distance_m: float = MATCH_DISTANCE_M,
) -> np.ndarray:
    """Match one frame's predictions to its ground truth (the protocol's rule, spelled out).

    Predictions in descending score (equal scores keep list order) each take the nearest
    still-unmatched ground truth whose center distance is strictly less than
    ``match_distance_m``; equal distances go to the earlier ground-truth entry.

    Parameters
    ----------
    pred_xy_m
        float64 (P, 2), ego frame, metres.
    pred_score
        float64 (P,).
    gt_xy_m
        float64 (G, 2), ego frame, metres.
    match_distance_m
        The match threshold (exclusive).

    Returns
    -------
    numpy.ndarray
        int64 (P,): the ground-truth index matched by each prediction (in list order), or -1.
    """
    matched = np.full(len(pred_xy_m), UNMATCHED, dtype=np.int64)
    taken = np.zeros(len(gt_xy_m), dtype=bool)
    for p in np.argsort(-pred_score, kind="stable"):
        delta = gt_xy_m - pred_xy_m[p]
        distance_m = np.sqrt(delta[:, 0] * delta[:, 0] + delta[:, 1] * delta[:, 1])
        distance_m[taken] = np.inf
        if len(distance_m) and distance_m.min() < match_distance_m:
            g = int(np.argmin(distance_m))  # argmin returns the first of equal minima
            matched[p] = g
            taken[g] = True
    return matched


@numba.njit(cache=True, nogil=True)
def _sort_stable_descending(rows, n, score):
    # Reorders rows[:n] (ascending row numbers, i.e. list order) by descending score, equal
    # scores keeping list order. Insertion sort for the usual handful of rows (no allocation);
    # mergesort, which is stable, for longer lists.
    if n > 32:
        rows[:n] = rows[:n][np.argsort(-score[rows[:n]], kind="mergesort")]
        return
    for i in range(1, n):
        row = rows[i]
        j = i
        while j > 0 and score[rows[j - 1]] < score[row]:
            rows[j] = rows[j - 1]
            j -= 1
        rows[j] = row


@numba.njit(cache=True, nogil=True)
def _within(x, y, gt_x, gt_y, g_start, g_stop, match_distance_m):
    for g in range(g_start, g_stop):
        dx = x - gt_x[g]
        dy = y - gt_y[g]
        if math.sqrt(dx * dx + dy * dy) < match_distance_m:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _band_bits(r, band_low_m, band_high_m):
    bits = 0
    for b in range(len(band_low_m)):
        if band_low_m[b] <= r < band_high_m[b]:
            bits |= 1 << b
    return bits


@numba.njit(cache=True, nogil=True)
def _match_and_band_kernel(
    pred_x, pred_y, pred_score, pred_offsets, pred_gt_frame, gt_x, gt_y, gt_offsets, match_distance_m,
    band_low_m, band_high_m,
):
    matched = np.full(len(pred_x), -1, dtype=np.int64)
    taken = np.zeros(len(gt_x), dtype=np.bool_)
    longest = 0
    for f in range(len(pred_offsets) - 1):
        longest = max(longest, pred_offsets[f + 1] - pred_offsets[f])
    candidates = np.empty(longest, dtype=np.int64)  # reused by every frame
    for f in range(len(pred_offsets) - 1):
        g_start = gt_offsets[pred_gt_frame[f]]
        g_stop = gt_offsets[pred_gt_frame[f] + 1]
        if g_start == g_stop:
            continue
        # Only predictions within reach of some ground truth can match, whatever the order; the
        # others need not be sorted. The candidates keep their relative order in the full order.
        n = 0
        for p in range(pred_offsets[f], pred_offsets[f + 1]):
            if _within(pred_x[p], pred_y[p], gt_x, gt_y, g_start, g_stop, match_distance_m):
                candidates[n] = p
                n += 1
        _sort_stable_descending(candidates, n, pred_score)
        for k in range(n):
            p = candidates[k]
            best = -1
            best_distance = match_distance_m  # strict "<" below makes the threshold exclusive
            for g in range(g_start, g_stop):
                if taken[g]:
                    continue
                dx = pred_x[p] - gt_x[g]
                dy = pred_y[p] - gt_y[g]
                distance = math.sqrt(dx * dx + dy * dy)
                if distance < best_distance:  # strict: an equal later distance keeps the earlier entry
                    best_distance = distance
                    best = g
            if best >= 0:
                taken[best] = True
                matched[p] = best
    # Bands in the same compiled call: a TP counts at its ground truth's range, an FP at its own.
    bits = np.empty(len(pred_x), dtype=np.uint8)
    for p in range(len(pred_x)):
        g = matched[p]
        if g >= 0:
            r = math.sqrt(gt_x[g] * gt_x[g] + gt_y[g] * gt_y[g])
        else:
            r = math.sqrt(pred_x[p] * pred_x[p] + pred_y[p] * pred_y[p])
        bits[p] = _band_bits(r, band_low_m, band_high_m)
    return matched, bits


def match_frames(
    pred_x_m: np.ndarray,
    pred_y_m: np.ndarray,
    pred_score: np.ndarray,
    pred_offsets: np.ndarray,
    pred_gt_frame: np.ndarray,
    gt_x_m: np.ndarray,
    gt_y_m: np.ndarray,
    gt_offsets: np.ndarray,
    match_distance_m: float = MATCH_DISTANCE_M,
) -> np.ndarray:
    """Match the predictions of many frames at once (same rule as :func:`match_frame`).

    Parameters
    ----------
    pred_x_m, pred_y_m, pred_score
        float64 (P,), ego frame, metres; grouped by frame, each frame's detections in list order.
    pred_offsets
        int64 (F_p + 1,): predictions of frame f are rows ``pred_offsets[f]:pred_offsets[f + 1]``.
    pred_gt_frame
        int64 (F_p,): the ground-truth frame of each prediction frame (each used at most once).
    gt_x_m, gt_y_m
        float64 (G,), ego frame, metres, grouped by frame.
    gt_offsets
        int64 (F_g + 1,): ground truth of frame g is ``gt_offsets[g]:gt_offsets[g + 1]``.
    match_distance_m
        The match threshold (exclusive).

    Returns
    -------
    numpy.ndarray
        int64 (P,): index into the ground-truth arrays matched by each prediction, or -1.
    """
    return match_and_band(
        pred_x_m, pred_y_m, pred_score, pred_offsets, pred_gt_frame, gt_x_m, gt_y_m, gt_offsets,
        np.zeros(0), np.zeros(0), match_distance_m,
    )[0]


def match_and_band(
    pred_x_m: np.ndarray,
    pred_y_m: np.ndarray,
    pred_score: np.ndarray,
    pred_offsets: np.ndarray,
    pred_gt_frame: np.ndarray,
    gt_x_m: np.ndarray,
    gt_y_m: np.ndarray,
    gt_offsets: np.ndarray,
    band_low_m: np.ndarray,
    band_high_m: np.ndarray,
    match_distance_m: float = MATCH_DISTANCE_M,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`match_frames` and each prediction's bands, in one compiled pass.

    Parameters
    ----------
    pred_x_m, pred_y_m, pred_score, pred_offsets, pred_gt_frame, gt_x_m, gt_y_m, gt_offsets
        As for :func:`match_frames`.
    band_low_m, band_high_m
        float64 (B,), B ≤ 8: half-open range bands ``[low, high)``, metres.
    match_distance_m
        The match threshold (exclusive).

    Returns
    -------
    (matched, band_bits)
        int64 (P,) as from :func:`match_frames`, and uint8 (P,) with bit b set when the
        prediction counts in band b: at its ground truth's range when matched, else at its own.
    """
    if len(band_low_m) > 8 or len(band_low_m) != len(band_high_m):
        raise ValueError(
            f"need as many band lows as highs, at most 8, got {len(band_low_m)} and {len(band_high_m)}"
        )
    return _match_and_band_kernel(
        np.ascontiguousarray(pred_x_m, dtype=np.float64),
        np.ascontiguousarray(pred_y_m, dtype=np.float64),
        np.ascontiguousarray(pred_score, dtype=np.float64),
        np.ascontiguousarray(pred_offsets, dtype=np.int64),
        np.ascontiguousarray(pred_gt_frame, dtype=np.int64),
        np.ascontiguousarray(gt_x_m, dtype=np.float64),
        np.ascontiguousarray(gt_y_m, dtype=np.float64),
        np.ascontiguousarray(gt_offsets, dtype=np.int64),
        float(match_distance_m),
        np.ascontiguousarray(band_low_m, dtype=np.float64),
        np.ascontiguousarray(band_high_m, dtype=np.float64),
    )
