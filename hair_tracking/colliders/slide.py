"""The contact of the trackers without state (blend and turn), on the same shapes: a node
placed at a fixed distance from its predecessor slides along the surface instead of into it,
then goes onto the surface if the curvature still leaves it inside.

For node ``n`` (inside shape ``k``'s surface + margin) after its predecessor ``p``, with ``g``
an outward normal of the shape at ``p``'s level (not of unit length: ``Q (p - C)`` for the
ellipsoid, ``p`` minus its closest core point for a sphere or capsule, the normal for the
plane), the step ``d = n - p`` loses its inward part, ``d - min(0, d.g) / (g.g) g``, and the
node is put at ``length`` from ``p`` along it (:func:`slide_along`).  For ``p`` outside a convex
shape the result lies outside too (on the outer side of the tangent plane of the convex level
set through ``p``) but for the curvature between; :func:`push_radial` then moves a node still
inside onto the surface: along the ray from the centre for the ellipsoid, from the closest core
point for the sphere and capsule, along the normal for the plane.

The inside test of these trackers (:func:`level`) and the ellipsoid's normal use the shape's
world quadric ``(x - C)^T Q (x - C)`` with ``Q = R diag(1 / a^2) R^T``: one matrix-vector
product, no change of axes, so a block of lanes tests in one vector pass.  It is the same
level set as :func:`~hair_tracking.colliders.contact.contact` uses (``F(R^T (x - C))``) and
agrees with it to rounding.

Each rule exists per kind (``*_ellipsoid``, ``*_round``, ``*_plane``: one straight run of
arithmetic) and once with a switch on the kind (:func:`slide_push_of`).  A kernel that runs
lanes side by side switches on the kind outside its lane loop and calls the per-kind function
(or the switch with a constant kind): no branch per lane, and the ellipsoid's arithmetic fused
as the blend tracker's (through a switch whose branches join inside the loop, LLVM fuses the
multiply-adds differently: the last bit of a few nodes in a thousand changes).
"""
import math

from numba import njit

from hair_tracking.colliders.contact import core_point, plane_level
from hair_tracking.colliders.shapes import (A0, CX, CY, CZ, ELLIPSOID, I0, KIND, PLANE, Q00,
                                            Q01, Q02, Q11, Q12, Q22, R02, R12, R22)


# ----------------------------------------------------------------------------- inside test
@njit(cache=True, inline='always')
def quadric(dx, dy, dz, q0, q1, q2, q3, q4, q5):
    """``d^T Q d`` with ``Q``'s entries Q00 Q11 Q22 Q01 Q02 Q12 as scalars (in a vector loop
    they stay in registers): below 1 inside the ellipsoid for ``d = x - C``."""
    return q0 * dx * dx + q1 * dy * dy + q2 * dz * dz + \
        2.0 * (q3 * dx * dy + q4 * dx * dz + q5 * dy * dz)


@njit(cache=True, inline='always')
def quadric_of(sh, k):
    """The entries Q00 Q11 Q22 Q01 Q02 Q12 of shape ``k``'s world quadric."""
    return sh[k, Q00], sh[k, Q11], sh[k, Q22], sh[k, Q01], sh[k, Q02], sh[k, Q12]


@njit(cache=True, inline='always')
def quadric_form(dx, dy, dz, sh, k):
    """:func:`quadric` of shape ``k``."""
    return quadric(dx, dy, dz, sh[k, Q00], sh[k, Q11], sh[k, Q22], sh[k, Q01], sh[k, Q02],
                   sh[k, Q12])


@njit(cache=True, inline='always')
def level_round(x0, x1, x2, sh, k):
    """``|x - core|^2 / (radius + margin)^2 - 1`` of a sphere or capsule (negative inside)."""
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    return (ex * ex + ey * ey + ez * ez) * sh[k, I0] - 1.0


@njit(cache=True, inline='always')
def level(x0, x1, x2, sh, k):
    """Negative where ``x`` is inside shape ``k``'s surface + margin: the ellipsoid's world
    quadric minus 1, :func:`level_round`, the height over the plane + margin."""
    kind = int(sh[k, KIND])
    if kind == ELLIPSOID:
        return quadric_form(x0 - sh[k, CX], x1 - sh[k, CY], x2 - sh[k, CZ], sh, k) - 1.0
    if kind == PLANE:
        return plane_level(x0, x1, x2, sh, k)
    return level_round(x0, x1, x2, sh, k)


# ----------------------------------------------------------------------------- slide
@njit(cache=True, inline='always')
def slide_along(n0, n1, n2, p0, p1, p2, gx, gy, gz, length):
    """The node ``n`` at ``length`` from ``p`` along ``n - p`` without its part against the
    outward normal ``g`` (any length); a step of no length leaves ``n`` as it is.  ``d - (d.g /
    g.g) g`` needs no unit normal: one square root and two divisions."""
    dx, dy, dz = n0 - p0, n1 - p1, n2 - p2
    inward = dx * gx + dy * gy + dz * gz
    gg = gx * gx + gy * gy + gz * gz
    if inward < 0.0 and gg > 0.0:
        a = inward / gg
        dx, dy, dz = dx - a * gx, dy - a * gy, dz - a * gz
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if d <= 0.0:
        return n0, n1, n2
    f = length / d
    return p0 + f * dx, p1 + f * dy, p2 + f * dz


@njit(cache=True, inline='always')
def slide_quadric(n0, n1, n2, p0, p1, p2, length, c, q):
    """:func:`slide_along` the outward normal ``Q (p - c)`` at ``p`` of the ellipsoid of world
    centre ``c`` and quadric entries ``q`` (:func:`quadric`)."""
    ex, ey, ez = p0 - c[0], p1 - c[1], p2 - c[2]
    gx = q[0] * ex + q[3] * ey + q[4] * ez
    gy = q[3] * ex + q[1] * ey + q[5] * ez
    gz = q[4] * ex + q[5] * ey + q[2] * ez
    return slide_along(n0, n1, n2, p0, p1, p2, gx, gy, gz, length)


@njit(cache=True, inline='always')
def slide_ellipsoid(n0, n1, n2, p0, p1, p2, length, sh, k):
    """:func:`slide_quadric` of an ellipsoid shape."""
    return slide_quadric(n0, n1, n2, p0, p1, p2, length, (sh[k, CX], sh[k, CY], sh[k, CZ]),
                         quadric_of(sh, k))


@njit(cache=True, inline='always')
def slide_round(n0, n1, n2, p0, p1, p2, length, sh, k):
    """:func:`slide_along` a sphere's or capsule's outward normal at ``p`` (``p`` minus its
    closest core point)."""
    bx, by, bz, gx, gy, gz = core_point(p0, p1, p2, sh, k)
    return slide_along(n0, n1, n2, p0, p1, p2, gx, gy, gz, length)


@njit(cache=True, inline='always')
def slide_plane(n0, n1, n2, p0, p1, p2, length, sh, k):
    """:func:`slide_along` a plane's normal."""
    return slide_along(n0, n1, n2, p0, p1, p2, sh[k, R02], sh[k, R12], sh[k, R22], length)


# ----------------------------------------------------------------------------- push
@njit(cache=True, inline='always')
def push_quadric(x0, x1, x2, c, q):
    """:func:`push_radial` of the ellipsoid of world centre ``c`` and quadric entries ``q``:
    along the ray from its centre (a point at the centre stays)."""
    dx, dy, dz = x0 - c[0], x1 - c[1], x2 - c[2]
    e = quadric(dx, dy, dz, q[0], q[1], q[2], q[3], q[4], q[5])
    if not 0.0 < e < 1.0:
        return x0, x1, x2
    f = 1.0 / math.sqrt(e)
    return c[0] + f * dx, c[1] + f * dy, c[2] + f * dz


@njit(cache=True, inline='always')
def push_ellipsoid(x0, x1, x2, sh, k):
    """:func:`push_quadric` of an ellipsoid shape."""
    return push_quadric(x0, x1, x2, (sh[k, CX], sh[k, CY], sh[k, CZ]), quadric_of(sh, k))


@njit(cache=True, inline='always')
def slide_push_lane(n, p, c, q, acts):
    """The slide and push of an ellipsoid (world centre ``c``, quadric entries ``q``) for node
    ``n`` after ``p`` (x, y, z tuples) without branches, for a loop over lanes side by side:
    ``n`` inside and ``acts`` is placed at its own step's length ``|n - p|`` from ``p`` along
    the step without its inward part, then radially onto the surface if still inside (the
    length of the slid step from ``|d|^2 - (d.g)^2 / g.g``: one square root); else it stays.
    Returns ``(inside, x, y, z)``."""
    nx, ny, nz = n
    px, py, pz = p
    c0, c1, c2 = c
    q0, q1, q2, q3, q4, q5 = q
    inside = (quadric(nx - c0, ny - c1, nz - c2, q0, q1, q2, q3, q4, q5) < 1.0) & acts
    ex, ey, ez = px - c0, py - c1, pz - c2
    gx = q0 * ex + q3 * ey + q4 * ez                      # outward normal Q (p - c)
    gy = q3 * ex + q1 * ey + q5 * ez
    gz = q4 * ex + q5 * ey + q2 * ez
    dx, dy, dz = nx - px, ny - py, nz - pz
    dd = dx * dx + dy * dy + dz * dz
    dg = min(dx * gx + dy * gy + dz * gz, 0.0)
    a = dg / max(gx * gx + gy * gy + gz * gz, 1e-300)
    # |d - a g|^2 = dd - a dg: back to the step's length with one square root
    f = math.sqrt(dd / max(dd - a * dg, 1e-300))
    dx, dy, dz = dx - a * gx, dy - a * gy, dz - a * gz
    sx, sy, sz = px + f * dx - c0, py + f * dy - c1, pz + f * dz - c2
    e = quadric(sx, sy, sz, q0, q1, q2, q3, q4, q5)
    k = 1.0 / math.sqrt(min(max(e, 1e-300), 1.0))         # radially onto the surface
    return (inside, c0 + k * sx if inside else nx, c1 + k * sy if inside else ny,
            c2 + k * sz if inside else nz)


@njit(cache=True, inline='always')
def push_round(x0, x1, x2, sh, k):
    """:func:`push_radial` of a sphere or capsule: along the ray from the closest core point
    (a point on the core segment stays)."""
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    dd = ex * ex + ey * ey + ez * ez
    if not 0.0 < dd * sh[k, I0] < 1.0:
        return x0, x1, x2
    f = sh[k, A0] / math.sqrt(dd)
    return bx + f * ex, by + f * ey, bz + f * ez


@njit(cache=True, inline='always')
def push_plane(x0, x1, x2, sh, k):
    """:func:`push_radial` of a plane: along its normal."""
    phi = plane_level(x0, x1, x2, sh, k)
    if not phi < 0.0:
        return x0, x1, x2
    return x0 - phi * sh[k, R02], x1 - phi * sh[k, R12], x2 - phi * sh[k, R22]


@njit(cache=True, inline='always')
def slide_push_of(kind, n0, n1, n2, p0, p1, p2, length, sliding, sh, k):
    """The stateless trackers' contact of node ``n`` after ``p`` with shape ``k`` of kind
    ``kind``: the slide (when ``sliding``: the trackers that keep segment lengths), then the
    push onto the surface.  ``kind`` a constant gives the kind's straight code (see
    :func:`~hair_tracking.colliders.contact.contact_of`)."""
    if kind == ELLIPSOID:
        if sliding:
            n0, n1, n2 = slide_ellipsoid(n0, n1, n2, p0, p1, p2, length, sh, k)
        return push_ellipsoid(n0, n1, n2, sh, k)
    if kind == PLANE:
        if sliding:
            n0, n1, n2 = slide_plane(n0, n1, n2, p0, p1, p2, length, sh, k)
        return push_plane(n0, n1, n2, sh, k)
    if sliding:
        n0, n1, n2 = slide_round(n0, n1, n2, p0, p1, p2, length, sh, k)
    return push_round(n0, n1, n2, sh, k)


@njit(cache=True, inline='always')
def slide_push(n0, n1, n2, p0, p1, p2, length, sliding, sh, k):
    """:func:`slide_push_of` shape ``k``."""
    return slide_push_of(int(sh[k, KIND]), n0, n1, n2, p0, p1, p2, length, sliding, sh, k)


@njit(cache=True, inline='always')
def push_radial(x0, x1, x2, sh, k):
    """A point inside shape ``k``'s surface + margin moved onto it (module docstring); a point
    outside is returned as it is."""
    return slide_push_of(int(sh[k, KIND]), x0, x1, x2, x0, x1, x2, 0.0, False, sh, k)
