"""Diffuse returns of the street: the ground (road and sidewalks) by the constant-gamma law, walls by
Lambert's, canopies from their volume; each as seen from the radar."""

from __future__ import annotations

import numpy as np
import pytest

from zendar_dataset.sim.clutter import road_clutter, view_gains
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import build_scene
from zendar_dataset.sim.world import (
    CURB_WIDTH_M,
    SURFACE_GROUND,
    SURFACE_WALL,
    WALL_SCATTERING,
    Road,
    ScattererSet,
    street_edge_m,
)

RADAR_HEIGHT_M = 0.5


def test_ground_clutter_falls_with_the_grazing_angle():
    settings = Imperfections()
    road = Road.from_curvature(-10.0, 200.0, lambda s: np.zeros_like(s))
    clutter = road_clutter(np.random.default_rng(0), road, 0.0, 150.0, (-10.0, 10.0), settings)
    assert np.all(clutter.surface == SURFACE_GROUND)
    radar = np.array([0.0, 0.0, RADAR_HEIGHT_M])
    distance = np.linalg.norm(clutter.position_m - radar, axis=1)
    # sigma0 = gamma sin(psi): each cell's RCS (gamma times its area at normal view, times its Weibull
    # speckle, whose mean is 1) is seen times the sine of its grazing angle.
    np.testing.assert_allclose(view_gains(clutter, radar), RADAR_HEIGHT_M / distance, rtol=1e-12)
    gamma = 10 ** (settings.clutter_gamma_db / 10)
    assert np.mean(clutter.rcs_m2) / settings.clutter_spacing_m**2 == pytest.approx(gamma, rel=0.05)
    # About -24 dB at 5 m (5.7 deg) down to -35 dB at 60 m (0.5 deg), within the span measured on asphalt
    # near grazing incidence (docs/simulator.md).
    sigma0_db = {r: 10 * np.log10(gamma * RADAR_HEIGHT_M / np.hypot(r, RADAR_HEIGHT_M)) for r in (5.0, 60.0)}
    assert -25.0 < sigma0_db[5.0] < -23.0
    assert -36.0 < sigma0_db[60.0] < -34.0
    assert np.all(view_gains(clutter, np.array([0.0, 0.0, -1.0])) == 0.0)  # from below: nothing


def test_walls_are_lambertian_and_dark_from_behind():
    n = 5
    angles = np.radians(np.array([0.0, 30.0, 60.0, 85.0, 120.0]))
    wall = ScattererSet(np.zeros((n, 3)), np.ones(n), np.zeros(n, bool), np.zeros(n),
                        surface=np.full(n, SURFACE_WALL, np.int8), normal=np.tile([1.0, 0.0, 0.0], (n, 1)))
    gains = [view_gains(wall.subset([k]), 10.0 * np.array([np.cos(a), np.sin(a), 0.0]))[0] for k, a in enumerate(angles)]
    np.testing.assert_allclose(gains, [1.0, 0.75, 0.25, np.cos(angles[3]) ** 2, 0.0], atol=1e-12)


def test_a_scene_has_diffuse_ground_from_facade_to_facade_and_lambertian_facades():
    profile = get_profile("demo")
    truth = build_scene(profile, 0, 0)
    static = truth.world.static_scatterers
    road = truth.world.road
    ground = static.subset(static.surface == SURFACE_GROUND)
    # Lateral offset of each ground cell from the nearest centre-line sample: sidewalks included, beyond
    # the curbs on both sides.
    centre = road.xy_enu[::20]
    nearest = np.argmin(np.linalg.norm(ground.position_m[:, None, :2] - centre[None], axis=-1), axis=1)
    yaw = road.yaw_rad[::20][nearest]
    offset = ground.position_m[:, :2] - centre[nearest]
    lateral = np.cos(yaw) * offset[:, 1] - np.sin(yaw) * offset[:, 0]
    for side in (1.0, -1.0):
        beyond_curb = side * lateral > abs(street_edge_m(side)) + CURB_WIDTH_M + 0.5
        assert beyond_curb.sum() > 0.1 * ground.position_m.shape[0] / 2
    walls = static.subset(static.surface == SURFACE_WALL)
    cell_m2 = profile.facade_spacing_m * 0.9
    assert np.mean(walls.rcs_m2) / cell_m2 == pytest.approx(4.0 * WALL_SCATTERING**2, rel=0.15)
    np.testing.assert_allclose(np.linalg.norm(walls.normal, axis=1), 1.0)
