"""A node out of every shape at once: the closest point outside the union of a posed table's
shapes, where two overlapping shapes make a crease.

A node inside the union of overlapping shapes (a shoulder capsule running into the chest
capsule) pushed out of one shape at a time (:func:`~hair_tracking.colliders.contact.project`,
in table order) may land inside the other, and back: in a crease whose surfaces meet at a
shallow angle ``phi`` the depth shrinks by about ``cos(phi)`` a pair of projections, so a few
sweeps leave the node millimetres inside.  :func:`escape` takes the closest of the candidate
points instead (the closest point outside a union of shapes lies on one surface, or on the
curve where two surfaces meet):

- each shape's own projection that lies outside every other shape;
- for each pair of shapes whose surfaces are given by a distance (sphere, capsule, plane), the
  closest point of their intersection curve (:func:`crease_point`): Gauss-Newton on the two
  signed distances ``f_a(y) = f_b(y) = 0``, each step the least-norm move onto both tangent
  planes, ``d = alpha n_a + beta n_b`` with ``alpha + c beta = -f_a``, ``c alpha + beta =
  -f_b``, ``c = n_a . n_b`` (the projection onto the intersection of two constraint manifolds
  as in Nocedal & Wright, "Numerical Optimization", 2006, ch. 18, and the two-constraint
  solve of position-based dynamics, Mueller et al. 2007); exact in one step for planes,
  quadratic for spheres, which meet in a circle;
- when none of them lies outside every shape, the points where three surfaces meet
  (:func:`corner_point`: Newton on the three signed distances), the closest one outside every
  shape; failing that, projections shape by shape, :data:`SWEEPS` sweeps.

Ellipsoids take part through their projections and the sweeps, not through creases.
"""
import math

from numba import njit

from hair_tracking.colliders.bounds import near
from hair_tracking.colliders.contact import core_point, outside_within, plane_level, project
from hair_tracking.colliders.shapes import A0, ELLIPSOID, KIND, PLANE, R02, R12, R22

#: Newton steps of :func:`crease_point` and :func:`corner_point` at most.
CREASE_STEPS = 16
#: A point within this fraction of the largest size (or of a metre) of the surfaces meets them.
MET = 1e-12
#: Below this ``1 - (n_a . n_b)^2`` two surfaces are tangent (no crease between them).
PARALLEL = 1e-9
#: Sweeps of projections, shape by shape, when no candidate of :func:`escape` is outside.
SWEEPS = 16


@njit(cache=True, inline='always')
def signed_distance(x0, x1, x2, sh, k):
    """``(f, n0, n1, n2)``: the signed distance [m] of ``x`` to the surface + margin of shape
    ``k`` (a sphere, capsule or plane; negative inside) and the outward unit normal there
    (zero where it has no direction)."""
    if sh[k, KIND] == PLANE:
        return plane_level(x0, x1, x2, sh, k), sh[k, R02], sh[k, R12], sh[k, R22]
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    d = math.sqrt(ex * ex + ey * ey + ez * ez)
    if not d > 0.0:
        return -sh[k, A0], 0.0, 0.0, 0.0
    return d - sh[k, A0], ex / d, ey / d, ez / d


@njit(cache=True)
def crease_point(x0, x1, x2, sh, a, b):
    """The closest point to ``x`` of the curve where the surfaces + margins of shapes ``a`` and
    ``b`` (spheres, capsules, planes) meet (module docstring): ``(found, y0, y1, y2)``;
    ``found`` is false where the surfaces are tangent, or the steps do not reach both."""
    y0, y1, y2 = x0, x1, x2
    close = MET * max(sh[a, A0], sh[b, A0], 1.0)
    for _ in range(CREASE_STEPS):
        fa, a0, a1, a2 = signed_distance(y0, y1, y2, sh, a)
        fb, b0, b1, b2 = signed_distance(y0, y1, y2, sh, b)
        if abs(fa) <= close and abs(fb) <= close:
            return True, y0, y1, y2
        c = a0 * b0 + a1 * b1 + a2 * b2
        det = 1.0 - c * c
        if not det > PARALLEL:
            return False, x0, x1, x2
        alpha = (c * fb - fa) / det
        beta = (c * fa - fb) / det
        y0 += alpha * a0 + beta * b0
        y1 += alpha * a1 + beta * b1
        y2 += alpha * a2 + beta * b2
    return False, x0, x1, x2


@njit(cache=True)
def corner_point(x0, x1, x2, sh, a, b, c):
    """The point near ``x`` where the surfaces + margins of shapes ``a``, ``b`` and ``c``
    (spheres, capsules, planes) meet: Newton on the three signed distances, each step the move
    onto the three tangent planes (Cramer's rule).  ``(found, y0, y1, y2)``; ``found`` is
    false where two of the normals are (nearly) parallel or the steps do not reach all three."""
    y0, y1, y2 = x0, x1, x2
    close = MET * max(sh[a, A0], sh[b, A0], sh[c, A0], 1.0)
    for _ in range(CREASE_STEPS):
        fa, a0, a1, a2 = signed_distance(y0, y1, y2, sh, a)
        fb, b0, b1, b2 = signed_distance(y0, y1, y2, sh, b)
        fc, c0, c1, c2 = signed_distance(y0, y1, y2, sh, c)
        if abs(fa) <= close and abs(fb) <= close and abs(fc) <= close:
            return True, y0, y1, y2
        bc0, bc1, bc2 = b1 * c2 - b2 * c1, b2 * c0 - b0 * c2, b0 * c1 - b1 * c0
        ca0, ca1, ca2 = c1 * a2 - c2 * a1, c2 * a0 - c0 * a2, c0 * a1 - c1 * a0
        ab0, ab1, ab2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        det = a0 * bc0 + a1 * bc1 + a2 * bc2
        if not abs(det) > math.sqrt(PARALLEL):
            return False, x0, x1, x2
        y0 -= (fa * bc0 + fb * ca0 + fc * ab0) / det
        y1 -= (fa * bc1 + fb * ca1 + fc * ab1) / det
        y2 -= (fa * bc2 + fb * ca2 + fc * ab2) / det
    return False, x0, x1, x2


@njit(cache=True, inline='always')
def outside_all(x0, x1, x2, sh, tol):
    """Whether ``x`` lies outside every shape's surface + margin, or less than ``tol`` [m]
    inside."""
    for k in range(sh.shape[0]):
        if near(x0, x1, x2, sh, k) and not outside_within(x0, x1, x2, sh, k, tol):
            return False
    return True


@njit(cache=True, inline='always')
def _nearer(found, y0, y1, y2, x0, x1, x2, sh, tol, best, z0, z1, z2):
    """``(best, z0, z1, z2)``, with the candidate ``y`` taken instead when it was found, lies
    outside every shape and is nearer to ``x`` (squared distance ``best``)."""
    if found and outside_all(y0, y1, y2, sh, tol):
        d = (y0 - x0) ** 2 + (y1 - x1) ** 2 + (y2 - x2) ** 2
        if d < best:
            return d, y0, y1, y2
    return best, z0, z1, z2


@njit(cache=True)
def escape(x0, x1, x2, sh, tol):
    """The closest point to ``x`` outside every shape of the posed table ``sh`` (within ``tol``
    [m]; module docstring: a shape's own projection or a point of a crease, else a corner):
    ``(moved, y0, y1, y2)``, ``x`` itself with ``moved`` false when it is outside already."""
    if outside_all(x0, x1, x2, sh, tol):
        return False, x0, x1, x2
    best = math.inf
    z0, z1, z2 = x0, x1, x2
    shapes = sh.shape[0]
    for k in range(shapes):
        if not near(x0, x1, x2, sh, k):
            continue
        moved, y0, y1, y2 = project(x0, x1, x2, sh, k)
        best, z0, z1, z2 = _nearer(moved, y0, y1, y2, x0, x1, x2, sh, tol, best, z0, z1, z2)
    for a in range(shapes):
        if sh[a, KIND] == ELLIPSOID:
            continue
        for b in range(a + 1, shapes):
            if sh[b, KIND] == ELLIPSOID:
                continue
            if not (near(x0, x1, x2, sh, a) or near(x0, x1, x2, sh, b)):
                continue
            found, y0, y1, y2 = crease_point(x0, x1, x2, sh, a, b)
            best, z0, z1, z2 = _nearer(found, y0, y1, y2, x0, x1, x2, sh, tol, best,
                                       z0, z1, z2)
    if best < math.inf:
        return True, z0, z1, z2
    for a in range(shapes):
        for b in range(a + 1, shapes):
            for c in range(b + 1, shapes):
                if sh[a, KIND] == ELLIPSOID or sh[b, KIND] == ELLIPSOID or \
                        sh[c, KIND] == ELLIPSOID:
                    continue
                if not (near(x0, x1, x2, sh, a) or near(x0, x1, x2, sh, b)
                        or near(x0, x1, x2, sh, c)):
                    continue
                found, y0, y1, y2 = corner_point(x0, x1, x2, sh, a, b, c)
                best, z0, z1, z2 = _nearer(found, y0, y1, y2, x0, x1, x2, sh, tol, best,
                                           z0, z1, z2)
    if best < math.inf:
        return True, z0, z1, z2
    y0, y1, y2 = x0, x1, x2
    for _ in range(SWEEPS):
        for k in range(shapes):
            if near(y0, y1, y2, sh, k):
                y0, y1, y2 = project(y0, y1, y2, sh, k)[1:]
        if outside_all(y0, y1, y2, sh, tol):
            break
    return True, y0, y1, y2
