"""The compiled fast paths against the plain numpy formulation of the same step."""

import numpy as np
import pytest

from zendar_dataset.eval.ap import average_precision, band_steps, curve_from_steps
from zendar_dataset.eval.matching import match_and_band, match_frame
from zendar_dataset.eval.protocol import BANDS_M


@pytest.mark.parametrize("n_distinct", [3, 1000, None])
def test_band_steps_equal_a_mask_and_sort_per_band(n_distinct):
    rng = np.random.default_rng(n_distinct or 0)
    n = 5000
    score = rng.random(n) if n_distinct is None else rng.integers(0, n_distinct, n) / n_distinct
    score[::7] = -score[::7]  # negative scores are scores too
    is_tp = rng.random(n) < 0.4
    bits = rng.integers(0, 16, n).astype(np.uint8)
    for b, (step_score, tp_cumulative, fp_cumulative) in enumerate(band_steps(score, is_tp, bits, 4)):
        in_band = (bits >> b) & 1 == 1
        n_gt = int(is_tp[in_band].sum()) + 3
        expected_ap, expected = average_precision(score[in_band], is_tp[in_band], n_gt)
        ap, curve = curve_from_steps(step_score, tp_cumulative, fp_cumulative, n_gt)
        assert ap == expected_ap
        np.testing.assert_array_equal(curve.score, expected.score)
        np.testing.assert_array_equal(curve.recall, expected.recall)
        np.testing.assert_array_equal(curve.precision_envelope, expected.precision_envelope)
        assert tp_cumulative[-1] == is_tp[in_band].sum()
        assert fp_cumulative[-1] == (~is_tp[in_band]).sum()


def test_band_steps_with_an_empty_band():
    steps = band_steps(np.array([0.5, 0.2]), np.array([True, False]), np.array([1, 0], np.uint8), 2)
    assert steps[0][0].tolist() == [0.5] and steps[0][1].tolist() == [1] and steps[0][2].tolist() == [0]
    assert [len(a) for a in steps[1]] == [0, 0, 0]


def test_match_and_band_agree_with_the_readable_rule_and_numpy_bands():
    rng = np.random.default_rng(5)
    n_frames, per_frame = 60, 60  # over 32 candidates in a frame takes the mergesort branch
    gt_counts = rng.integers(0, 50, n_frames)
    gt_offsets = np.concatenate([[0], np.cumsum(gt_counts)])
    gt_xy = np.round(rng.uniform(-65, 65, (gt_offsets[-1], 2)) * 2) / 2
    pred_offsets = np.arange(n_frames + 1) * per_frame
    pred_xy = np.round(rng.uniform(-65, 65, (pred_offsets[-1], 2)) * 2) / 2
    for f in range(n_frames):  # most predictions near some ground truth, on the 0.5 m grid
        if gt_counts[f]:
            near = rng.integers(gt_offsets[f], gt_offsets[f + 1], per_frame)
            pred_xy[pred_offsets[f] : pred_offsets[f + 1]] = gt_xy[near] + rng.integers(-4, 5, (per_frame, 2)) * 0.5
    score = rng.integers(0, 4, len(pred_xy)) / 4.0
    low = np.array([b[0] for b in BANDS_M.values()])
    high = np.array([b[1] for b in BANDS_M.values()])
    matched, bits = match_and_band(
        pred_xy[:, 0], pred_xy[:, 1], score, pred_offsets, np.arange(n_frames),
        gt_xy[:, 0], gt_xy[:, 1], gt_offsets, low, high,
    )
    for f in range(n_frames):
        rows = slice(pred_offsets[f], pred_offsets[f + 1])
        local = match_frame(pred_xy[rows], score[rows], gt_xy[gt_offsets[f] : gt_offsets[f + 1]])
        expected = np.where(local >= 0, local + gt_offsets[f], -1)
        np.testing.assert_array_equal(matched[rows], expected)
    where = np.where((matched >= 0)[:, None], gt_xy[np.maximum(matched, 0)], pred_xy)
    r = np.sqrt(where[:, 0] ** 2 + where[:, 1] ** 2)
    expected_bits = sum(((r >= lo) & (r < hi)).astype(np.uint8) << b for b, (lo, hi) in enumerate(zip(low, high)))
    np.testing.assert_array_equal(bits, expected_bits)
    assert (matched >= 0).sum() > 100
