"""The cheap bound test that comes before the exact contact test: a node, or a box around a
block of nodes, far from a shape pays a few multiply-adds per shape and nothing else.

Every shape but the plane lies inside its bounding sphere (centre ``C``, radius ``BOUND`` of
the posed table: the largest semi-axis + margin of an ellipsoid; radius + margin + half length
of a sphere or capsule), padded by :data:`~hair_tracking.colliders.shapes.BOUND_PAD` so that
rounding never puts a node the exact test finds inside outside it.  A plane has no bounding
sphere; its test is its exact one (one dot product), and a box's is the plane's height at the
box's lowest corner.  A box must also meet a capsule's axis-aligned box (its core segment's
box grown by the radius + margin, padded alike: :func:`shape_box`), which a box along a long
capsule's side meets where the sphere around the whole capsule reaches far beyond it.  The
tests never miss a contact (``test/test_colliders.py`` holds them to that); they may pass nodes
that are not in contact.
"""
import math

from numba import njit

from hair_tracking.colliders.shapes import (A0, A1, BOUND, BOUND_PAD, CAPSULE, CX, CY, CZ,
                                            KIND, PLANE, R02, R12, R22)


@njit(cache=True, inline='always')
def near(x0, x1, x2, sh, k):
    """Whether the node ``x`` may touch shape ``k`` (inside its bounding sphere; a plane:
    below the plane + margin)."""
    dx, dy, dz = x0 - sh[k, CX], x1 - sh[k, CY], x2 - sh[k, CZ]
    if sh[k, KIND] == PLANE:
        return dx * sh[k, R02] + dy * sh[k, R12] + dz * sh[k, R22] < sh[k, A0]
    b = sh[k, BOUND]
    return dx * dx + dy * dy + dz * dz < b * b


@njit(cache=True, inline='always')
def box_near(lo0, lo1, lo2, hi0, hi1, hi2, sh, k):
    """Whether any point of the box ``lo .. hi`` may touch shape ``k``: the box meets the
    bounding sphere, and a capsule's box (a plane: the box's lowest corner along the normal is
    below the plane + margin)."""
    if sh[k, KIND] == PLANE:
        n0, n1, n2 = sh[k, R02], sh[k, R12], sh[k, R22]
        low = (lo0 if n0 > 0.0 else hi0) - sh[k, CX]
        h = low * n0
        low = (lo1 if n1 > 0.0 else hi1) - sh[k, CY]
        h += low * n1
        low = (lo2 if n2 > 0.0 else hi2) - sh[k, CZ]
        h += low * n2
        return h < sh[k, A0]
    d0 = max(lo0 - sh[k, CX], sh[k, CX] - hi0, 0.0)
    d1 = max(lo1 - sh[k, CY], sh[k, CY] - hi1, 0.0)
    d2 = max(lo2 - sh[k, CZ], sh[k, CZ] - hi2, 0.0)
    b = sh[k, BOUND]
    inside = d0 * d0 + d1 * d1 + d2 * d2 < b * b
    if sh[k, KIND] != CAPSULE:
        return inside
    # the tests combined without branches: which way each goes follows the hair, not the code
    return inside & _meets(lo0, hi0, sh[k, CX], sh[k, R02], sh[k, A1], sh[k, A0]) & \
        _meets(lo1, hi1, sh[k, CY], sh[k, R12], sh[k, A1], sh[k, A0]) & \
        _meets(lo2, hi2, sh[k, CZ], sh[k, R22], sh[k, A1], sh[k, A0])


@njit(cache=True, inline='always')
def _meets(lo, hi, c, u, h, r):
    """Whether ``lo .. hi`` meets the extent along one world axis of a capsule of centre
    coordinate ``c``, axis coordinate ``u``, half length ``h`` and radius ``r`` (padded as
    the bounding sphere)."""
    e = (abs(u) * h + r) * (1.0 + BOUND_PAD)
    return (lo < c + e) & (hi > c - e)


@njit(cache=True, inline='always')
def shape_box(sh, k):
    """The axis-aligned box ``(lo0, lo1, lo2, hi0, hi1, hi2)`` around shape ``k`` + margin,
    padded as the bounding sphere: a capsule's core segment's box grown by its radius, the
    bounding sphere's box of a sphere or an ellipsoid, all space for a plane."""
    if sh[k, KIND] == PLANE:
        return -math.inf, -math.inf, -math.inf, math.inf, math.inf, math.inf
    e0 = e1 = e2 = sh[k, BOUND]
    if sh[k, KIND] == CAPSULE:
        e0 = (abs(sh[k, R02]) * sh[k, A1] + sh[k, A0]) * (1.0 + BOUND_PAD)
        e1 = (abs(sh[k, R12]) * sh[k, A1] + sh[k, A0]) * (1.0 + BOUND_PAD)
        e2 = (abs(sh[k, R22]) * sh[k, A1] + sh[k, A0]) * (1.0 + BOUND_PAD)
    return (sh[k, CX] - e0, sh[k, CY] - e1, sh[k, CZ] - e2, sh[k, CX] + e0, sh[k, CY] + e1,
            sh[k, CZ] + e2)


@njit(cache=True, inline='always')
def boxes_meet(lo0, lo1, lo2, hi0, hi1, hi2, boxes, k):
    """Whether the box ``lo .. hi`` meets the box ``boxes[k]`` (lo0 lo1 lo2 hi0 hi1 hi2),
    without a branch on the answer (which way it goes follows the hair, not the code)."""
    return (lo0 < boxes[k, 3]) & (hi0 > boxes[k, 0]) & (lo1 < boxes[k, 4]) & \
        (hi1 > boxes[k, 1]) & (lo2 < boxes[k, 5]) & (hi2 > boxes[k, 2])


@njit(cache=True, inline='always')
def strand_box(x, s, first):
    """The box ``(lo0, lo1, lo2, hi0, hi1, hi2)`` of the nodes ``first ..`` of strand ``s`` of
    ``x`` (S, N, 3); coordinates that are not finite are left out, as in :func:`lane_box`."""
    lo0 = lo1 = lo2 = math.inf
    hi0 = hi1 = hi2 = -math.inf
    for j in range(first, x.shape[1]):
        v = float(x[s, j, 0])
        lo0 = v if v < lo0 else lo0
        hi0 = v if v > hi0 else hi0
        v = float(x[s, j, 1])
        lo1 = v if v < lo1 else lo1
        hi1 = v if v > hi1 else hi1
        v = float(x[s, j, 2])
        lo2 = v if v < lo2 else lo2
        hi2 = v if v > hi2 else hi2
    return lo0, lo1, lo2, hi0, hi1, hi2
