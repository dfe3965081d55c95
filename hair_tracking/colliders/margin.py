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


def clearance(points, shape: Shape) -> np.ndarray:
    """Distance [m] of ``points`` (..., 3), given in the shape's frame, outside the bare shape
    (no margin); 0 inside."""
    p = np.asarray(points, dtype=np.float64) - np.asarray(shape.center, dtype=np.float64)
    q = np.asarray(shape.rotation, dtype=np.float64)
    if q[0] != 0.0 or q[1] != 0.0 or q[2] != 0.0:
        p = p @ quat_to_matrix(q / np.linalg.norm(q))            # R^T p, point by point
    if shape.kind == 'ellipsoid':
        return outside_distance(p, shape.radii)
    if shape.kind == 'plane':
        return np.maximum(p[..., 2], 0.0)
    h = shape.half_length if shape.kind == 'capsule' else 0.0
    core = np.zeros_like(p)
    core[..., 2] = np.clip(p[..., 2], -h, h)
    return np.maximum(np.linalg.norm(p - core, axis=-1) - shape.radius, 0.0)


def fit_margin(shape: Shape, rest_points, segment_lengths) -> float:
    """The margin [m] of ``shape`` for a strand set whose free nodes rest at ``rest_points``
    (..., 3) in the shape's frame (none: the rest shape is not known in that frame) and whose
    segments have the rest lengths ``segment_lengths`` (module docstring)."""
    margin = float(shape.margin)
    points = None if rest_points is None else np.asarray(rest_points, dtype=np.float64)
    if margin <= 0.0 or (points is not None and points.size == 0):
        return margin
    lengths = np.asarray(segment_lengths, dtype=np.float64)
    positive = lengths[lengths > 0]
    half_segment = 0.5 * float(positive.min()) if positive.size else margin
    fitted = min(margin, half_segment)
    if points is not None:
        fitted = min(fitted, float(clearance(points, shape).min()))
    return max(0.0, fitted)
