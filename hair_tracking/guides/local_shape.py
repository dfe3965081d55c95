"""Bending with a direction: local shape constraints of the FTL guides.

Han & Harada 2012, "Real-time Hair Simulation with Efficient Hair Style Preservation"
(VRIPHYS; AMD TressFX's local shape constraints): every segment keeps its rest direction in its
parent segment's frame.  Walking a strand from the root, the frame of each segment is its
parent's frame turned by the smallest rotation that takes the direction the parent's frame
gives the segment onto the segment's current direction (parallel transport; TressFX turns the
frame by the rotation between the frame's axis and the segment, the same rotation), and each
node is moved toward where its rest segment, carried by its parent's frame, puts it::

    Q_0 = R                                     (the root segment turns with the head)
    t_i = p_{i-1} + Q_{i-2} (rest_i - rest_{i-1})
    p_i <- p_i + k (t_i - p_i)
    Q_{i-1} = T(Q_{i-2} e_{i-1}, p_i - p_{i-1}) Q_{i-2}

with ``R`` the head rotation, ``rest`` the groomed nodes in the head frame, ``e_{i-1}`` the
rest segment ``rest_i - rest_{i-1}`` and ``T(a, b)`` the smallest rotation taking the direction
of ``a`` onto that of ``b``.  The groomed shape carried by the head is a fixed point for any
``k`` (every frame is then ``R``, every target the node itself), so hair at rest keeps the shape
it was groomed in, against gravity, to the extent ``k`` resists the substep's prediction.  Only
the child node of each segment moves (the roots, nodes 0 and 1, never): the leader is placed
first, as in Follow-The-Leader (Müller, Kim & Chentanez 2012), and the FTL pass that follows
restores the lengths.  ``T`` of opposite directions is undefined: the frame is then kept.
"""
import math

from numba import njit

from hair_tracking.guides.integrate import FASTMATH

#: Below this squared length [m^2] (or ``1 + cos`` of the turn) a direction is not used.
SHAPE_TINY = 1e-24


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def shape_sweep_block(x, rest, rot, k, s0, s1):
    """One root-to-tip sweep of the local shape constraints (stiffness ``k``, 0..1) over the
    strands ``s0 <= s < s1`` of ``x`` (S, N, 3) [m, world], in place; ``rest`` (S, N, 3) the
    groomed shape [m, head frame], ``rot`` (3, 3) the head rotation."""
    n = x.shape[1]
    for s in range(s0, s1):
        q00, q01, q02 = rot[0, 0], rot[0, 1], rot[0, 2]
        q10, q11, q12 = rot[1, 0], rot[1, 1], rot[1, 2]
        q20, q21, q22 = rot[2, 0], rot[2, 1], rot[2, 2]
        px, py, pz = x[s, 1, 0], x[s, 1, 1], x[s, 1, 2]       # the parent before the sweep
        for i in range(2, n):
            ex = rest[s, i, 0] - rest[s, i - 1, 0]
            ey = rest[s, i, 1] - rest[s, i - 1, 1]
            ez = rest[s, i, 2] - rest[s, i - 1, 2]
            ax = q00 * ex + q01 * ey + q02 * ez           # the rest segment in the parent frame
            ay = q10 * ex + q11 * ey + q12 * ez
            az = q20 * ex + q21 * ey + q22 * ez
            cx, cy, cz = x[s, i, 0], x[s, i, 1], x[s, i, 2]
            x[s, i, 0] = x[s, i - 1, 0] + (1.0 - k) * (cx - px) + k * ax
            x[s, i, 1] = x[s, i - 1, 1] + (1.0 - k) * (cy - py) + k * ay
            x[s, i, 2] = x[s, i - 1, 2] + (1.0 - k) * (cz - pz) + k * az
            px, py, pz = cx, cy, cz
            if i == n - 1:
                break
            bx = x[s, i, 0] - x[s, i - 1, 0]
            by = x[s, i, 1] - x[s, i - 1, 1]
            bz = x[s, i, 2] - x[s, i - 1, 2]
            la = ax * ax + ay * ay + az * az
            lb = bx * bx + by * by + bz * bz
            if la <= SHAPE_TINY or lb <= SHAPE_TINY:
                continue
            f = 1.0 / math.sqrt(la * lb)
            c = (ax * bx + ay * by + az * bz) * f           # cos of the turn
            vx = (ay * bz - az * by) * f                    # its axis times its sin
            vy = (az * bx - ax * bz) * f
            vz = (ax * by - ay * bx) * f
            if 1.0 + c <= SHAPE_TINY:
                continue
            h = 1.0 / (1.0 + c)
            q00, q10, q20 = _turn(q00, q10, q20, vx, vy, vz, c, h)
            q01, q11, q21 = _turn(q01, q11, q21, vx, vy, vz, c, h)
            q02, q12, q22 = _turn(q02, q12, q22, vx, vy, vz, c, h)


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def _turn(x, y, z, vx, vy, vz, c, h):
    """``(x, y, z)`` turned by the rotation of axis times sine ``v`` and cosine ``c`` (``h =
    1 / (1 + c)``; Rodrigues: ``c u + v x u + h (v . u) v``)."""
    d = h * (vx * x + vy * y + vz * z)
    return (c * x + vy * z - vz * y + d * vx,
            c * y + vz * x - vx * z + d * vy,
            c * z + vx * y - vy * x + d * vz)
