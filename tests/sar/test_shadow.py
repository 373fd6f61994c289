"""The radar's shadow from the lidar, against the simulator's own geometry.

A street with a building's facade beside it, a moving car between the facade and the ego, and a
parked car: the simulator's multipath model (:func:`zendar_dataset.sim.multipath.ghost_pairs`, plane
mirrors) places the car's ghosts behind the facade, its ray caster gives the lidar sweep and which of
the car's scatterers the radar sees. Every ghost must lie in the shadow the lidar measures, every
scatterer the radar sees must not.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.detection.chain_helpers import T0_NS, LidarReader, driving_poses
from zendar_dataset.detection.static_scene import DEFAULT_SHADOW_MARGIN_M
from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.occlusion import hidden_behind_obstacles
from zendar_dataset.sar.shadow import MAX_SWEEP_GAP_NS, OBSTACLE_HEIGHTS_M, SHADOW_BIN_RAD, RadarShadow
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.multipath import ghost_pairs, mirror_points, mirrors_from_boxes
from zendar_dataset.sim.profiles import PROFILES
from zendar_dataset.sim.raycast import line_of_sight
from zendar_dataset.sim.world import COLORS, BoxSet

LIDAR_ENU = np.array([0.0, 0.0, 1.9])
RADAR_ENU = np.array([0.5, 0.85, 0.5])
MARGIN_M = DEFAULT_SHADOW_MARGIN_M


def _boxes(*boxes) -> BoxSet:
    centres, sizes, colors = zip(*boxes)
    return BoxSet(np.array(centres, float), np.array(sizes, float), np.zeros(len(boxes)),
                  np.array([COLORS[c] for c in colors], np.uint8), np.full(len(boxes), -1, np.int64))


@pytest.fixture(scope="module")
def street():
    boxes = _boxes(
        ((30.0, 13.0, 5.0), (40.0, 10.0, 10.0), "building"),  # its facade: the plane y = 8 m, x in [10, 50]
        ((25.0, 4.5, 0.75), (4.5, 1.8, 1.5), "car"),  # moving, between the facade and the ego
        ((16.0, -4.0, 0.75), (4.5, 1.8, 1.5), "car"),  # parked across the road
    )
    points_lidar, _ = lidar_sweep(np.random.default_rng(0), np.eye(3), LIDAR_ENU, boxes, PROFILES["demo"].lidar_azimuth_step_deg)
    lidar_enu = points_lidar[:, :3].astype(np.float64) + LIDAR_ENU
    # The moving car's scatterers: its corners and the middles of its faces, at bumper height.
    x0, x1, y0, y1 = 22.75, 27.25, 3.6, 5.4
    car = np.array([(x, y, 0.5) for x in (x0, 25.0, x1) for y in (y0, 4.5, y1) if (x, y) != (25.0, 4.5)])
    mirrors = mirrors_from_boxes(boxes, Imperfections())
    face, point = ghost_pairs(mirrors, RADAR_ENU, car)
    ghosts = mirror_points(car[point], mirrors.center_enu[face], mirrors.normal[face])
    seen = line_of_sight(RADAR_ENU, car, boxes, owner_box=np.full(len(car), 1))
    return lidar_enu, car, seen, ghosts


def _obstacles(lidar_enu: np.ndarray) -> np.ndarray:
    low, high = OBSTACLE_HEIGHTS_M
    return lidar_enu[(lidar_enu[:, 2] > low) & (lidar_enu[:, 2] < high), :2]


def test_the_simulators_ghosts_lie_in_the_shadow_and_the_car_it_sees_does_not(street):
    lidar_enu, car, seen, ghosts = street
    assert len(ghosts) >= 4 and np.all(ghosts[:, 1] > 8.0)  # mirrored behind the facade
    assert seen.sum() >= 4
    obstacles = _obstacles(lidar_enu)
    assert hidden_behind_obstacles(ghosts[:, :2], RADAR_ENU[:2], obstacles, margin_m=MARGIN_M, bin_rad=SHADOW_BIN_RAD).all()
    assert not hidden_behind_obstacles(car[seen, :2], RADAR_ENU[:2], obstacles, margin_m=MARGIN_M, bin_rad=SHADOW_BIN_RAD).any()


def test_a_point_is_hidden_only_beyond_the_margin_and_behind_every_neighbouring_bin():
    wall = np.column_stack([np.linspace(-20.0, 20.0, 2001), np.full(2001, 10.0)])
    viewpoint = np.zeros(2)

    def hidden(points, obstacles=wall, margin_m=1.0):
        return hidden_behind_obstacles(np.array(points, float), viewpoint, obstacles, margin_m=margin_m, bin_rad=SHADOW_BIN_RAD)

    np.testing.assert_array_equal(hidden([(0.0, 5.0), (0.0, 10.5), (0.0, 11.5), (5.0, 30.0), (60.0, 20.0)]),
                                  [False, False, True, True, False])  # before, within the margin, behind, behind, past its end
    np.testing.assert_array_equal(hidden([(0.0, 10.5)], margin_m=0.0), [True])
    pole = np.array([[0.0, 10.0]])  # one obstacle: its neighbouring bins are open, it hides nothing
    assert not hidden([(0.0, 20.0)], obstacles=pole).any()
    behind = np.column_stack([np.full(201, -10.0), np.linspace(-2.0, 2.0, 201)])  # azimuth ±180°: the bins wrap
    np.testing.assert_array_equal(hidden([(-15.0, 0.01), (-15.0, -0.01), (15.0, 0.0)], obstacles=behind), [True, True, False])
    assert hidden(np.zeros((0, 2))).shape == (0,) and not hidden([(0.0, 30.0)], obstacles=np.zeros((0, 2))).any()


def test_bad_arguments_are_named_all_at_once():
    with pytest.raises(ZendarError, match=r"points_xy must be \[N, 2\].*obstacles_xy must be \[M, 2\].*viewpoint_xy.*margin_m.*bin_rad"):
        hidden_behind_obstacles(np.zeros((3, 3)), np.zeros(3), np.zeros(4), margin_m=-1.0, bin_rad=0.0)


@pytest.mark.parametrize("speed_mps, yaw_rate_rad_s, lidar_yaw_rad, gap_ns", [
    (0.0, 0.0, 0.0, 0),  # parked, the lidar along the ego's axes, asked at the sweep's time
    (10.0, 1.0, np.pi / 2, 100_000_000),  # driving and turning, the lidar turned 90°, asked 100 ms after the sweep
])
def test_the_shadow_of_a_scene_reads_its_lidar_in_the_ego_frame_and_needs_a_sweep_near_the_time(
        street, speed_mps, yaw_rate_rad_s, lidar_yaw_rad, gap_ns):
    """The street in the ego frame at the sweep's time (``driving_poses`` starts with the ego's axes
    along ECEF's), the sweep stored in the lidar's own frame (turned 90° on the second ego), the points
    asked about in ECEF, the radar where it is when asked (1 m further and 5.7° turned on the second
    ego). A lidar frame read as the ego's would put the facade beside the ego: no ghost hidden."""
    lidar_enu, car, seen, ghosts = street
    poses = driving_poses(speed_mps, yaw_rate_rad_s)
    c, s = np.cos(lidar_yaw_rad), np.sin(lidar_yaw_rad)
    in_lidar_frame = (lidar_enu - LIDAR_ENU) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # R(yaw)ᵀ · p
    shadow = RadarShadow.of(LidarReader(in_lidar_frame, LIDAR_ENU, lidar_yaw_rad, poses))
    asked_ns = T0_NS + gap_ns
    radar_ecef = poses.ego_to_ecef(RADAR_ENU[None], asked_ns)[0]
    asked = np.concatenate([ghosts, car[seen]])
    hidden = shadow.hidden(poses.ego_to_ecef(asked, T0_NS), radar_ecef, asked_ns, MARGIN_M)
    np.testing.assert_array_equal(hidden, np.arange(len(asked)) < len(ghosts))
    far_in_time = T0_NS + MAX_SWEEP_GAP_NS + 1
    assert not shadow.hidden(poses.ego_to_ecef(ghosts, T0_NS), radar_ecef, far_in_time, MARGIN_M).any()
    assert RadarShadow.of(type("NoLidar", (), {"sensors": lambda self, group: []})()) is None
