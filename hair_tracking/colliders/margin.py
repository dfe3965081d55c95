"""The margin a strand set is kept outside a shape, fitted to the strands: the scene's margin,
but no more than the rest clearance of any free node (a collider must never push a strand out
of its own rest shape) and no more than half the shortest segment (a push is resolved by moving
one node; pushes longer than its segments tear PBD strands: with 1 mm segments and a 4 mm margin
the first segments were stretched by 200 %).  The guide solver fits it to the guides, the
trackers without state to the ghosts.
"""
import numpy as np

from hair_tracking.colliders.shapes import Shape
from hair_tracking.core.transforms import quat_to_matrix


def outside_distance(q: np.ndarray, radii) -> np.ndarray:
    """Distance [m] of points ``q`` (..., 3) to the ellipsoid ``sum (y_k / a_k)^2 = 1`` (centred,
    axis-aligned, semi-axes ``radii``); 0 for points inside or on it.

    The closest point of an outside point ``q`` is ``y_k = a_k^2 q_k / (t + a_k^2)`` with ``t > 0``
    the root of ``sum (a_k q_k / (t + a_k^2))^2 = 1`` (Eberly 2013, "Distance from a point to an
    ellipse, an ellipsoid, or a hyperellipsoid"), found here by bisection on
    ``[0, max(a) |q|]``, where the sum is at most 1; vectorised numpy, for set-up code.
    """
    q = np.asarray(q, dtype=np.float64)
    a2 = np.asarray(radii, dtype=np.float64) ** 2
    outside = np.einsum('...k,...k->...', q * q, 1.0 / a2) > 1.0
    lo = np.zeros(q.shape[:-1])
    hi = np.sqrt(a2.max()) * np.linalg.norm(q, axis=-1)
    for _ in range(64):
        t = 0.5 * (lo + hi)
        f = np.sum((np.sqrt(a2) * q / (t[..., None] + a2)) ** 2, axis=-1)
        big = f > 1.0
        lo = np.where(big, t, lo)
        hi = np.where(big, hi, t)
    t = 0.5 * (lo + hi)
    y = a2 * q / (t[..., None] + a2)
    return np.where(outside, np.linalg.norm(q - y, axis=-1), 0.0)


def _local(points, shape: Shape) -> np.ndarray:
    """``points`` (..., 3), given in the shape's frame, relative to its centre in its axes."""
    p = np.asarray(points, dtype=np.float64) - np.asarray(shape.center, dtype=np.float64)
    q = np.asarray(shape.rotation, dtype=np.float64)
    if q[0] != 0.0 or q[1] != 0.0 or q[2] != 0.0:
        p = p @ quat_to_matrix(q / np.linalg.norm(q))            # R^T p, point by point
    return p


def _local_clearance(p: np.ndarray, shape: Shape) -> np.ndarray:
    """:func:`clearance` of points already in the shape's axes (:func:`_local`)."""
    if shape.kind == 'ellipsoid':
        return outside_distance(p, shape.radii)
    if shape.kind == 'plane':
        return np.maximum(p[..., 2], 0.0)
    h = shape.half_length if shape.kind == 'capsule' else 0.0
    core = np.zeros_like(p)
    core[..., 2] = np.clip(p[..., 2], -h, h)
    return np.maximum(np.linalg.norm(p - core, axis=-1) - shape.radius, 0.0)


def clearance(points, shape: Shape) -> np.ndarray:
    """Distance [m] of ``points`` (..., 3), given in the shape's frame, outside the bare shape
    (no margin); 0 inside."""
    return _local_clearance(_local(points, shape), shape)


def _nearer_than(p: np.ndarray, shape: Shape, d: float) -> np.ndarray:
    """The points of ``p`` (P, 3; the shape's axes) that may lie nearer than ``d`` to the bare
    shape.  For an ellipsoid of semi-axes ``a`` a point on the ellipsoid scaled by ``s =
    sqrt(sum (q_k / a_k)^2)`` lies at least ``(s - 1) min(a)`` from it (``g(q) = s`` is a norm
    with ``g(v) <= |v| / min(a)``, so ``|q - y| >= min(a) g(q - y) >= min(a) (s - 1)`` for ``y``
    on it): the others need no distance (the exact one is a bisection per point)."""
    if shape.kind != 'ellipsoid':
        return p
    a = np.asarray(shape.radii, dtype=np.float64)
    s = np.sqrt((p * p) @ (1.0 / (a * a)))
    return p[(s - 1.0) * a.min() < d]


def fit_margin(shape: Shape, rest_points, segment_lengths) -> float:
    """The margin [m] of ``shape`` for a strand set whose free nodes rest at ``rest_points``
    (..., 3) in the shape's frame (none: the rest shape is not known in that frame) and whose
    segments have the rest lengths ``segment_lengths`` (module docstring).  Only the nodes that
    may lie nearer the shape than the margin so far are measured."""
    margin = float(shape.margin)
    points = None if rest_points is None else np.asarray(rest_points, dtype=np.float64)
    if margin <= 0.0 or (points is not None and points.size == 0):
        return margin
    lengths = np.asarray(segment_lengths, dtype=np.float64)
    positive = lengths[lengths > 0]
    half_segment = 0.5 * float(positive.min()) if positive.size else margin
    fitted = min(margin, half_segment)
    if points is not None:
        near = _nearer_than(_local(points, shape).reshape(-1, 3), shape, fitted)
        if near.size:
            fitted = min(fitted, float(_local_clearance(near, shape).min()))
    return max(0.0, fitted)
