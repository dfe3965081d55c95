"""Plain-numpy statements of the contact model (:mod:`hair_tracking.colliders.contact`,
:mod:`~hair_tracking.colliders.slide`, :mod:`~hair_tracking.colliders.bounds`,
:mod:`~hair_tracking.colliders.pose`): the yardstick the kernels are tested against.  Slow;
for tests and for reading.  ``row`` is one row of a posed table, ``x`` points (n, 3) [m].
"""
import math

import numpy as np

from hair_tracking.colliders.contact import SHALLOW_LEVEL
from hair_tracking.colliders.shapes import (A0, A1, A2, BOUND, BOUND_PAD, CAPSULE, CX, CZ,
                                            ELLIPSOID, FRICTION, I0, I2, KIND, L_CX, L_CZ, L_FRAME,
                                            L_FRICTION, L_KIND, L_MARGIN, L_R00, L_REFINE, L_S0,
                                            L_S1, L_S2, M00, MARGIN, OX, OZ, PLANE, PX, PZ, Q00,
                                            Q01, Q02, Q11, Q12, Q22, R00, REFINE, WIDTH)


def reference_pose(local, rot, pos, rot_prev, pos_prev, jump=math.inf) -> np.ndarray:
    """The posed table of ``local`` for the frames ``rot`` (F, 3, 3), ``pos`` (F, 3) now and
    at the previous substep (:func:`~hair_tracking.colliders.pose.pose_shapes`)."""
    out = np.zeros((local.shape[0], WIDTH))
    for k, row in enumerate(local):
        f = int(row[L_FRAME])
        kind = int(row[L_KIND])
        r_off = row[L_R00:L_R00 + 9].reshape(3, 3)
        c_off = row[L_CX:L_CZ + 1]
        o = out[k]
        o[KIND] = kind
        o[CX:CZ + 1] = rot[f] @ c_off + pos[f]
        o[R00:R00 + 9] = (rot[f] @ r_off).reshape(9)
        margin = row[L_MARGIN]
        o[MARGIN], o[FRICTION], o[REFINE] = margin, row[L_FRICTION], row[L_REFINE]
        if kind == ELLIPSOID:
            a = row[L_S0:L_S2 + 1] + margin
            o[A0:A2 + 1] = a
            o[I0:I2 + 1] = 1.0 / a ** 2
            o[BOUND] = a.max() * (1.0 + BOUND_PAD)
            r = o[R00:R00 + 9].reshape(3, 3)
            qm = r @ np.diag(1.0 / a ** 2) @ r.T
            o[[Q00, Q11, Q22, Q01, Q02, Q12]] = qm[[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]
        elif kind == PLANE:
            o[A0] = margin
            o[BOUND] = math.inf
        else:
            h = row[L_S1] if kind == CAPSULE else 0.0
            o[A0], o[A1] = row[L_S0] + margin, h
            o[I0] = 1.0 / o[A0] ** 2
            o[BOUND] = (o[A0] + h) * (1.0 + BOUND_PAD)
        m = rot[f] @ rot_prev[f].T
        o[OX:OZ + 1] = pos[f]
        o[PX:PZ + 1] = pos_prev[f]
        o[M00:M00 + 9] = m.reshape(9)
        if jump < math.inf and _moved(o, rot_prev[f] @ c_off + pos_prev[f], m, kind) > jump:
            o[M00:M00 + 9] = np.eye(3).reshape(9)
            o[PX:PZ + 1] = pos[f]
    return out


def _moved(o, c_prev, m, kind):
    angle = math.acos(min(1.0, max(-1.0, 0.5 * (np.trace(m) - 1.0))))
    d = o[CX:CZ + 1] - c_prev
    if kind == PLANE:
        return abs(float(d @ _axes(o)[:, 2])) + angle * 1.0
    return float(np.linalg.norm(d)) + angle * o[BOUND]


def _axes(row):
    return row[R00:R00 + 9].reshape(3, 3)


def reference_carried(x, row) -> np.ndarray:
    """Points ``x`` moved with the shape's frame over the substep."""
    m = row[M00:M00 + 9].reshape(3, 3)
    return (np.asarray(x) - row[PX:PZ + 1]) @ m.T + row[OX:OZ + 1]


def reference_surface_point(q, a, refine) -> np.ndarray:
    """The ellipsoid projection of points ``q`` (n, 3) (its axes, inside): radial, then
    ``refine`` normal-line refinements; the centre to the end of the shortest semi-axis."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    a = np.asarray(a, dtype=np.float64)
    f = np.sum((q / a) ** 2, axis=1)
    centre = f < 1e-24
    y = q / np.sqrt(np.where(centre, 1.0, f))[:, None]
    for _ in range(refine):
        n = y / a ** 2
        aa = np.sum(n ** 2 / a ** 2, axis=1)
        bb = np.sum(q * n / a ** 2, axis=1)
        with np.errstate(invalid='ignore', divide='ignore'):
            t = (-bb + np.sqrt(bb ** 2 - aa * (f - 1.0))) / aa
        y = q + t[:, None] * n
    exit_point = np.zeros(3)
    exit_point[int(np.argmin(a))] = a.min()
    y[centre] = exit_point
    return y


def _core(x, row):
    """Closest points of the core segment (sphere, capsule) to ``x``."""
    u = _axes(row)[:, 2]
    c = row[CX:CZ + 1]
    t = np.clip((x - c) @ u, -row[A1], row[A1])
    return c + t[:, None] * u


def reference_inside(x, row) -> np.ndarray:
    """Whether each point is inside the surface + margin."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    kind = int(row[KIND])
    if kind == ELLIPSOID:
        q = (x - row[CX:CZ + 1]) @ _axes(row)
        return np.sum((q / row[A0:A2 + 1]) ** 2, axis=1) < 1.0
    if kind == PLANE:
        return (x - row[CX:CZ + 1]) @ _axes(row)[:, 2] < row[A0]
    return np.linalg.norm(x - _core(x, row), axis=1) < row[A0]


def reference_normal(y, row) -> np.ndarray:
    """Outward unit normals (world) at surface points ``y``."""
    y = np.atleast_2d(np.asarray(y, dtype=np.float64))
    kind = int(row[KIND])
    r = _axes(row)
    if kind == ELLIPSOID:
        n = ((y - row[CX:CZ + 1]) @ r) / row[A0:A2 + 1] ** 2
    elif kind == PLANE:
        n = np.repeat(r[:, 2][None], len(y), axis=0)
    else:
        n = y - _core(y, row)
        flat = np.einsum('ij,ij->i', n, n) <= 1e-24
        n[flat] = r[:, 0]
        return n / np.linalg.norm(n, axis=1)[:, None]
    if kind == ELLIPSOID:
        n = n @ r.T
    return n / np.linalg.norm(n, axis=1)[:, None]


def _ellipsoid_push_out(x, ref, row, with_friction, fast=True):
    """:func:`reference_push_out` of points ``x`` inside an ellipsoid: with ``fast`` those just
    inside (``F(q) >`` :data:`~hair_tracking.colliders.contact.SHALLOW_LEVEL`) one Newton step
    along the gradient ``g`` and friction about ``g``, the others (all without ``fast``)
    :func:`reference_surface_point` and friction about the normal there."""
    r, c, a = _axes(row), row[CX:CZ + 1], row[A0:A2 + 1]
    q = (x - c) @ r
    p = (ref - c) @ r
    f = np.sum((q / a) ** 2, axis=1)
    g = q / a ** 2
    g2 = np.sum(g * g, axis=1)
    y = reference_surface_point(q, a, int(row[REFINE]))
    n = y / a ** 2
    n /= np.linalg.norm(n, axis=1)[:, None]
    shallow = (f > SHALLOW_LEVEL) & fast
    y[shallow] = q[shallow] - (0.5 * (f[shallow] - 1.0) / g2[shallow])[:, None] * g[shallow]
    n[shallow] = g[shallow] / np.sqrt(g2[shallow])[:, None]
    if with_friction and row[FRICTION] > 0.0:
        m = y - p
        y = y - row[FRICTION] * (m - np.sum(m * n, axis=1)[:, None] * n)
    return y @ r.T + c


def reference_push_out(x, ref, row, with_friction=True, fast=True):
    """Points ``x`` moved onto the surface + margin where inside, with the friction rule
    relative to ``ref``: ``(moved (n,), y (n, 3))`` (:func:`contact.contact_of
    <hair_tracking.colliders.contact.contact_of>`; without ``fast`` the ellipsoid's refined
    projection at every depth)."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    ref = np.atleast_2d(np.asarray(ref, dtype=np.float64))
    inside = reference_inside(x, row)
    y = x.copy()
    xi = x[inside]
    kind = int(row[KIND])
    c = row[CX:CZ + 1]
    if kind == ELLIPSOID:
        y[inside] = _ellipsoid_push_out(xi, ref[inside], row, with_friction, fast)
        return inside, y
    if kind == PLANE:
        n = _axes(row)[:, 2]
        yi = xi - (((xi - c) @ n) - row[A0])[:, None] * n
    else:
        core = _core(xi, row)
        yi = core + row[A0] * reference_normal(xi, row)
    if with_friction and row[FRICTION] > 0.0 and len(yi):
        n = reference_normal(yi, row)
        m = yi - ref[inside]
        yi = yi - row[FRICTION] * (m - np.sum(m * n, axis=1)[:, None] * n)
    y[inside] = yi
    return inside, y


def reference_project(x, row):
    """Points ``x`` moved to the closest point of the surface + margin where inside, without
    friction (:func:`contact.project <hair_tracking.colliders.contact.project>`):
    ``(moved (n,), y (n, 3))``."""
    return reference_push_out(x, x, row, with_friction=False, fast=False)


def reference_bounded_start(s, y, r, n, cap) -> np.ndarray:
    """Start positions moved along ``n`` by the part of ``(y - r) . n`` beyond ``cap``."""
    e = np.sum((y - r) * n, axis=-1) - cap
    if cap < 0:
        return np.array(s, dtype=np.float64)
    return s + np.maximum(e, 0.0)[..., None] * n


def reference_depth(x, row) -> np.ndarray:
    """Depth [m] of points inside the surface + margin (0 outside)."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    inside, y = reference_project(x, row)
    return np.where(inside, np.linalg.norm(y - x, axis=1), 0.0)


def reference_level(x, row) -> np.ndarray:
    """The stateless trackers' level (negative inside): quadric - 1, scaled squared distance
    - 1, height over the plane + margin."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    kind = int(row[KIND])
    c = row[CX:CZ + 1]
    if kind == ELLIPSOID:
        q = (x - c) @ _axes(row)
        return np.sum((q / row[A0:A2 + 1]) ** 2, axis=1) - 1.0
    if kind == PLANE:
        return (x - c) @ _axes(row)[:, 2] - row[A0]
    return np.sum((x - _core(x, row)) ** 2, axis=1) / row[A0] ** 2 - 1.0


def reference_slide_push(p, prev, length, row, sliding=True) -> np.ndarray:
    """The stateless trackers' contact of node ``p`` (3,) after ``prev`` (3,): slid at
    ``length`` from ``prev`` along its step without the inward part (the outward normal at
    ``prev``'s level), then moved onto the surface if still inside (radially from the centre
    for the ellipsoid)."""
    p = np.asarray(p, dtype=np.float64)
    prev = np.asarray(prev, dtype=np.float64)
    kind = int(row[KIND])
    c = row[CX:CZ + 1]
    if sliding:
        if kind == ELLIPSOID:
            g = (_axes(row) / row[A0:A2 + 1] ** 2 @ _axes(row).T) @ (prev - c)
        elif kind == PLANE:
            g = _axes(row)[:, 2]
        else:
            g = prev - _core(prev[None], row)[0]
        d = p - prev
        if d @ g < 0.0 and g @ g > 0.0:
            d = d - (d @ g) / (g @ g) * g
        if np.linalg.norm(d) > 0.0:
            p = prev + d * (length / np.linalg.norm(d))
    e = float(reference_level(p, row)[0])
    if e < 0.0:
        if kind == ELLIPSOID:
            if e > -1.0:
                p = c + (p - c) / np.sqrt(e + 1.0)
        elif kind == PLANE:
            p = p - e * _axes(row)[:, 2]
        else:
            core = _core(p[None], row)[0]
            d = p - core
            if np.linalg.norm(d) > 0.0:
                p = core + d * (row[A0] / np.linalg.norm(d))
    return p


def reference_near(x, row) -> np.ndarray:
    """The bound test of points ``x``."""
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    if int(row[KIND]) == PLANE:
        return reference_inside(x, row)
    return np.linalg.norm(x - row[CX:CZ + 1], axis=1) < row[BOUND]


def reference_box_near(lo, hi, row) -> bool:
    """The bound test of the box ``lo .. hi``."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    c = row[CX:CZ + 1]
    if int(row[KIND]) == PLANE:
        n = _axes(row)[:, 2]
        corner = np.where(n > 0.0, lo, hi)
        return bool((corner - c) @ n < row[A0])
    if not np.linalg.norm(np.clip(c, lo, hi) - c) < row[BOUND]:
        return False
    if int(row[KIND]) != CAPSULE:
        return True
    box_lo, box_hi = reference_shape_box(row)
    return bool(np.all(lo < box_hi) and np.all(hi > box_lo))


def reference_shape_box(row):
    """The axis-aligned box ``(lo, hi)`` around a shape + margin (all space for a plane)."""
    c = row[CX:CZ + 1]
    if int(row[KIND]) == PLANE:
        return np.full(3, -np.inf), np.full(3, np.inf)
    e = np.full(3, row[BOUND])
    if int(row[KIND]) == CAPSULE:
        e = (np.abs(_axes(row)[:, 2]) * row[A1] + row[A0]) * (1.0 + BOUND_PAD)
    return c - e, c + e
