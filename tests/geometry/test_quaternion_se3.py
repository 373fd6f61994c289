import math

import numpy as np
import pytest

from zendar_dataset.geometry import SE3, matrix_to_quat_wxyz, quat_wxyz_to_matrix


def rot_z(angle_rad):
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_quaternion_is_scalar_first():
    # 90 degrees about z: w = cos(45°), z = sin(45°).
    q = [math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]
    np.testing.assert_allclose(quat_wxyz_to_matrix(q), rot_z(math.pi / 2), atol=1e-15)
    np.testing.assert_allclose(quat_wxyz_to_matrix([1, 0, 0, 0]), np.eye(3))
    # 180 degrees about x maps y -> -y and z -> -z.
    np.testing.assert_allclose(quat_wxyz_to_matrix([0, 1, 0, 0]), np.diag([1.0, -1.0, -1.0]), atol=1e-15)


def test_quaternion_round_trip_batched_and_canonical():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(5, 7, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    matrices = quat_wxyz_to_matrix(q)
    assert matrices.shape == (5, 7, 3, 3)
    back = matrix_to_quat_wxyz(matrices)
    assert back.shape == (5, 7, 4)
    assert np.all(back[..., 0] >= 0)
    # q and -q are the same rotation.
    np.testing.assert_allclose(back, q * np.sign(q[..., :1]), atol=1e-12)


def test_quaternion_rejects_bad_shapes():
    with pytest.raises(ValueError, match=r"\[\.\.\., 4\]"):
        quat_wxyz_to_matrix([1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="non-zero"):
        quat_wxyz_to_matrix([0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"\[\.\.\., 3, 3\]"):
        matrix_to_quat_wxyz(np.eye(4))


def test_se3_compose_inverse_and_points():
    a_T_b = SE3(rot_z(math.pi / 2), [1.0, 2.0, 3.0])
    b_T_c = SE3(np.eye(3), [10.0, 0.0, 0.0])
    # Point at c's origin lies 10 m along b's x; b's x is a's y.
    np.testing.assert_allclose(a_T_b.compose(b_T_c).transform_points([0, 0, 0]), [1.0, 12.0, 3.0], atol=1e-12)
    points = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 5.0]]])
    np.testing.assert_allclose(a_T_b.transform_points(points), [[[1.0, 3.0, 3.0], [0.0, 2.0, 8.0]]], atol=1e-12)
    np.testing.assert_allclose(a_T_b.inverse().transform_points(a_T_b.transform_points(points)), points, atol=1e-12)
    np.testing.assert_allclose(a_T_b.compose(a_T_b.inverse()).as_matrix(), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(a_T_b.rotate_vectors([1.0, 0.0, 0.0]), [0.0, 1.0, 0.0], atol=1e-12)
    m = a_T_b.as_matrix()
    assert m.shape == (4, 4) and m.dtype == np.float64
    np.testing.assert_allclose(SE3.from_matrix(m).translation, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(SE3.from_wxyz(a_T_b.as_wxyz(), [1, 2, 3]).rotation, a_T_b.rotation, atol=1e-12)


def test_se3_checks_shapes_and_is_immutable():
    with pytest.raises(ValueError, match="rotation"):
        SE3(np.eye(4), np.zeros(3))
    with pytest.raises(ValueError, match="translation"):
        SE3(np.eye(3), np.zeros(4))
    t = SE3.identity()
    with pytest.raises(ValueError):
        t.translation[0] = 1.0
