"""Distinct labelled cars per band, against hand-made label tables whose answers are worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.car_counts import SceneLabels, count_distinct_cars, track_motion_kinds


def table(rows):
    """Label arrays from ``(timestamp_ns, x, y, yaw, track_id)`` rows."""
    t, x, y, yaw, track = (np.array(column) for column in zip(*rows))
    return {"timestamp_ns": t.astype(np.int64), "x": x.astype(float), "y": y.astype(float), "yaw": yaw.astype(float),
            "track_id": track.astype(np.int64)}


# Scene a: track 1 at 10 m then 20 m (near and mid), track 2 at 14.99 m and 15.0 m (near, then mid: the bands are
# half-open), track 3 at 40 m in two frames, track 4 at 60 m (in no band).
SCENE_A = table([
    (1, 6.0, 8.0, 0.0, 1), (2, 12.0, 16.0, 0.0, 1),
    (1, 14.99, 0.0, np.pi, 2), (2, 9.0, 12.0, np.pi, 2),
    (1, 40.0, 0.0, np.pi / 2, 3), (2, 0.0, 40.0, np.pi / 2, 3),
    (1, 60.0, 0.0, 0.0, 4),
])
# Scene b reuses track ids 1 and 3: different cars (a car is a scene and a track).
SCENE_B = table([(5, 3.0, 4.0, 0.0, 1), (5, 30.0, 0.0, 0.0, 3)])


def test_a_car_counts_once_per_band_it_is_labelled_in():
    counts = count_distinct_cars([SceneLabels("a", SCENE_A), SceneLabels("b", SCENE_B)])
    assert counts.cars == {"near": 3, "mid": 2, "far": 2, "all": 5}  # track 4 (60 m) in none
    assert counts.label_rows == {"near": 3, "mid": 2, "far": 3, "all": 8}
    assert counts.by_kind["near"] == {"unknown": 3}  # no ego headings given
    assert counts.shortfall(3, ("near", "mid", "far")) == {"mid": 2, "far": 2}


def test_kept_rows_alone_count():
    keep = SCENE_A["timestamp_ns"] == 2  # the second frame of scene a only
    counts = count_distinct_cars([SceneLabels("a", SCENE_A, keep=keep)])
    # Frame 2: track 1 at 20 m (mid), track 2 at 15 m (mid), track 3 at 40 m (far).
    assert counts.cars == {"near": 0, "mid": 2, "far": 1, "all": 3}


def test_kinds_from_headings_relative_to_the_ego_and_over_ground():
    # The ego's heading over ground: 0 at t=1, 0.3 rad at t=2 (a gentle curve).
    labels = table([
        (1, 10.0, 0.0, 0.1, 1), (2, 10.0, 0.0, -0.1, 1),                  # ground 0.1 -> 0.2, with the ego: ahead
        (1, 20.0, 3.0, np.pi - 0.1, 2), (2, 20.0, 3.0, -np.pi + 0.1, 2),  # opposite (wraps at pi): oncoming
        (1, 20.0, 5.0, np.pi / 2, 3), (2, 20.0, 5.0, np.pi / 2, 3),      # across, ground pi/2 -> pi/2 + 0.3: crossing
        (1, 25.0, 0.0, 0.0, 4), (2, 25.0, 0.0, np.pi / 2 - 0.3, 4),      # ground 0 -> pi/2: turning
        (1, 30.0, 0.0, 0.0, 5), (2, 30.0, 0.0, -0.3, 5),                 # ground 0 throughout, 0.3 off the ego: ahead
    ])
    ego_yaw = np.where(labels["timestamp_ns"] == 1, 0.0, 0.3)
    kinds = track_motion_kinds(labels, ego_yaw)
    assert kinds == {1: "ahead", 2: "oncoming", 3: "crossing", 4: "turning", 5: "ahead"}
    counts = count_distinct_cars([SceneLabels("s", labels, ego_yaw)])
    assert counts.by_kind["all"] == {"ahead": 2, "oncoming": 1, "crossing": 1, "turning": 1}
    assert counts.by_kind["near"] == {"ahead": 1}


def test_misshapen_keep_is_refused():
    with pytest.raises(ZendarError, match=r"a: keep: expected one entry per label row \(7\)"):
        count_distinct_cars([SceneLabels("a", SCENE_A, keep=np.ones(3, bool))])
