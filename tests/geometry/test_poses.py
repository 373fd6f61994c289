import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry import PoseInterpolator

# Analytic trajectory: a circle of radius 30 m driven at 15 m/s (yaw rate 0.5 rad/s),
# sampled every 10 ms (the 100 Hz tracklog). Between samples the heading turns by
# θ = 5 mrad, so linear interpolation of the position is off the arc by at most the
# sagitta R·(1 − cos(θ/2)) ≈ R·θ²/8 = 94 µm, well below the 1 mm bound. The rotation is
# about a fixed axis at a constant rate, which Slerp reproduces exactly, so the
# 1 µrad bound tests the implementation, not the model.
RADIUS_M = 30.0
SPEED_MPS = 15.0
YAW_RATE_RPS = SPEED_MPS / RADIUS_M
STEP_NS = 10_000_000
T0_NS = 1_300_000_000_000_000_000

# An arbitrary but fixed placement of the circle's plane in ECEF.
PLANE_R = Rotation.from_euler("zyx", [0.3, -0.7, 1.1]).as_matrix()
CENTRE_ECEF = np.array([-2_700_000.0, -4_300_000.0, 3_850_000.0])


def truth(timestamp_ns):
    t_s = (np.asarray(timestamp_ns, dtype=np.int64) - T0_NS) / 1e9
    yaw = YAW_RATE_RPS * t_s
    local = np.stack([RADIUS_M * np.sin(yaw), -RADIUS_M * np.cos(yaw), np.zeros_like(yaw)], axis=-1)
    position = CENTRE_ECEF + local @ PLANE_R.T
    rotation = Rotation.from_matrix(PLANE_R) * Rotation.from_rotvec(np.outer(yaw, [0.0, 0.0, 1.0]))
    return position, rotation


def make_interpolator(n=500):
    timestamp_ns = T0_NS + STEP_NS * np.arange(n, dtype=np.int64)
    position, rotation = truth(timestamp_ns)
    return PoseInterpolator(timestamp_ns, position, rotation.as_quat(scalar_first=True)), timestamp_ns


def test_matches_analytic_circle_between_samples():
    interp, timestamp_ns = make_interpolator()
    rng = np.random.default_rng(3)
    query = rng.integers(timestamp_ns[0], timestamp_ns[-1], size=2000, dtype=np.int64)
    query = np.concatenate([query, timestamp_ns[:3], timestamp_ns[-3:], timestamp_ns[:-1] + STEP_NS // 2])
    position, attitude = interp.at(query)
    true_position, true_rotation = truth(query)
    position_error_m = np.linalg.norm(position - true_position, axis=1)
    assert position_error_m.max() < 1e-3
    # Mid-points sit on the worst case, the sagitta (independent of the code under test).
    sagitta_m = RADIUS_M * (1 - math.cos(YAW_RATE_RPS * STEP_NS / 1e9 / 2))
    assert position_error_m.max() == pytest.approx(sagitta_m, rel=1e-3)
    angle_error_rad = (Rotation.from_quat(attitude, scalar_first=True) * true_rotation.inv()).magnitude()
    assert angle_error_rad.max() < 1e-6
    assert np.all(attitude[:, 0] >= 0)


def test_exact_at_samples_and_se3():
    interp, timestamp_ns = make_interpolator(10)
    position, _ = interp.at(timestamp_ns)
    np.testing.assert_allclose(position, truth(timestamp_ns)[0], atol=1e-9)
    ecef_T_imu = interp.ecef_T_imu(int(timestamp_ns[4]))
    true_position, true_rotation = truth([timestamp_ns[4]])
    np.testing.assert_allclose(ecef_T_imu.translation, true_position[0], atol=1e-9)
    np.testing.assert_allclose(ecef_T_imu.rotation, true_rotation.as_matrix()[0], atol=1e-12)


def test_extrapolation_raises_naming_time_and_span():
    interp, timestamp_ns = make_interpolator(10)
    start, end = int(timestamp_ns[0]), int(timestamp_ns[-1])
    interp.at([start, end])  # both ends are inside
    for bad in (start - 1, end + 1):
        with pytest.raises(ZendarError) as excinfo:
            interp.at(bad)
        message = str(excinfo.value)
        assert str(bad) in message and str(start) in message and str(end) in message
    with pytest.raises(ZendarError, match="outside the tracklog span"):
        interp.ecef_T_imu(end + STEP_NS)


def test_bad_tracklogs():
    q = np.tile([1.0, 0.0, 0.0, 0.0], (3, 1))
    p = np.zeros((3, 3))
    with pytest.raises(ZendarError, match="strictly increasing"):
        PoseInterpolator(np.array([0, 10, 10]), p, q)
    with pytest.raises(ZendarError, match="position_ecef must be"):
        PoseInterpolator(np.array([0, 10, 20]), p[:2], q)
    with pytest.raises(ZendarError, match="at least 2"):
        PoseInterpolator(np.array([0]), p[:1], q[:1])
    with pytest.raises(ZendarError, match="zero or non-finite"):
        PoseInterpolator(np.array([0, 10, 20]), p, np.zeros((3, 4)))


def test_rotation_between_samples_one_radian_apart_is_the_closed_form_rotation():
    # 1 s samples of a constant-rate turn of 1.1 rad/s about a fixed tilted axis: steps of
    # 1.1 rad, where a normalised lerp of the quaternions is off by up to 5 mrad (exact only
    # at the midpoint). Quaternion signs alternate, as a tracklog may store them.
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    rate_rad_per_s = 1.1
    start = Rotation.from_euler("zyx", [0.4, 0.2, -1.3])
    step_ns = 1_000_000_000
    timestamp_ns = T0_NS + step_ns * np.arange(6, dtype=np.int64)

    def closed_form(t_ns):
        t_s = (np.asarray(t_ns, dtype=np.int64) - T0_NS) / 1e9
        return Rotation.from_rotvec(np.outer(rate_rad_per_s * t_s, axis)) * start

    quaternions = closed_form(timestamp_ns).as_quat(scalar_first=True)
    quaternions *= np.where(np.arange(6) % 2 == 0, 1.0, -1.0)[:, None]
    interp = PoseInterpolator(timestamp_ns, np.zeros((6, 3)), quaternions)
    fractions = np.array([0.1, 0.25, 0.4, 0.5, 0.6, 0.75, 0.9])
    query = (timestamp_ns[:-1, None] + (fractions * step_ns).astype(np.int64)[None]).reshape(-1)
    _, attitude = interp.at(query)
    error_rad = (Rotation.from_quat(attitude, scalar_first=True) * closed_form(query).inv()).magnitude()
    assert error_rad.max() < 1e-9
