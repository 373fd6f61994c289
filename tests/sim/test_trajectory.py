"""Trajectories along the road and along curvature profiles, against circles worked by hand."""

import numpy as np
import pytest

from zendar_dataset.sim.traffic import _quarter_turn, _straight
from zendar_dataset.sim.trajectory import SAMPLE_INTERVAL_S, follow_path, follow_road, travelled_distance_m
from zendar_dataset.sim.world import Road

RADIUS_M = 40.0
SPEED_MPS = 8.0


def _circle_road() -> Road:
    """A left-turning road of constant radius: s = 0 at the origin heading east, centre at (0, R)."""
    return Road.from_curvature(-50.0, 150.0, lambda s: np.full_like(s, 1.0 / RADIUS_M))


def _on_circle(s_m: np.ndarray, lateral_m: float) -> tuple[np.ndarray, np.ndarray]:
    yaw = s_m / RADIUS_M
    east = RADIUS_M * np.sin(yaw) - lateral_m * np.sin(yaw)
    north = RADIUS_M * (1.0 - np.cos(yaw)) + lateral_m * np.cos(yaw)
    return np.stack([east, north], axis=-1), yaw


def test_travelled_distance_is_exact_for_constant_acceleration():
    time_s = np.arange(0.0, 3.0, SAMPLE_INTERVAL_S)
    np.testing.assert_allclose(travelled_distance_m(time_s, 2.0 * time_s), time_s**2, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(("lateral_m", "against_road"), [(0.0, False), (3.5, True), (-1.0, False)])
def test_follow_road_stays_on_the_offset_circle(lateral_m, against_road):
    time_s = np.arange(0.0, 5.0, SAMPLE_INTERVAL_S)
    start_s_m = 60.0
    trajectory = follow_road(
        _circle_road(), time_s, np.full_like(time_s, SPEED_MPS), start_s_m, lateral_m=lateral_m, against_road=against_road
    )
    s_m = start_s_m + (-1.0 if against_road else 1.0) * SPEED_MPS * time_s
    xy, road_yaw = _on_circle(s_m, lateral_m)
    # The road is sampled every 5 cm: the chord between samples is within 1e-5 m of the arc.
    np.testing.assert_allclose(trajectory.position_enu[:, :2], xy, atol=2e-5)
    np.testing.assert_array_equal(trajectory.position_enu[:, 2], 0.0)
    np.testing.assert_allclose(trajectory.yaw_rad, road_yaw + (np.pi if against_road else 0.0), atol=1e-6)
    np.testing.assert_array_equal(trajectory.speed_mps, SPEED_MPS)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_quarter_turn_turns_by_a_right_angle_on_its_radius(sign):
    radius_m, turn_start_m = 8.0, 5.0
    time_s = np.arange(0.0, 4.0, SAMPLE_INTERVAL_S)
    path = follow_path(time_s, np.full_like(time_s, SPEED_MPS), np.zeros(3), 0.0, _quarter_turn(turn_start_m, radius_m, sign))
    assert path.yaw_rad[-1] == pytest.approx(sign * np.pi / 2, abs=2e-3)
    # After the turn the car drives along the line x = turn start + R, offset R to its side.
    end_s_m = SPEED_MPS * time_s[-1]
    expected_end = [turn_start_m + radius_m, sign * (radius_m + end_s_m - turn_start_m - np.pi / 2 * radius_m)]
    np.testing.assert_allclose(path.position_enu[-1, :2], expected_end, atol=0.05)


def test_straight_profile_keeps_the_heading():
    time_s = np.arange(0.0, 2.0, SAMPLE_INTERVAL_S)
    path = follow_path(time_s, np.full_like(time_s, SPEED_MPS), np.array([1.0, 2.0, 0.0]), 0.5, _straight)
    np.testing.assert_array_equal(path.yaw_rad, 0.5)
    distance_m = SPEED_MPS * time_s[-1]
    np.testing.assert_allclose(path.position_enu[-1], [1.0 + distance_m * np.cos(0.5), 2.0 + distance_m * np.sin(0.5), 0.0])
