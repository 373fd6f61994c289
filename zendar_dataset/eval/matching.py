"""Center-distance matching of predictions to ground truth, once per frame over all ranges.

:func:`match_frame` states the rule in a few readable lines; :func:`match_frames` is the same rule
for many frames at once, compiled with numba because greedy matching is sequential within a frame
(each prediction's choice depends on the ones before it) and cannot be written as array operations
without quadratic memory.
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
def _stable_descending_order(score):
    # Equal scores keep their list order. Insertion sort for the usual handful of detections
    # (no allocation beyond the result); mergesort, which is stable, for longer lists.
    n = len(score)
    if n > 32:
        return np.argsort(-score, kind="mergesort")
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        j = i
        while j > 0 and score[order[j - 1]] < score[i]:
            order[j] = order[j - 1]
            j -= 1
        order[j] = i
    return order


@numba.njit(cache=True, nogil=True)
def _match_frames_kernel(
    pred_x, pred_y, pred_score, pred_offsets, pred_gt_frame, gt_x, gt_y, gt_offsets, match_distance_m
):
    matched = np.full(len(pred_x), -1, dtype=np.int64)
    taken = np.zeros(len(gt_x), dtype=np.bool_)
    for f in range(len(pred_offsets) - 1):
        p_start = pred_offsets[f]
        g_start = gt_offsets[pred_gt_frame[f]]
        g_stop = gt_offsets[pred_gt_frame[f] + 1]
        if g_start == g_stop or p_start == pred_offsets[f + 1]:
            continue
        by_score = _stable_descending_order(pred_score[p_start : pred_offsets[f + 1]])
        for k in range(len(by_score)):
            p = p_start + by_score[k]
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
    return matched


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
    return _match_frames_kernel(
        np.ascontiguousarray(pred_x_m, dtype=np.float64),
        np.ascontiguousarray(pred_y_m, dtype=np.float64),
        np.ascontiguousarray(pred_score, dtype=np.float64),
        np.ascontiguousarray(pred_offsets, dtype=np.int64),
        np.ascontiguousarray(pred_gt_frame, dtype=np.int64),
        np.ascontiguousarray(gt_x_m, dtype=np.float64),
        np.ascontiguousarray(gt_y_m, dtype=np.float64),
        np.ascontiguousarray(gt_offsets, dtype=np.int64),
        float(match_distance_m),
    )
