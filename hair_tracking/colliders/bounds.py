"""The cheap bound test that comes before the exact contact test: a node, or a box around a
block of nodes, far from a shape pays a few multiply-adds per shape and nothing else.

Every shape but the plane lies inside its bounding sphere (centre ``C``, radius ``BOUND`` of
the posed table: the largest semi-axis + margin of an ellipsoid; radius + margin + half length
of a sphere or capsule), padded by :data:`~hair_tracking.colliders.shapes.BOUND_PAD` so that
rounding never puts a node the exact test finds inside outside it.  A plane has no bounding
sphere; its test is its exact one (one dot product), and a box's is the plane's height at the
box's lowest corner.  The tests never miss a contact (``test/test_colliders.py`` holds them
to that); they may pass nodes that are not in contact.
"""
import math

from numba import njit

from hair_tracking.colliders.shapes import (A0, BOUND, CX, CY, CZ, KIND, PLANE, R02, R12,
                                            R22)


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
    bounding sphere (a plane: the box's lowest corner along the normal is below the plane +
    margin)."""
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
    return d0 * d0 + d1 * d1 + d2 * d2 < b * b


@njit(cache=True, inline='always')
def near_shapes(lo0, lo1, lo2, hi0, hi1, hi2, sh, out):
    """The shapes of the table ``sh`` that the box ``lo .. hi`` may touch, in table order, into
    ``out`` (int64, at least one entry a shape); returns their count."""
    m = 0
    for k in range(sh.shape[0]):
        if box_near(lo0, lo1, lo2, hi0, hi1, hi2, sh, k):
            out[m] = k
            m += 1
    return m


@njit(cache=True, inline='always')
def lane_box(xs, ys, zs, n):
    """The box ``(lo0, lo1, lo2, hi0, hi1, hi2)`` of ``n`` lanes whose coordinates are the
    first ``n`` entries of the rows ``xs``, ``ys``, ``zs`` (a block's lanes at one node
    index).  A coordinate that is not finite is left out (the other lanes keep their bound;
    no finite lane gives an empty box, near no shape)."""
    lo0 = lo1 = lo2 = math.inf
    hi0 = hi1 = hi2 = -math.inf
    for i in range(n):
        v = xs[i]
        lo0 = v if v < lo0 else lo0
        hi0 = v if v > hi0 else hi0
        v = ys[i]
        lo1 = v if v < lo1 else lo1
        hi1 = v if v > hi1 else hi1
        v = zs[i]
        lo2 = v if v < lo2 else lo2
        hi2 = v if v > hi2 else hi2
    return lo0, lo1, lo2, hi0, hi1, hi2
