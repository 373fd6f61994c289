"""The shared detection chain and the CFAR baseline.

Physics: a point target simulated sample by sample (``beat_signal_exact``) comes back as a point at
its true place; hand-computed clusters, offsets and scores; on a tiny simulated dataset the CFAR
baseline's predictions are accepted by the official evaluator with every frame of the split.
"""

from __future__ import annotations

import dataclasses

import json
import math

import numpy as np
import pytest

from tests.detection.chain_helpers import T0_NS, driving_poses, parked_poses, radar_calibration, radar_params, sar_frames, simulate_cube
from zendar_baselines.classical.cfar_baseline import cfar_predictions
from zendar_dataset.detection import (
    ChainParams,
    CubePoints,
    FramePoints,
    RadarCells,
    cfar_cells,
    cube_points,
    cube_power,
    frame_detections,
    probability_peaks,
    to_frame,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate
from zendar_dataset.format.ground_truth import ground_truth_frames
from zendar_dataset.geometry.se3 import SE3
from zendar_dataset.sim.generate import synthesize_dataset

MOUNT_YAW_RAD = math.radians(30.0)
MOUNT_M = (1.0, 0.5, 0.6)


def test_a_simulated_point_target_lands_where_it_was_with_its_radial_velocity():
    params = radar_params(n_samples=128)  # 24 m reach
    calibration = radar_calibration(params, MOUNT_YAW_RAD, MOUNT_M)
    range_m, azimuth_rad = 18.0, math.radians(10.0)
    direction = np.array([math.cos(azimuth_rad), math.sin(azimuth_rad), 0.0])
    speed_mps = 2 * params.doppler_bin_mps  # receding at exactly two Doppler bins
    cube = simulate_cube(params, range_m * direction, speed_mps * direction, [1.0], noise=1e-2)
    cells = cfar_cells(cube)
    strongest = int(np.argmax(cells.score))
    poses = parked_poses()
    points = cube_points(cube, cells, T0_NS, calibration, poses, sar_frames())
    mount = SE3.from_wxyz(calibration["rotation_wxyz"], MOUNT_M)
    expected_ego = mount.transform_points((range_m * direction)[None])[0]
    # Within half a range bin along the line of sight and 0.5 deg across it.
    assert np.linalg.norm(points.points_ego[strongest] - expected_ego) < math.hypot(params.range_bin_m / 2, range_m * math.radians(0.5))
    assert points.residual_mps[strongest] == pytest.approx(speed_mps, abs=1e-6)  # a parked radar: all Doppler is the target's
    assert cells.doppler_bin[strongest] == cube.shape[1] // 2 + 2
    # No SAR image: nothing can be confirmed static, nothing is called dynamic.
    assert np.isnan(points.sar_db).all() and not points.dynamic.any()


def test_an_array_that_is_not_symmetric_places_a_point_target_too():
    # An imported radar's antennas need not be symmetric about their centre (no forward-backward
    # averaging then); the target still lands where it was.
    params = radar_params(n_samples=128)
    rx = params.rx_positions_m.copy()
    rx[:, 1] = np.array([0.0, 0.5, 1.5, 1.8]) * params.wavelength_m
    params = dataclasses.replace(params, rx_positions_m=rx)
    calibration = radar_calibration(params, MOUNT_YAW_RAD, MOUNT_M)
    range_m, azimuth_rad = 15.0, math.radians(-12.0)
    direction = np.array([math.cos(azimuth_rad), math.sin(azimuth_rad), 0.0])
    cube = simulate_cube(params, range_m * direction, 0.0 * direction, [1.0], noise=1e-2)
    cells = cfar_cells(cube)
    strongest = int(np.argmax(cells.score))
    points = cube_points(cube, cells, T0_NS, calibration, parked_poses(), sar_frames())
    expected_ego = SE3.from_wxyz(calibration["rotation_wxyz"], MOUNT_M).transform_points((range_m * direction)[None])[0]
    assert np.linalg.norm(points.points_ego[strongest] - expected_ego) < math.hypot(params.range_bin_m / 2, range_m * math.radians(0.5))


def _cube_points(poses, points_ego, residual_mps, radar_ego=(0.0, 0.0, 0.0)) -> CubePoints:
    n = len(points_ego)
    return CubePoints(T0_NS, poses.ecef_T_ego(T0_NS), np.asarray(radar_ego, float), np.zeros(n, np.int64), np.zeros(n, np.int64),
                      np.asarray(points_ego, float), np.ones(n), np.asarray(residual_mps, float), np.zeros(n), np.ones(n, bool))


def test_points_move_to_the_frame_along_their_line_of_sight_by_their_radial_velocity():
    poses = parked_poses()
    points = _cube_points(poses, [(20.0, 0.0, 0.0), (0.0, -10.0, 0.0), (15.0, 5.0, 0.0)], [10.0, -4.0, 0.0])
    moved = to_frame(points, poses, T0_NS + 100_000_000)
    np.testing.assert_allclose(moved.points_xy, [(21.0, 0.0), (0.0, -9.6), (15.0, 5.0)], atol=1e-6)
    np.testing.assert_allclose(moved.radar_xy, np.zeros((3, 2)), atol=1e-6)


def test_static_points_keep_their_place_in_the_world_while_the_ego_drives_and_turns():
    speed_mps, yaw_rate_rad_s = 10.0, 0.2
    poses = driving_poses(speed_mps, yaw_rate_rad_s)
    points = _cube_points(poses, [(20.0, 0.0, 0.0), (5.0, 3.0, 0.0)], [0.0, 0.0], radar_ego=(2.0, 1.0, 0.0))
    moved = to_frame(points, poses, T0_NS + 100_000_000)
    # 0.1 s later the ego is 1 m further along x, turned by 0.02 rad: p_frame = R(-yaw) (p - (1, 0)).
    yaw = 0.1 * yaw_rate_rad_s
    back = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]])
    expected = (np.array([(20.0, 0.0), (5.0, 3.0), (2.0, 1.0)]) - [0.1 * speed_mps, 0.0]) @ back.T
    np.testing.assert_allclose(moved.points_xy, expected[:2], atol=1e-6)
    np.testing.assert_allclose(moved.radar_xy, np.repeat(expected[2:], 2, axis=0), atol=1e-6)


def test_one_detection_per_cluster_with_dynamic_points_pushed_along_the_line_of_sight():
    points = FramePoints(
        points_xy=np.array([(20.0, 0.5), (20.0, -0.5), (40.0, 10.0), (40.5, 10.0), (10.0, -10.0), (10.5, -10.0)]),
        radar_xy=np.zeros((6, 2)),
        score=np.array([1.0, 3.0, 2.0, 5.0, 7.0, 7.0]),
        sar_db=np.zeros(6),
        dynamic=np.array([True, True, True, False, False, False]),
    )
    detections = frame_detections(points, ChainParams(centre_offset_m=2.0))
    assert len(detections) == 2  # the all-static cluster gives none
    by_x = sorted(detections, key=lambda d: d["x"])
    centre = np.array([20.0, -0.25])  # score-weighted: (1 * 0.5 + 3 * -0.5) / 4
    expected = centre + 2.0 * centre / np.linalg.norm(centre)
    assert (by_x[0]["x"], by_x[0]["y"]) == pytest.approx(tuple(expected))
    assert by_x[0]["score"] == pytest.approx(4.0)  # all dynamic: summed score
    centre = np.array([40.0, 10.0])  # only the dynamic point places the mixed cluster
    expected = centre + 2.0 * centre / np.linalg.norm(centre)
    assert (by_x[1]["x"], by_x[1]["y"]) == pytest.approx(tuple(expected))
    assert by_x[1]["score"] == pytest.approx(2.0 * 0.5)  # half its points dynamic
    assert frame_detections(FramePoints.concatenate([])) == []


def test_with_ahead_only_detections_beside_or_behind_the_front_bumper_are_dropped():
    """Labels that hold only cars whose centre is ahead of the front bumper (x > 0, the simulator's)
    never hold a car passing beside the ego, so its detection would be a false positive: with
    ``ahead_only`` the chain drops it. The test is on the corrected centre: a cluster just behind the
    bumper, pushed ahead along its line of sight from a radar at the back, is kept. By default (labels
    of unknown region) every detection is kept."""
    radar = np.array([[-4.0, 0.0]])
    points = FramePoints(
        points_xy=np.array([(20.0, 0.0), (-1.0, 3.0), (-1.0, -3.0), (-0.5, 0.0)]), radar_xy=np.repeat(radar, 4, axis=0),
        score=np.ones(4), sar_db=np.zeros(4), dynamic=np.ones(4, bool),
    )
    params = ChainParams(centre_offset_m=1.0)
    kept = frame_detections(points, dataclasses.replace(params, ahead_only=True))
    assert sorted(round(d["x"], 6) for d in kept) == [0.5, 21.0]  # (-0.5, 0) moves 1 m along +x; the two beside are dropped
    assert len(frame_detections(points, params)) == 4
    assert ChainParams().to_json()["ahead_only"] is False


def test_probability_peaks_are_the_local_maxima_above_the_floor_with_doppler_wrapping_round():
    probability = np.full((8, 6), 0.01)
    probability[1, 2], probability[1, 3], probability[2, 2] = 0.9, 0.6, 0.7  # one blob: one peak
    probability[5, 0], probability[5, 5] = 0.4, 0.8  # neighbours across the Doppler wrap: (5, 5) only
    probability[7, 3] = 0.05  # an isolated peak at the floor
    probability[3, 5] = 0.04  # an isolated peak below it
    cells = probability_peaks(probability, floor=0.05)
    assert list(zip(cells.range_bin.tolist(), cells.doppler_bin.tolist())) == [(1, 2), (5, 5), (7, 3)]
    assert cells.score.tolist() == [0.9, 0.8, 0.05]
    assert len(probability_peaks(probability, floor=0.95)) == 0


def test_a_clusters_max_score_does_not_grow_with_its_size_while_a_sum_would():
    def cluster_score(n_points: int, cluster_score: str) -> float:
        points = FramePoints(
            points_xy=np.stack([20.0 + 0.5 * np.arange(n_points), np.zeros(n_points)], axis=1), radar_xy=np.zeros((n_points, 2)),
            score=np.r_[0.9, np.full(n_points - 1, 0.6)], sar_db=np.zeros(n_points), dynamic=np.ones(n_points, bool),
        )
        (detection,) = frame_detections(points, ChainParams(cluster_score=cluster_score))
        return detection["score"]

    assert [cluster_score(n, "max") for n in (1, 2, 5, 20)] == [0.9] * 4
    assert cluster_score(20, "sum") == pytest.approx(0.9 + 19 * 0.6)


def test_bad_inputs_raise_named_errors():
    with pytest.raises(ZendarError, match=r"probability must be \[R, D\]"):
        probability_peaks(np.zeros(5), floor=0.1)
    with pytest.raises(ZendarError, match="RadarCells"):
        RadarCells(np.zeros(3, np.int64), np.zeros(2, np.int64), np.zeros(3))
    with pytest.raises(ZendarError, match="complex range-Doppler cube"):
        cube_power(np.zeros((4, 4, 2)))
    with pytest.raises(ZendarError, match="cluster_eps_m"):
        ChainParams(cluster_eps_m=0.0)
    with pytest.raises(ZendarError, match="cluster_score must be one of"):
        ChainParams(cluster_score="mean")


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("chain") / "tiny"
    synthesize_dataset(root, "tiny", n_scenes=3, seed=5, split_ratios=(1, 1, 1), progress=False)
    return root


def test_the_cfar_baseline_predicts_every_frame_of_the_split_in_the_evaluators_format(tiny_root):
    predictions = cfar_predictions(tiny_root, "test", progress=False)
    json.dumps(predictions)  # a JSON document
    frames = ground_truth_frames(tiny_root, "test")
    assert set(predictions["results"]) == set(frames)
    assert predictions["meta"]["parameters"]["centre_offset_m"] == ChainParams().centre_offset_m
    metrics = evaluate(predictions, tiny_root, split="test")
    print("CFAR baseline AP on a tiny test split:", json.dumps(metrics["ap"]))
    assert metrics["ap"]["all"] > 0.0
    assert metrics["n_frames"] == len(frames)
