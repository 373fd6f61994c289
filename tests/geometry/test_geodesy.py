import math

import numpy as np
import pytest

from zendar_dataset.geometry import LocalENU, ecef_to_geodetic, geodetic_to_ecef

WGS84_A_M = 6378137.0
WGS84_B_M = 6356752.314245179


def test_equator_prime_meridian_and_poles():
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 0.0), [WGS84_A_M, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 90.0, 0.0), [0.0, WGS84_A_M, 0.0], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, WGS84_B_M], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(-90.0, 0.0, 100.0), [0.0, 0.0, -WGS84_B_M - 100.0], atol=1e-6)


def test_published_pair():
    # Worked example from the EPSG guidance note 7-2 (§4.1.1, WGS 84):
    # 53°48'33.820"N, 2°07'46.380"E, h = 73.000 m -> X 3771793.968, Y 140253.342, Z 5124304.349 m.
    lat_deg = 53 + 48 / 60 + 33.820 / 3600
    lon_deg = 2 + 7 / 60 + 46.380 / 3600
    expected = [3771793.968, 140253.342, 5124304.349]
    np.testing.assert_allclose(geodetic_to_ecef(lat_deg, lon_deg, 73.0), expected, atol=2e-3)
    lat, lon, h = ecef_to_geodetic(expected)
    assert abs(lat - lat_deg) < 1e-8 and abs(lon - lon_deg) < 1e-8 and abs(h - 73.0) < 2e-3


def test_closed_form_and_round_trip_batched():
    rng = np.random.default_rng(1)
    lat = rng.uniform(-89, 89, size=(4, 6))
    lon = rng.uniform(-180, 180, size=(4, 6))
    h = rng.uniform(-100, 3000, size=(4, 6))
    ecef = geodetic_to_ecef(lat, lon, h)
    assert ecef.shape == (4, 6, 3)
    # Independent closed form for the ellipsoid.
    e2 = 1 - (WGS84_B_M / WGS84_A_M) ** 2
    phi, lam = np.radians(lat), np.radians(lon)
    n = WGS84_A_M / np.sqrt(1 - e2 * np.sin(phi) ** 2)
    closed = np.stack(
        [(n + h) * np.cos(phi) * np.cos(lam), (n + h) * np.cos(phi) * np.sin(lam), (n * (1 - e2) + h) * np.sin(phi)],
        axis=-1,
    )
    np.testing.assert_allclose(ecef, closed, atol=1e-6)
    lat2, lon2, h2 = ecef_to_geodetic(ecef)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(h2, h, atol=1e-6)


def test_enu_of_points_north_east_up():
    enu = LocalENU(37.0, -122.0, 20.0)
    origin = geodetic_to_ecef(37.0, -122.0, 20.0)
    np.testing.assert_allclose(enu.ecef_to_enu(origin), [0.0, 0.0, 0.0], atol=1e-6)
    # 100 m north along the meridian: about (0, 100, -0.0008) — the ellipsoid curves away (d²/2R).
    one_hundred_m_north_deg = 100.0 / 110_985.0  # metres per degree of latitude at 37°N
    p = enu.ecef_to_enu(geodetic_to_ecef(37.0 + one_hundred_m_north_deg, -122.0, 20.0))
    assert abs(p[0]) < 1e-6
    assert abs(p[1] - 100.0) < 0.05
    assert -0.01 < p[2] < 0.0
    # Straight up is +z.
    np.testing.assert_allclose(enu.ecef_to_enu(geodetic_to_ecef(37.0, -122.0, 70.0)), [0, 0, 50.0], atol=1e-6)
    # A point along the local east tangent is pure +x.
    east_ecef = origin + 25.0 * np.array([-math.sin(math.radians(-122.0)), math.cos(math.radians(-122.0)), 0.0])
    np.testing.assert_allclose(enu.ecef_to_enu(east_ecef), [25.0, 0.0, 0.0], atol=1e-6)


def test_enu_rotation_matches_the_pipeline():
    enu = LocalENU(-33.9, 151.2, 5.0)
    rng = np.random.default_rng(2)
    points_enu = rng.uniform(-500, 500, size=(50, 3))
    points_ecef = enu.enu_to_ecef(points_enu)
    np.testing.assert_allclose(enu.ecef_to_enu(points_ecef), points_enu, atol=1e-6)
    np.testing.assert_allclose(enu.ecef_T_enu.transform_points(points_enu), points_ecef, atol=1e-6)
    np.testing.assert_allclose(enu.enu_T_ecef.transform_points(points_ecef), points_enu, atol=1e-6)
    np.testing.assert_allclose(enu.ecef_R_enu @ enu.ecef_R_enu.T, np.eye(3), atol=1e-15)


def test_enu_bad_origin_and_pickle():
    import pickle

    with pytest.raises(ValueError, match="lat_deg"):
        LocalENU(95.0, 0.0, 0.0)
    enu = pickle.loads(pickle.dumps(LocalENU(10.0, 20.0, 30.0)))
    np.testing.assert_allclose(enu.ecef_to_enu(geodetic_to_ecef(10.0, 20.0, 30.0)), 0.0, atol=1e-6)
