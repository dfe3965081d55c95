"""Rigid transforms with quaternions in ROS order (x, y, z, w).

A head pose maps head-frame points to the world (the fixed frame of the pose stream):
``p_world = position + R(q) @ p_head``.
"""
import math

import numpy as np


def quat_normalize(q):
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_multiply(a, b):
    """Hamilton product a * b (apply b first, then a)."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def quat_conjugate(q):
    q = np.array(q, dtype=np.float64)
    q[..., :3] *= -1.0
    return q


def quat_to_matrix(q):
    """Rotation matrix of a unit quaternion (x, y, z, w); works on stacks (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape == (4,):     # one quaternion: on Python floats, 5x faster
        return matrix_of_quat(*q.tolist())
    x, y, z, w = np.moveaxis(q, -1, 0)
    m = np.empty(np.shape(x) + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def matrix_of_quat(x, y, z, w):
    """Rotation matrix (3, 3) of one unit quaternion given as four floats (the head track's
    samples, one a substep)."""
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrices_to_quats(m):
    """(..., 3, 3) rotation matrices -> (..., 4) unit quaternions (x, y, z, w).

    Shepperd (1978), "Quaternion from rotation matrix", J. Guidance and Control 1(3): the largest
    of 1 + trace, 1 + 2 m_ii - trace picks the numerically safe formula; vectorised.
    """
    m = np.asarray(m, dtype=np.float64)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], tr], axis=1)
    pick = np.argmax(cand, axis=1)
    q = np.empty((len(m), 4))
    for k in range(4):
        sel = pick == k
        if not np.any(sel):
            continue
        a = m[sel]
        if k == 3:
            s = 2.0 * np.sqrt(1.0 + tr[sel])
            q[sel] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) / s, (a[:, 0, 2] - a[:, 2, 0]) / s,
                               (a[:, 1, 0] - a[:, 0, 1]) / s, 0.25 * s], axis=1)
            continue
        i, j, h = k, (k + 1) % 3, (k + 2) % 3
        s = 2.0 * np.sqrt(np.maximum(1.0 + a[:, i, i] - a[:, j, j] - a[:, h, h], 0.0))
        out = np.empty((len(a), 4))
        out[:, i] = 0.25 * s
        out[:, j] = (a[:, j, i] + a[:, i, j]) / s
        out[:, h] = (a[:, h, i] + a[:, i, h]) / s
        out[:, 3] = (a[:, h, j] - a[:, j, h]) / s
        q[sel] = out
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(shape + (4,))


def matrix_to_quat(m):
    """Unit quaternion (x, y, z, w) with w >= 0 of one rotation matrix (see
    :func:`matrices_to_quats`)."""
    q = matrices_to_quats(m)
    return q if q[3] >= 0 else -q


def quat_from_axis_angle(axis, angle):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([axis * np.sin(angle / 2.0), [np.cos(angle / 2.0)]])


def quat_angle(a, b):
    """Angle [rad] of the rotation taking unit quaternion a to b (sign-insensitive)."""
    d = abs(float(np.dot(a, b)))
    return 2.0 * np.arccos(min(1.0, d))


#: Above this cosine of the half angle between two quaternions :func:`slerp` interpolates
#: linearly and normalises (the arc is flat there, and sin(theta) too small to divide by).
NLERP_ABOVE = 0.9995


def slerp(a, b, u):
    """Spherical linear interpolation (Shoemake 1985, "Animating rotation with quaternion
    curves", SIGGRAPH) from unit quaternions ``a`` to ``b``, shortest arc, at ``u`` in [0, 1].

    ``a``, ``b`` (..., 4) and ``u`` a number or (...,): one quaternion or a stack of them; the
    normalised linear interpolation where the two are closer than :data:`NLERP_ABOVE`.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64)[..., None]
    d = np.sum(a * b, axis=-1, keepdims=True)
    b = np.where(d < 0.0, -b, b)
    d = np.abs(d)
    near = d > NLERP_ABOVE
    lerp = a + u * (b - a)
    lerp = lerp / np.linalg.norm(lerp, axis=-1, keepdims=True)
    theta = np.arccos(np.minimum(d, 1.0))
    s = np.where(near, 1.0, np.sin(theta))
    return np.where(near, lerp, (np.sin((1 - u) * theta) * a + np.sin(u * theta) * b) / s)


def quat_dot(a, b) -> float:
    """Dot product of two quaternions given as sequences of four floats."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]


def slerp_floats(a, b, u):
    """:func:`slerp` of two unit quaternions given as sequences of four floats, on Python floats
    (a tuple; the head track samples one pose a substep, where numpy's per-call cost would
    dominate); shortest arc."""
    d = quat_dot(a, b)
    if d < 0.0:
        b, d = tuple(-c for c in b), -d
    if d > NLERP_ABOVE:
        q = tuple(a[k] + u * (b[k] - a[k]) for k in range(4))
        n = math.hypot(*q)
        return tuple(c / n for c in q)
    theta = math.acos(min(1.0, d))
    s = math.sin(theta)
    wa, wb = math.sin((1 - u) * theta) / s, math.sin(u * theta) / s
    return tuple(wa * a[k] + wb * b[k] for k in range(4))


def rotation_between(a, b):
    """Smallest rotation matrix taking unit vector a onto unit vector b."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        perp /= np.linalg.norm(perp)
        return 2.0 * np.outer(perp, perp) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)
