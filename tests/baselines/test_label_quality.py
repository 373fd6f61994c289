"""Label-quality figures on hand-made masks whose answers are counted by hand."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError

from zendar_baselines.labels.quality import combine_quality, format_quality, mask_quality
from zendar_baselines.labels.mask_classes import MOVING, UNCERTAIN

# One frame, 8 range bins x 8 Doppler bins; the last bin (70 m) is in no band.
RANGE_M = np.array([5.0, 10.0, 14.0, 16.0, 20.0, 29.0, 35.0, 70.0])


def hand_made_masks() -> tuple[np.ndarray, np.ndarray]:
    """Label segments L1 (near), L2, L3 (mid); automatic segments A1 (near), A2, A5 (mid), A3 (far), A4 (70 m).

    ::

        row  range   label                     automatic
        0     5 m    L1 (0,0) (0,1)
        1    10 m    L1 (1,0) (1,1)            A1 (1,1)
        2    14 m    L3 (2,6)                  A1 (2,1)
        3    16 m    L3 (3,6)                  A2 (3,3) (3,4); A5 (3,6)
        4    20 m    L2 (4,3) (4,4); U (4,5)   U (4,3)
        5    29 m                              U (5,7)
        6    35 m                              A3 (6,0)
        7    70 m                              A4 (7,2)
    """
    label = np.zeros((1, 8, 8), np.uint8)
    auto = np.zeros((1, 8, 8), np.uint8)
    for r, d in [(0, 0), (0, 1), (1, 0), (1, 1), (2, 6), (3, 6), (4, 3), (4, 4)]:
        label[0, r, d] = MOVING
    label[0, 4, 5] = UNCERTAIN
    for r, d in [(1, 1), (2, 1), (3, 3), (3, 4), (3, 6), (6, 0), (7, 2)]:
        auto[0, r, d] = MOVING
    auto[0, 4, 3] = UNCERTAIN
    auto[0, 5, 7] = UNCERTAIN
    return auto, label


# Counted by hand from the figure above.
#   near rows 0-2: TP (1,1); FP (2,1); FN (0,0) (0,1) (1,0) (2,6).
#   mid rows 3-5: TP (3,6); FP (3,3) (3,4); FN (4,4); excluded (4,3) auto U, (4,5) label U, (5,7) auto U.
#   far row 6: FP (6,0).
#   Segments by mean range: L1 7.5 m near, found via (1,1); L3 15 m mid, found via (3,6); L2 20 m mid, not
#   found ((4,3) is UNCERTAIN, (4,4) BACKGROUND). A1 12 m near matched; A2 16 m and A5 16 m mid, only A5
#   matched; A3 35 m far unmatched; A4 70 m in no band.
EXPECTED_COUNTS = {
    "near": dict(cells=24, uncertain_cells=0, excluded_cells=0, tp_cells=1, fp_cells=1, fn_cells=4,
                 label_segments=1, label_segments_found=1, auto_segments=1, auto_segments_matched=1),
    "mid": dict(cells=24, uncertain_cells=2, excluded_cells=3, tp_cells=1, fp_cells=2, fn_cells=1,
                label_segments=2, label_segments_found=1, auto_segments=2, auto_segments_matched=1),
    "far": dict(cells=8, uncertain_cells=0, excluded_cells=0, tp_cells=0, fp_cells=1, fn_cells=0,
                label_segments=0, label_segments_found=0, auto_segments=1, auto_segments_matched=0),
    "all": dict(cells=56, uncertain_cells=2, excluded_cells=3, tp_cells=2, fp_cells=4, fn_cells=5,
                label_segments=3, label_segments_found=2, auto_segments=4, auto_segments_matched=2),
}
EXPECTED_RATIOS = {
    "near": dict(cell_precision=1 / 2, cell_recall=1 / 5, uncertain_share=0.0, object_recall=1.0, object_precision=1.0),
    "mid": dict(cell_precision=1 / 3, cell_recall=1 / 2, uncertain_share=2 / 24, object_recall=1 / 2, object_precision=1 / 2),
    "far": dict(cell_precision=0.0, cell_recall=None, uncertain_share=0.0, object_recall=None, object_precision=0.0),
    "all": dict(cell_precision=2 / 6, cell_recall=2 / 7, uncertain_share=2 / 56, object_recall=2 / 3, object_precision=2 / 4),
}


def test_hand_counted_figures_per_band() -> None:
    auto, label = hand_made_masks()
    quality = mask_quality(auto, label, RANGE_M)
    assert quality["n_frames"] == 1
    assert list(quality["bands"]) == ["near", "mid", "far", "all"]
    assert quality["bands"]["mid"]["range_m"] == [15.0, 30.0]
    for band, expected in EXPECTED_COUNTS.items():
        assert quality["bands"][band]["counts"] == expected, band
        for ratio, value in EXPECTED_RATIOS[band].items():
            assert quality["bands"][band][ratio] == (None if value is None else pytest.approx(value)), (band, ratio)


def test_segments_do_not_join_across_frames_or_diagonals() -> None:
    label = np.zeros((2, 4, 4), np.uint8)
    label[:, 1, 1] = MOVING  # the same cell in two frames: two segments
    label[0, 2, 2] = MOVING  # diagonal neighbour of (1, 1): a third segment
    auto = np.zeros_like(label)
    auto[1, 1, 1] = MOVING
    quality = mask_quality(auto, label, np.array([2.0, 4.0, 6.0, 8.0]))
    counts = quality["bands"]["near"]["counts"]
    assert counts["label_segments"] == 3 and counts["label_segments_found"] == 1
    assert counts["auto_segments"] == 1 and counts["auto_segments_matched"] == 1
    assert quality["bands"]["near"]["object_recall"] == pytest.approx(1 / 3)


def test_combining_sums_counts_before_dividing() -> None:
    auto, label = hand_made_masks()
    one = mask_quality(auto, label, RANGE_M)
    # A second "radar" where everything agrees: 3 true cells, 1 segment, in the near band.
    agree = np.zeros((2, 8, 8), np.uint8)
    agree[1, 0, 0:3] = MOVING
    other = mask_quality(agree, agree, RANGE_M)
    combined = combine_quality([one, other])
    assert combined["n_frames"] == 3
    near = combined["bands"]["near"]
    assert near["counts"]["tp_cells"] == 4 and near["counts"]["fp_cells"] == 1 and near["counts"]["fn_cells"] == 4
    assert near["counts"]["cells"] == 24 + 48
    # Pooled (4 / 5 and 4 / 8), not the mean of the per-radar ratios ((1/2 + 1) / 2 and (1/5 + 1) / 2).
    assert near["cell_precision"] == pytest.approx(4 / 5)
    assert near["cell_recall"] == pytest.approx(4 / 8)
    assert near["object_recall"] == pytest.approx(2 / 2)
    assert combine_quality([])["bands"]["all"]["cell_precision"] is None


def test_frame_blocks_add_up_like_one_pass() -> None:
    rng = np.random.default_rng(5)
    auto = rng.choice(np.array([0, 1, 2], np.uint8), size=(150, 16, 6), p=[0.8, 0.15, 0.05])
    label = rng.choice(np.array([0, 1, 2], np.uint8), size=(150, 16, 6), p=[0.8, 0.15, 0.05])
    range_m = np.linspace(0.0, 75.0, 16)
    whole = mask_quality(auto, label, range_m)
    tp = int(np.count_nonzero((auto == MOVING) & (label == MOVING) & (range_m < 60.0)[None, :, None]))
    assert whole["bands"]["all"]["counts"]["tp_cells"] == tp
    per_frame = combine_quality(mask_quality(auto[i : i + 1], label[i : i + 1], range_m) for i in range(150))
    assert per_frame == whole


def test_bad_input_lists_every_problem() -> None:
    auto = np.zeros((2, 4, 3), np.uint8)
    auto[0, 0, 0] = 3
    label = np.zeros((2, 4, 4), np.float32)
    with pytest.raises(ZendarError) as caught:
        mask_quality(auto, label, np.arange(5.0))
    message = str(caught.value)
    assert "auto_masks: expected values in [0, 1, 2], found 1 cells outside" in message
    assert "label_masks: expected integer masks (uint8), found float32" in message
    assert "one shape, found [2, 4, 3] and [2, 4, 4]" in message
    assert "range_m: expected one range per range bin [4], found shape [5]" in message


def test_table_shows_percentages_and_counts() -> None:
    auto, label = hand_made_masks()
    table = format_quality(mask_quality(auto, label, RANGE_M))
    lines = table.splitlines()
    assert lines[0] == "automatic vs label masks, 1 frames (ratios in %)"
    near = next(line for line in lines if line.startswith("near"))
    assert near.split()[3:] == ["50.0", "20.0", "0.0", "100.0", "100.0", "1", "1", "4", "1", "1"]
    far = next(line for line in lines if line.startswith("far"))
    assert far.split()[3:8] == ["0.0", "n/a", "0.0", "n/a", "0.0"]
    assert "left out" in table
