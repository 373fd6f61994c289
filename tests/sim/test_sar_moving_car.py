"""A car's point echo in a simulated SAR image: where a static car focuses and a moving one lands.

Paper §1.1.2: a moving object whose motion is not compensated is displaced in azimuth by an
amount set by its speed over the ego's. For a radar moving at ``V`` along +x, a point at angle
``θ`` from the track has range rate ``-V cos θ``; a target closing at ``v`` adds ``-v``, which the
processor (assuming a static scene) reads as the angle ``θ'`` with ``cos θ' = cos θ + v / V``, at
the same range. So the car's image lies on its range circle, rotated towards the track
(``≈ R v / (V sin θ)`` along the arc). The scene here: the ego drives straight east at 10 m/s,
one car (a single point scatterer, imperfections off) 8 m along the front-left radar's boresight
at the image time, parked or closing on the radar at 2 m/s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim import scene as scene_module
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import build_scene, simulate_sar
from zendar_dataset.sim.trajectory import Trajectory
from zendar_dataset.sim.world import BoxSet, MovingCar, ScattererSet, World

SENSOR = "front_left"
EGO_SPEED_MPS = 10.0
RANGE_M = 8.0
CLOSING_MPS = 2.0
T_IMAGE_S = 0.55
PIXEL_M = 0.1
PROFILE = dataclasses.replace(
    get_profile("tiny"),
    sar_pixel_m=PIXEL_M,
    sar_bandwidth_hz=299_792_458.0 / (2 * PIXEL_M),
    sar_aperture_m=0.4,
    sar_coverage_m=14.0,
    imperfections=Imperfections(
        road_clutter=False, multipath=False, car_aspect=False, wheel_micro_doppler=False, antenna_errors=False
    ),
)


def _straight(time_s: np.ndarray) -> Trajectory:
    position = np.zeros((time_s.size, 3))
    position[:, 0] = EGO_SPEED_MPS * time_s
    return Trajectory(time_s, position, np.zeros(time_s.size), np.full(time_s.size, EGO_SPEED_MPS))


def _radar_at_image_time() -> np.ndarray:
    """ENU position of the radar's phase centre at the image time (ego at x = V t, yaw 0)."""
    mount = ego_model.EGO_T_SENSOR[SENSOR]
    return np.array([EGO_SPEED_MPS * T_IMAGE_S, 0.0, 0.0]) + np.asarray(mount.translation)


def _car(time_s: np.ndarray, closing_mps: float) -> MovingCar:
    boresight = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0])  # the radar is yawed 45° left
    at_image = _radar_at_image_time() + RANGE_M * boresight
    at_image[2] = 0.0  # trajectories are on the ground; the scatterer sits at the radar's height
    velocity = -closing_mps * boresight
    position = at_image[None] + velocity[None] * (time_s - T_IMAGE_S)[:, None]
    yaw = np.full(time_s.size, np.arctan2(velocity[1], velocity[0]) if closing_mps else 0.0)
    trajectory = Trajectory(time_s, position, yaw, np.full(time_s.size, closing_mps))
    height = float(ego_model.EGO_T_SENSOR[SENSOR].translation[2])
    point = ScattererSet(np.array([[0.0, 0.0, height]]), np.array([10.0]), np.array([False]), np.array([0.0]))
    # A small body below the scatterer: a car's box would hide a point inside it from the radar.
    return MovingCar(1, trajectory, np.array([0.3, 0.3, 0.3]), point)


@pytest.fixture(scope="module")
def straight_truth():
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(scene_module, "follow_road", lambda road, time_s, speed, s0: _straight(np.asarray(time_s)))
        return build_scene(PROFILE, seed=0, scene_index=0)


def _peak_enu(truth, closing_mps: float) -> tuple[np.ndarray, float]:
    """ENU position of the image's brightest pixel, and its magnitude."""
    empty_boxes = BoxSet(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3), np.uint8), np.zeros(0, np.int64))
    world = World(truth.world.road, empty_boxes, ScattererSet.empty(), [_car(truth.ego.time_s, closing_mps)], [])
    scene = dataclasses.replace(truth, world=world)
    exact = truth.tracklog_truth  # the noise-free poses: only the car's motion moves its image
    tracklog = PoseInterpolator(exact.timestamp_ns, exact.position_ecef, exact.attitude_wxyz)
    image, grid_ecef, _ = simulate_sar(scene, PROFILE, SENSOR, T_IMAGE_S, np.random.default_rng(0), tracklog)
    pixels_enu = truth.enu.ecef_to_enu(grid_ecef.pixel_centers().reshape(-1, 3)).reshape(*image.shape, 3)
    # A straight track cannot tell left from right: every echo has a mirror image across the
    # track's line (y = the radar's y). Look on the car's side only.
    magnitude = np.where(pixels_enu[..., 1] > _radar_at_image_time()[1] + 0.5, np.abs(image), 0.0)
    i, j = np.unravel_index(np.argmax(magnitude), magnitude.shape)
    return pixels_enu[i, j], float(magnitude[i, j])


def test_a_parked_car_focuses_where_it_is_and_a_moving_one_is_displaced_along_its_range_circle(straight_truth):
    radar = _radar_at_image_time()
    static_enu, static_peak = _peak_enu(straight_truth, 0.0)
    moving_enu, moving_peak = _peak_enu(straight_truth, CLOSING_MPS)
    truth_enu = radar + RANGE_M * np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0])
    # Static: on its pixel (within a pixel's diagonal).
    assert np.linalg.norm((static_enu - truth_enu)[:2]) <= 1.5 * PIXEL_M
    # Moving: same range, at the angle whose range rate matches the car's (closed form above).
    theta = np.arccos(np.cos(np.pi / 4) + CLOSING_MPS / EGO_SPEED_MPS)
    expected = radar + RANGE_M * np.array([np.cos(theta), np.sin(theta), 0.0])
    shift_m = np.linalg.norm((expected - truth_enu)[:2])
    assert shift_m > 2.5  # 2.8 m: the check below tells the two cases apart by far
    assert np.linalg.norm((moving_enu - expected)[:2]) <= 2.5 * PIXEL_M, (moving_enu, expected)
    assert np.linalg.norm((moving_enu - radar)[:2]) == pytest.approx(RANGE_M, abs=1.5 * PIXEL_M)
    # Both are real echoes well above the noise floor (the same scatterer, similar focus).
    assert moving_peak > 0.3 * static_peak
