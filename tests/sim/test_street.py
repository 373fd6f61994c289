"""The simulated street is physically consistent: no two bodies ever overlap, parked cars stand in
their parking strips.  Only the world and the trajectories are built (no sensor data), so many seeds
of every profile stay cheap.  The overlap test is written here from scratch (separating axes of two
rectangles, by hand), independent of the simulator's own ``sim.bodies``."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import build_scene
from zendar_dataset.sim.world import COLORS

SEEDS = {"tiny": range(8), "demo": range(4), "paper": range(2)}
STEP_S = 0.05


def rectangles(center, size, yaw):
    """Corners [B, 4, 2] (counter-clockwise) of rectangles: centre [B, 2+], length/width [B, 2+], yaw [B]."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    along = np.concatenate([c, s], axis=1) * size[:, :1] / 2
    across = np.concatenate([-s, c], axis=1) * size[:, 1:2] / 2
    xy = center[:, :2]
    return np.stack([xy + along + across, xy - along + across, xy - along - across, xy + along - across], axis=1)


def boxes(center, size, yaw):
    """(corners [B, 4, 2], z_low [B], z_high [B]) of boxes: centre [B, 3] (z at half height), size [B, 3], yaw [B]."""
    return rectangles(center, size, yaw), center[:, 2] - size[:, 2] / 2, center[:, 2] + size[:, 2] / 2


def overlaps(first, second):
    """Pairs (i, j) whose boxes intersect: footprints by the separating-axis theorem (two convex polygons
    are disjoint iff their projections on one of the edge normals are) and height intervals."""
    ca, lo_a, hi_a = first
    cb, lo_b, hi_b = second
    a, b = ca[:, None], cb[None, :]  # [A, 1, 4, 2], [1, B, 4, 2]
    apart = (hi_a[:, None] <= lo_b[None, :]) | (hi_b[None, :] <= lo_a[:, None])
    for polygon in (a, b):
        for k in range(4):
            edge = polygon[..., (k + 1) % 4, :] - polygon[..., k, :]
            normal = np.stack([-edge[..., 1], edge[..., 0]], axis=-1)[..., None, :]  # [., ., 1, 2]
            pa, pb = np.sum(a * normal, axis=-1), np.sum(b * normal, axis=-1)  # [A, B, 4]
            apart |= (pa.max(-1) <= pb.min(-1) + 1e-9) | (pb.max(-1) <= pa.min(-1) + 1e-9)
    return [tuple(pair) for pair in np.argwhere(~apart)]


@pytest.mark.slow
@pytest.mark.parametrize("profile_name", ["tiny", "demo", "paper"])
def test_no_two_bodies_overlap(profile_name):
    profile = get_profile(profile_name)
    for seed in SEEDS[profile_name]:
        truth = build_scene(profile, seed, 0)
        world = truth.world
        static = world.static_boxes
        statics = boxes(static.center_enu, static.size_m, static.yaw_rad)
        pairs = [(i, j) for i, j in overlaps(statics, statics) if i < j]
        assert not pairs, f"{profile_name} seed {seed}: static bodies overlap: {pairs[:5]}"
        for t in np.arange(0.0, profile.scene_duration_s, STEP_S):
            moving = [c for c in world.cars]
            centers = np.array([c.trajectory.position_at(t) for c in moving]).reshape(-1, 3)
            sizes = np.array([c.size_m for c in moving]).reshape(-1, 3)
            centers[:, 2] = sizes[:, 2] / 2
            yaws = np.array([float(c.trajectory.yaw_at(t)) for c in moving])
            # The ego body, from its pose: the ego frame's origin is the front bumper's midpoint.
            ego_rotation, ego_front = ego_model.enu_T_ego(truth.ego, np.array(t))
            length, width, height = ego_model.EGO_SIZE_M
            ego_center = ego_front + ego_rotation @ np.array([-length / 2, 0.0, height / 2])
            ego_yaw = np.arctan2(ego_rotation[1, 0], ego_rotation[0, 0])
            dynamic = boxes(np.vstack([ego_center[None], centers]), np.vstack([ego_model.EGO_SIZE_M[None], sizes]),
                                np.concatenate([[ego_yaw], yaws]))
            names = ["ego"] + [f"car {c.track_id}" for c in moving]
            hits = [(names[i], names[j]) for i, j in overlaps(dynamic, dynamic) if i < j]
            hits += [(names[i], f"static box {j}") for i, j in overlaps(dynamic, statics)]
            assert not hits, f"{profile_name} seed {seed} t={t:.2f} s: {hits}"


def lateral_offset(road, points_xy):
    """Signed left offset (m) of points [P, 2] from the road's reference line."""
    nearest = np.argmin(np.linalg.norm(road.xy_enu[None] - points_xy[:, None], axis=-1), axis=1)
    yaw = road.yaw_rad[nearest]
    delta = points_xy - road.xy_enu[nearest]
    return -np.sin(yaw) * delta[:, 0] + np.cos(yaw) * delta[:, 1]


def test_parked_cars_stand_in_the_parking_strips_beside_the_lanes():
    for seed in range(6):
        world = build_scene(get_profile("tiny"), seed, 0).world
        boxes = world.static_boxes
        parked = np.all(boxes.color == COLORS["parked_car"], axis=1)
        assert parked.any()
        lateral = lateral_offset(world.road, boxes.center_enu[parked, :2])
        half_width = boxes.size_m[parked, 1] / 2
        # Ego lane centred at 0, oncoming lane at +3.5 m (each 3.5 m wide): the carriageway spans
        # [-1.75, 5.25] m; a parked car lies wholly outside it, within 3 m of it.
        right = lateral < 0
        assert np.all(lateral[right] + half_width[right] <= -1.75)
        assert np.all(lateral[right] - half_width[right] >= -1.75 - 3.0)
        assert np.all(lateral[~right] - half_width[~right] >= 5.25)
        assert np.all(lateral[~right] + half_width[~right] <= 5.25 + 3.0)
