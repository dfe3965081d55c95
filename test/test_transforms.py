"""Quaternion helpers against independent constructions."""
import numpy as np

from hair_tracking.core.transforms import (matrices_to_quats, matrix_to_quat, quat_angle,
                                           quat_from_axis_angle, quat_multiply, quat_to_matrix,
                                           rotation_between, slerp, slerp_floats)


def _rodrigues(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def test_matrix_matches_rodrigues_and_round_trips():
    rng = np.random.default_rng(0)
    for _ in range(50):
        axis, angle = rng.normal(size=3), rng.uniform(-3, 3)
        q = quat_from_axis_angle(axis, angle)
        m = quat_to_matrix(q)
        assert np.allclose(m, _rodrigues(axis, angle))
        q2 = matrix_to_quat(m)
        assert np.allclose(quat_to_matrix(q2), m)


def test_matrices_to_quats_recovers_the_quaternions_in_every_branch():
    rng = np.random.default_rng(7)
    q = rng.normal(size=(400, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[:4] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]   # each branch
    got = matrices_to_quats(quat_to_matrix(q).reshape(20, 20, 3, 3))
    assert got.shape == (20, 20, 4)
    np.testing.assert_allclose(np.abs(np.sum(got.reshape(-1, 4) * q, axis=1)), 1.0, atol=1e-12)
    one = matrix_to_quat(quat_to_matrix(-q[5] if q[5, 3] > 0 else q[5]))
    assert one[3] >= 0 and abs(abs(np.dot(one, q[5])) - 1.0) < 1e-12


def test_multiply_composes_rotations():
    a = quat_from_axis_angle([1, 2, 3], 0.7)
    b = quat_from_axis_angle([-1, 0, 2], 1.9)
    assert np.allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b))


def test_slerp_constant_speed_shortest_arc():
    a = quat_from_axis_angle([0, 0, 1], 0.2)
    b = -quat_from_axis_angle([0, 0, 1], 1.4)      # same rotation as +, other sign
    for u in (0.0, 0.3, 0.5, 1.0):
        assert np.isclose(quat_angle(slerp(a, b, u), a), 1.2 * u, atol=1e-9)


def test_slerp_of_a_stack_is_slerp_of_each_and_the_float_form_agrees():
    """One formula for one quaternion and for stacks (bit for bit), near and far apart, and
    the head track's float form within rounding."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(300, 4))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = a + rng.normal(size=(300, 4)) * np.where(np.arange(300) % 2, 1.0, 1e-3)[:, None]
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    u = rng.uniform(size=300)
    stack = slerp(a, b, u)
    for k in range(300):
        one = slerp(a[k], b[k], u[k])
        assert np.array_equal(one, stack[k])
        np.testing.assert_allclose(slerp_floats(tuple(a[k]), tuple(b[k]), u[k]), one,
                                   atol=1e-15)
        assert np.isclose(quat_angle(one, a[k]), u[k] * quat_angle(a[k], b[k]), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(stack, axis=1), 1.0, atol=1e-15)


def test_rotation_between():
    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        r = rotation_between(a, b)
        assert np.allclose(r @ a, b) and np.allclose(r @ r.T, np.eye(3))
    r = rotation_between(np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]))
    assert np.allclose(r @ [1, 0, 0], [-1, 0, 0]) and np.isclose(np.linalg.det(r), 1.0)


def test_quat_to_matrix_one_quaternion_equals_the_stacked_path():
    """The scalar path for one quaternion (used every substep) gives the very bits of the
    vectorised path for stacks."""
    rng = np.random.default_rng(4)
    qs = rng.normal(size=(50, 4))
    qs /= np.linalg.norm(qs, axis=1, keepdims=True)
    stacked = quat_to_matrix(qs)
    for q, m in zip(qs, stacked):
        one = quat_to_matrix(q)
        assert one.shape == (3, 3) and one.dtype == np.float64
        assert np.array_equal(one, m)
    assert np.array_equal(quat_to_matrix([0, 0, 0, 1]), np.eye(3))
