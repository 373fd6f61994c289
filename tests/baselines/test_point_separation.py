"""The chain fit's point separation: ROC AUC overall and per range band, counted by hand (Mann-Whitney)."""

from __future__ import annotations

import numpy as np
import pytest
from zendar_baselines.classical.chain_fit import separation_auc, separation_of


def test_the_auc_per_band_counts_the_pairs_each_band_orders_right():
    separation = separation_of(
        #  near: on-car darker than the rest | mid: on-car brighter | far: ties | beyond 60 m | no image
        sar_db=[0.0, 1.0, 5.0, 6.0, 9.0, 3.0, 4.0, 4.0, -9.0, 2.0, np.nan],
        on_car=[1, 1, 0, 0, 1, 0, 1, 0, 1, 0, 1],
        range_m=[3.0, 14.9, 8.0, 10.0, 15.0, 29.0, 30.0, 59.0, 70.0, 61.0, 5.0],
    )
    assert separation["auc_per_band"] == {"near": 1.0, "mid": 0.0, "far": 0.5}
    assert separation["points_per_band"] == {"near": {"on_car": 2, "other": 2}, "mid": {"on_car": 1, "other": 1},
                                             "far": {"on_car": 1, "other": 1}}
    # Overall (every finite value, beyond 60 m included): 5 on-car x 5 other pairs, an on-car value below
    # the other's counts 1, a tie 1/2.
    on = np.array([0.0, 1.0, 9.0, 4.0, -9.0])
    off = np.array([5.0, 6.0, 3.0, 4.0, 2.0])
    by_hand = ((on[:, None] < off[None, :]).sum() + 0.5 * (on[:, None] == off[None, :]).sum()) / (on.size * off.size)
    assert separation["auc"] == pytest.approx(by_hand)


def test_a_band_without_on_car_points_has_no_auc_and_the_youden_threshold_cuts_a_clean_split():
    separation = separation_of(sar_db=[0.0, 1.0, 5.0, 6.0, 7.0], on_car=[1, 1, 0, 0, 0], range_m=[5.0, 6.0, 7.0, 20.0, 40.0])
    assert separation["auc_per_band"] == {"near": 1.0, "mid": None, "far": None}
    assert separation["auc"] == 1.0
    assert separation["youden_threshold_db"] == 1.0  # every on-car point at or below it, no other point
    assert separation_auc(np.array([True, False]), np.array([np.nan, 1.0])) is None
