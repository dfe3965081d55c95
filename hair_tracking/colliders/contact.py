"""The contact model: one node against one posed shape, as scalar functions that every guide
solver and ghost tracker calls inside its own loops (``@njit(inline='always')``: no call, no
array created; a kernel reads the shape from its posed table ``sh`` at row ``k``, see
:mod:`hair_tracking.colliders.shapes`).

**Projection** (:func:`contact_of`, :func:`push_out`, :func:`project`): a node inside a
shape's surface + margin is moved onto it, to the closest point of the surface:

- sphere, capsule: radially from the closest point of the core segment (the centre for a
  sphere; a node on the segment itself goes out along the shape's local x axis);
- plane: along its normal;
- ellipsoid: in its own axes ``q = R^T (x - C)``, the radial projection in the unit-sphere
  space ``y0 = q / sqrt(F(q))`` with ``F(q) = sum (q_k / a_k)^2``, which lies on the surface,
  then ``refine`` times the intersection of the surface with the line from ``q`` along the
  outward normal ``(y_k / a_k^2)_k`` at the current estimate (a quadratic in the line parameter
  with one positive root, ``q`` being inside).  The closest point is the fixed point of this
  map; every iterate lies exactly on the surface.  A node at the centre goes out along the
  shortest semi-axis.  Distance to the true closest point with 2 refinements on the head
  ellipsoid (0.095, 0.08, 0.105) m: 3e-7 m at 2 mm depth, 4e-5 m at 1 cm.

  The contact (:func:`ellipsoid_contact`) takes a fast path for a node just inside (``F(q) >``
  :data:`SHALLOW_LEVEL`, resting hair): one Newton step along the gradient, with friction
  about it (:func:`ellipsoid_newton`), within a few micrometres of the refined point.  The
  closest-point queries (:func:`project`, :func:`depth`) take the refined projection at every
  depth.

**Friction** (:func:`friction`), position-level as in Macklin, Müller, Chentanez & Kim 2014
("Unified Particle Physics for Real-Time Applications"), a proportional reduction in place of a
Coulomb cone: the displacement of the projected node ``y`` from its reference ``r`` is split at
the contact normal ``n`` and its tangential part reduced by the factor ``friction`` (0:
frictionless, 1: sticks).  The reference is where the node would be had it stuck to the shape
over the substep (:func:`carried`: its start position moved with the shape's frame), so a
moving collider drags the hair with its surface velocity.  The node stays on the tangent plane,
outside a convex surface.

**Push-out velocity bound** (:func:`bounded_start`): a position-based solver makes velocity of
every position change, ``v = (x - x_start) / dt``, so a node found inside a shape that appeared
around it, jumped onto it or was reset into it would leave with ``depth / dt`` (5 cm at
dt = 1/240 s: 12 m/s).  The normal part of the node's displacement relative to the shape,
``(y - r) . n``, is allowed up to ``cap`` [m] (a speed bound times ``dt``); the excess is a
push-out and is applied to the start position as well (the stabilisation of Macklin et al. 2014:
a correction applied to both the original and the predicted position adds no velocity), so a
pushed node leaves with at most the shape's normal surface speed plus ``cap / dt`` (the cap on
the speed of resolving penetration that rigid-body engines have, PhysX's maximum
depenetration velocity, Bepu's maximum recovery velocity).

The ellipsoid's projection and friction work in the shape's axes and reproduce the head
collider's arithmetic in its order (same results bit for bit under the same compile flags); the
round shapes and the plane work in the world.  :mod:`hair_tracking.colliders.reference` states
every rule in plain numpy.
"""
import math

from numba import njit

from hair_tracking.core.kernels import FASTMATH  # noqa: F401 (the contact kernels' flags)
from hair_tracking.colliders.shapes import (A0, A1, A2, CX, CY, CZ, ELLIPSOID, FRICTION, I0, I1,
                                            I2, KIND, M00, M01, M02, M10, M11, M12, M20, M21,
                                            M22, OX, OY, OZ, PLANE, PX, PY, PZ, R00, R01, R02,
                                            R10, R11, R12, R20, R21, R22, REFINE)

#: Below this ellipsoid level ``F(q)`` a node is at the centre (no radial direction).
CENTRE_LEVEL = 1e-24
#: Below this squared distance [m^2] from a capsule's core segment a node has no radial
#: direction (it goes out along the shape's local x axis).
TINY_SQ = 1e-24


# ----------------------------------------------------------------------------- frames
@njit(cache=True, inline='always')
def local_of(x0, x1, x2, rot, c0, c1, c2):
    """``R^T (x - c)``: a world point [m] relative to the world point ``c``, in the axes of the
    rotation ``R`` given by its nine entries row by row (``R_ij`` at ``3 i + j``)."""
    dx, dy, dz = x0 - c0, x1 - c1, x2 - c2
    return (rot[0] * dx + rot[3] * dy + rot[6] * dz,
            rot[1] * dx + rot[4] * dy + rot[7] * dz,
            rot[2] * dx + rot[5] * dy + rot[8] * dz)


@njit(cache=True, inline='always')
def world_of(y0, y1, y2, rot, c0, c1, c2):
    """``R y + c``: a point ``y`` in the axes of ``R`` (entries as :func:`local_of`) relative to
    the world point ``c``, back in the world."""
    return (rot[0] * y0 + rot[1] * y1 + rot[2] * y2 + c0,
            rot[3] * y0 + rot[4] * y1 + rot[5] * y2 + c1,
            rot[6] * y0 + rot[7] * y1 + rot[8] * y2 + c2)


@njit(cache=True, inline='always')
def rotation_of(sh, k):
    """The nine entries of shape ``k``'s world axes, row by row (:func:`local_of`)."""
    return (sh[k, R00], sh[k, R01], sh[k, R02], sh[k, R10], sh[k, R11], sh[k, R12], sh[k, R20],
            sh[k, R21], sh[k, R22])


@njit(cache=True, inline='always')
def to_local(x0, x1, x2, sh, k):
    """``R^T (x - C)``: a world point [m] in the axes of shape ``k``, relative to its centre."""
    return local_of(x0, x1, x2, rotation_of(sh, k), sh[k, CX], sh[k, CY], sh[k, CZ])


@njit(cache=True, inline='always')
def from_local(yx, yy, yz, sh, k):
    """``R y + C``: a point in the axes of shape ``k`` back in the world."""
    return world_of(yx, yy, yz, rotation_of(sh, k), sh[k, CX], sh[k, CY], sh[k, CZ])


@njit(cache=True, inline='always')
def carried(x0, x1, x2, sh, k):
    """Where the world point ``x`` is after moving with the frame of shape ``k`` over the
    substep: ``M (x - O_prev) + O`` (the friction reference of a node that started at ``x``;
    the guide solver's rigid carry of the head, in its arithmetic)."""
    ax, ay, az = x0 - sh[k, PX], x1 - sh[k, PY], x2 - sh[k, PZ]
    return (sh[k, M00] * ax + sh[k, M01] * ay + sh[k, M02] * az + sh[k, OX],
            sh[k, M10] * ax + sh[k, M11] * ay + sh[k, M12] * az + sh[k, OY],
            sh[k, M20] * ax + sh[k, M21] * ay + sh[k, M22] * az + sh[k, OZ])


# ----------------------------------------------------------------------------- ellipsoid
@njit(cache=True, inline='always')
def ellipsoid_level(qx, qy, qz, ix, iy, iz):
    """``F(q) = sum q_k^2 / a_k^2`` (``i`` the inverse squared semi-axes): below 1 inside."""
    return qx * qx * ix + qy * qy * iy + qz * qz * iz


@njit(cache=True, inline='always')
def ellipsoid_radial(qx, qy, qz, ix, iy, iz):
    """``(F(q), 1 / sqrt(F(q)))``: the level of ``q`` and the scale of its radial projection
    ``q / sqrt(F)`` onto the ellipsoid (scale 1 at the centre, ``F <`` :data:`CENTRE_LEVEL`,
    where :func:`centre_exit` replaces the projection)."""
    f = ellipsoid_level(qx, qy, qz, ix, iy, iz)
    return f, 1.0 / math.sqrt(f if not f < CENTRE_LEVEL else 1.0)


@njit(cache=True, inline='always')
def ellipsoid_refine(qx, qy, qz, yx, yy, yz, c, ix, iy, iz):
    """One normal-line refinement: the surface point on the line from ``q`` along the outward
    normal at the estimate ``y`` (``c = F(q) - 1``); the branch on the root's form as a
    select."""
    nx, ny, nz = yx * ix, yy * iy, yz * iz
    a = nx * nx * ix + ny * ny * iy + nz * nz * iz
    b = qx * nx * ix + qy * ny * iy + qz * nz * iz
    disc = math.sqrt(b * b - a * c)
    t = -c / (b + disc) if b > 0.0 else (disc - b) / a
    return qx + t * nx, qy + t * ny, qz + t * nz


@njit(cache=True, inline='always')
def centre_exit(ax, ay, az):
    """Where a node at the ellipsoid's centre goes: the end of the shortest semi-axis (the
    first of equal ones)."""
    ex = ax if ax <= ay and ax <= az else 0.0
    ey = ay if ex == 0.0 and ay <= az else 0.0
    ez = az if ex == 0.0 and ey == 0.0 else 0.0
    return ex, ey, ez


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def surface_point(qx, qy, qz, ax, ay, az, refine):
    """Approximate closest point on the ellipsoid ``sum (y_k / a_k)^2 = 1`` of the point ``q``
    (its axes, relative to its centre; inside): the radial projection then ``refine``
    normal-line refinements (module docstring).  A plain call, not inlined (a caller's
    arithmetic around it is not fused with its own)."""
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    f, sc = ellipsoid_radial(qx, qy, qz, ix, iy, iz)
    yx, yy, yz = qx * sc, qy * sc, qz * sc
    c = f - 1.0
    for _ in range(refine):
        yx, yy, yz = ellipsoid_refine(qx, qy, qz, yx, yy, yz, c, ix, iy, iz)
    ex, ey, ez = centre_exit(ax, ay, az)
    deg = f < CENTRE_LEVEL
    return (ex if deg else yx), (ey if deg else yy), (ez if deg else yz)


@njit(cache=True, inline='always')
def ellipsoid_depth(qx, qy, qz, ax, ay, az, ix, iy, iz, refine):
    """How deep [m] the point ``q`` (the ellipsoid's axes, relative to its centre) lies inside
    the ellipsoid of semi-axes ``a`` (``i`` their inverse squares): the distance to its
    :func:`surface_point`; 0 outside."""
    if ellipsoid_level(qx, qy, qz, ix, iy, iz) >= 1.0:
        return 0.0
    yx, yy, yz = surface_point(qx, qy, qz, ax, ay, az, refine)
    return math.sqrt((yx - qx) ** 2 + (yy - qy) ** 2 + (yz - qz) ** 2)


#: :func:`ellipsoid_contact` takes its fast path, one Newton step (:func:`ellipsoid_newton`),
#: for a node with ``F(q)`` above this level (up to about 0.5 % of the semi-axis deep, 0.5 mm on
#: a head): resting contact, hair pulled ``|g| dt^2`` (0.17 mm at 1/240 s) into the surface
#: every substep.
SHALLOW_LEVEL = 0.98


@njit(cache=True, inline='always')
def ellipsoid_newton(qx, qy, qz, f, ix, iy, iz, px, py, pz, mu):
    """The contact's fast path for a node just inside (``F(q) = f`` above
    :data:`SHALLOW_LEVEL`): the surface point ``q - (F - 1) / (2 |g|^2) g`` with ``g`` the
    gradient direction ``(q_k / a_k^2)_k`` (Newton's method on ``F = 1`` along the normal; it
    lands within 2.5 um of :func:`surface_point`'s point at the level's limit, the difference
    falling as the square of the depth, test_colliders_equivalence.py), then :func:`friction`
    about that normal relative to ``p`` (``mu`` 0: none), written with ``1 / |g|^2`` instead of
    a unit vector: one division where the refined projection and its unit normal take four
    square roots and four divisions, a chain each contact waits for.  All in the ellipsoid's
    axes."""
    gx, gy, gz = qx * ix, qy * iy, qz * iz
    inv = 1.0 / (gx * gx + gy * gy + gz * gz)
    t = 0.5 * (f - 1.0) * inv
    yx, yy, yz = qx - t * gx, qy - t * gy, qz - t * gz
    if mu > 0.0:
        mx, my, mz = yx - px, yy - py, yz - pz
        dn = (mx * gx + my * gy + mz * gz) * inv
        yx -= mu * (mx - dn * gx)
        yy -= mu * (my - dn * gy)
        yz -= mu * (mz - dn * gz)
    return yx, yy, yz


@njit(cache=True, inline='always')
def ellipsoid_pushed(qx, qy, qz, rx, ry, rz, placed, inv, exit_point):
    """:func:`ellipsoid_contact`'s refined projection and friction for a node known to lie
    deeper than its fast path takes (:func:`ellipsoid_pushed_shallow` the others), without
    branches on the node's values (the loops over a block's pushed nodes, sorted by
    :func:`contact_depth_class`, of :func:`~hair_tracking.colliders.head.project_block` and the
    paper tracker's :func:`~hair_tracking.ghosts.contacts.collide_lanes`): ``q`` the node in
    the ellipsoid's axes, ``r`` its friction reference (world), ``placed`` as there (at
    most 2 refinements, unrolled), ``inv`` the inverse squared semi-axes, ``exit_point``
    :func:`centre_exit`'s point.  Returns the node's new world position."""
    rot, cx, cy, cz, _, _, _, mu, refine = placed
    ix, iy, iz = inv
    f, sc = ellipsoid_radial(qx, qy, qz, ix, iy, iz)
    yx, yy, yz = qx * sc, qy * sc, qz * sc
    cc = f - 1.0
    if refine >= 1:
        yx, yy, yz = ellipsoid_refine(qx, qy, qz, yx, yy, yz, cc, ix, iy, iz)
    if refine >= 2:
        yx, yy, yz = ellipsoid_refine(qx, qy, qz, yx, yy, yz, cc, ix, iy, iz)
    deg = f < CENTRE_LEVEL
    yx = exit_point[0] if deg else yx
    yy = exit_point[1] if deg else yy
    yz = exit_point[2] if deg else yz
    if mu > 0.0:
        px, py, pz = local_of(rx, ry, rz, rot, cx, cy, cz)
        yx, yy, yz = ellipsoid_friction(yx, yy, yz, px, py, pz, ix, iy, iz, mu)
    return world_of(yx, yy, yz, rot, cx, cy, cz)


@njit(cache=True, inline='always')
def ellipsoid_pushed_shallow(qx, qy, qz, rx, ry, rz, placed, inv):
    """:func:`ellipsoid_contact`'s fast path (:func:`ellipsoid_newton`) for a node known to lie
    just inside (above :data:`SHALLOW_LEVEL`), arguments as :func:`ellipsoid_pushed`.  Returns
    the node's new world position."""
    rot, cx, cy, cz, _, _, _, mu, _ = placed
    ix, iy, iz = inv
    f = ellipsoid_level(qx, qy, qz, ix, iy, iz)
    px, py, pz = qx, qy, qz
    if mu > 0.0:
        px, py, pz = local_of(rx, ry, rz, rot, cx, cy, cz)
    yx, yy, yz = ellipsoid_newton(qx, qy, qz, f, ix, iy, iz, px, py, pz, mu)
    return world_of(yx, yy, yz, rot, cx, cy, cz)


@njit(cache=True, inline='always')
def sort_by_depth_class(w, rows, count):
    """The compaction of a block contact's pushed nodes, branch-free: columns ``0 <= c <
    count`` of the work array ``w``'s row ``flag`` hold each node's
    :func:`contact_depth_class`; row ``idx`` receives the columns of the nodes the fast path
    takes (class 2), then of the deeper ones (class 1), each in order, row ``scratch`` used on
    the way.  ``rows = (flag, idx, scratch)``.  Returns ``(m_fast, m)``: how many take the
    fast path, how many are pushed in all (the columns :func:`push_sorted` takes)."""
    flag, idx, scratch = rows
    m_fast, m_deep = 0, 0
    for c in range(count):
        w[idx, m_fast] = c
        w[scratch, m_deep] = c
        m_fast += 1 if w[flag, c] == 2.0 else 0
        m_deep += 1 if w[flag, c] == 1.0 else 0
    for c in range(m_deep):
        w[idx, m_fast + c] = w[scratch, c]
    return m_fast, m_fast + m_deep


@njit(cache=True, inline='always')
def push_sorted(w, rows, m_fast, m, placed, inv):
    """The contact of a block's pushed nodes, sorted by :func:`contact_depth_class` (the block
    contacts of :func:`~hair_tracking.colliders.head.project_block` and the paper tracker's
    :func:`~hair_tracking.ghosts.contacts.collide_lanes`): columns ``0 <= c < m_fast`` of the
    work array ``w`` take the fast path (:func:`ellipsoid_pushed_shallow`), columns
    ``m_fast <= c < m`` the refined projection (:func:`ellipsoid_pushed`), each loop without
    branches on the nodes' values.  ``rows = (px, py, pz, rx, ry, rz)``: the rows of ``w`` that
    hold the nodes' world positions (replaced by their new positions) and their friction
    references; ``placed`` the collider placed (:data:`~hair_tracking.colliders.head.Contact`),
    ``inv`` its inverse squared semi-axes."""
    rot, cx, cy, cz, ax, ay, az, _, _ = placed
    px, py, pz, rx, ry, rz = rows
    for c in range(m_fast):
        qx, qy, qz = local_of(w[px, c], w[py, c], w[pz, c], rot, cx, cy, cz)
        w[px, c], w[py, c], w[pz, c] = ellipsoid_pushed_shallow(
            qx, qy, qz, w[rx, c], w[ry, c], w[rz, c], placed, inv)
    exit_point = centre_exit(ax, ay, az)
    for c in range(m_fast, m):
        qx, qy, qz = local_of(w[px, c], w[py, c], w[pz, c], rot, cx, cy, cz)
        w[px, c], w[py, c], w[pz, c] = ellipsoid_pushed(
            qx, qy, qz, w[rx, c], w[ry, c], w[rz, c], placed, inv, exit_point)


@njit(cache=True, inline='always')
def contact_depth_class(f):
    """Which path of :func:`ellipsoid_contact` a node at level ``F(q) = f`` takes, as a number a
    block's compaction can sort by: 0 outside (NaN too), 1 the refined projection, 2 the fast
    path."""
    return 0.0 if not f < 1.0 else (2.0 if f > SHALLOW_LEVEL else 1.0)


@njit(cache=True, inline='always')
def ellipsoid_normal(yx, yy, yz, ix, iy, iz):
    """Outward unit normal ``(y_k / a_k^2)_k / |.|`` of the ellipsoid at its surface point
    ``y`` (its axes)."""
    nx, ny, nz = yx * ix, yy * iy, yz * iz
    nn = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
    return nx * nn, ny * nn, nz * nn


@njit(cache=True, inline='always')
def ellipsoid_friction(yx, yy, yz, px, py, pz, ix, iy, iz, mu):
    """:func:`friction` at the ellipsoid's surface point ``y`` (its axes; ``p`` the reference
    in the same axes)."""
    nx, ny, nz = ellipsoid_normal(yx, yy, yz, ix, iy, iz)
    return friction(yx, yy, yz, px, py, pz, nx, ny, nz, mu)


# ----------------------------------------------------------------------------- rules
@njit(cache=True, inline='always')
def friction(yx, yy, yz, px, py, pz, nx, ny, nz, mu):
    """The friction rule: the projected node ``y`` moved back toward its reference ``p`` by
    ``mu`` times the tangential part (to the unit normal ``n``) of ``y - p``.  Any one frame
    for the three points."""
    mx, my, mz = yx - px, yy - py, yz - pz
    dn = mx * nx + my * ny + mz * nz
    return yx - mu * (mx - dn * nx), yy - mu * (my - dn * ny), yz - mu * (mz - dn * nz)


@njit(cache=True, inline='always')
def bounded_start(s0, s1, s2, y0, y1, y2, r0, r1, r2, n0, n1, n2, cap):
    """The push-out velocity bound: the start position ``s`` of a node pushed to ``y`` (unit
    normal ``n`` there; ``r`` where it would be had it stuck to the shape, :func:`carried`)
    moved along ``n`` by the part of ``(y - r) . n`` beyond ``cap`` [m], so that ``(y - s) / dt``
    gains no more than ``cap / dt`` along the normal beyond the shape's own motion.  ``cap < 0``
    (or a node within it) leaves ``s`` as it is."""
    e = (y0 - r0) * n0 + (y1 - r1) * n1 + (y2 - r2) * n2 - cap
    if cap < 0.0 or not e > 0.0:
        return s0, s1, s2
    return s0 + e * n0, s1 + e * n1, s2 + e * n2


# ----------------------------------------------------------------------------- one node
@njit(cache=True, inline='always')
def core_point(x0, x1, x2, sh, k):
    """Sphere, capsule: the closest point of the core segment to ``x`` and ``x`` minus it."""
    ux, uy, uz = sh[k, R02], sh[k, R12], sh[k, R22]
    h = sh[k, A1]
    dx, dy, dz = x0 - sh[k, CX], x1 - sh[k, CY], x2 - sh[k, CZ]
    t = min(max(dx * ux + dy * uy + dz * uz, -h), h)
    bx, by, bz = sh[k, CX] + t * ux, sh[k, CY] + t * uy, sh[k, CZ] + t * uz
    return bx, by, bz, x0 - bx, x1 - by, x2 - bz


@njit(cache=True, inline='always')
def round_normal(ex, ey, ez, dd, sh, k):
    """Unit ``e`` (``dd = |e|^2``), the shape's local x axis when ``e`` has no direction."""
    if dd > TINY_SQ:
        s = 1.0 / math.sqrt(dd)
        return ex * s, ey * s, ez * s
    return sh[k, R00], sh[k, R10], sh[k, R20]


@njit(cache=True, inline='always')
def plane_level(x0, x1, x2, sh, k):
    """Signed height [m] of ``x`` over the plane + margin (negative inside)."""
    return (x0 - sh[k, CX]) * sh[k, R02] + (x1 - sh[k, CY]) * sh[k, R12] + \
        (x2 - sh[k, CZ]) * sh[k, R22] - sh[k, A0]


@njit(cache=True, inline='always')
def ellipsoid_contact(x0, x1, x2, r0, r1, r2, placed):
    """The projection and friction of one node ``x`` (world [m]) against one ellipsoid: the one
    statement of the rule every ellipsoid contact runs (the guide solvers' head collider, the
    FTL pass, the paper tracker's, :func:`contact_ellipsoid` of a posed table).  ``placed`` =
    ``(rot, cx, cy, cz, ax, ay, az, mu, refine)``: the nine entries of its world axes
    (:func:`local_of`), its centre in the world, its semi-axes (margin included), friction
    ``mu`` (0: none) relative to the reference ``r``, normal-line refinements.  A node just
    inside takes the fast path (:func:`ellipsoid_newton`), a deeper one :func:`surface_point`
    and :func:`ellipsoid_friction`.  Returns ``(moved, y0, y1, y2)``; a node outside comes back
    as it is with ``moved`` false."""
    rot, cx, cy, cz, ax, ay, az, mu, refine = placed
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    qx, qy, qz = local_of(x0, x1, x2, rot, cx, cy, cz)
    f = ellipsoid_level(qx, qy, qz, ix, iy, iz)
    if f >= 1.0:
        return False, x0, x1, x2
    px, py, pz = qx, qy, qz
    if mu > 0.0:
        px, py, pz = local_of(r0, r1, r2, rot, cx, cy, cz)
    if f > SHALLOW_LEVEL:
        yx, yy, yz = ellipsoid_newton(qx, qy, qz, f, ix, iy, iz, px, py, pz, mu)
    else:
        yx, yy, yz = surface_point(qx, qy, qz, ax, ay, az, refine)
        if mu > 0.0:
            yx, yy, yz = ellipsoid_friction(yx, yy, yz, px, py, pz, ix, iy, iz, mu)
    y0, y1, y2 = world_of(yx, yy, yz, rot, cx, cy, cz)
    return True, y0, y1, y2


@njit(cache=True, inline='always')
def ellipsoid_projection(x0, x1, x2, placed):
    """The refined projection of :func:`ellipsoid_contact` at every depth, without friction
    (the closest point of the surface, :func:`surface_point`): ``(moved, y0, y1, y2)``."""
    rot, cx, cy, cz, ax, ay, az, _, refine = placed
    qx, qy, qz = local_of(x0, x1, x2, rot, cx, cy, cz)
    if ellipsoid_level(qx, qy, qz, 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)) >= 1.0:
        return False, x0, x1, x2
    yx, yy, yz = surface_point(qx, qy, qz, ax, ay, az, refine)
    y0, y1, y2 = world_of(yx, yy, yz, rot, cx, cy, cz)
    return True, y0, y1, y2


@njit(cache=True, inline='always')
def placed_ellipsoid(sh, k, mu):
    """The ``placed`` tuple of :func:`ellipsoid_contact` for shape ``k`` of a posed table,
    friction ``mu``."""
    return (rotation_of(sh, k), sh[k, CX], sh[k, CY], sh[k, CZ], sh[k, A0], sh[k, A1],
            sh[k, A2], mu, int(sh[k, REFINE]))


@njit(cache=True, inline='always')
def contact_ellipsoid(x0, x1, x2, r0, r1, r2, sh, k, mu):
    """:func:`contact_of` an ellipsoid, friction ``mu`` (0: none): :func:`ellipsoid_contact`
    in its axes."""
    return ellipsoid_contact(x0, x1, x2, r0, r1, r2, placed_ellipsoid(sh, k, mu))


@njit(cache=True, inline='always')
def contact_round(x0, x1, x2, r0, r1, r2, sh, k, mu):
    """:func:`contact_of` a sphere or capsule, friction ``mu`` (0: none): radially from the
    closest point of the core segment, in the world."""
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    dd = ex * ex + ey * ey + ez * ez
    if dd * sh[k, I0] >= 1.0:
        return False, x0, x1, x2
    nx, ny, nz = round_normal(ex, ey, ez, dd, sh, k)
    r = sh[k, A0]
    y0, y1, y2 = bx + r * nx, by + r * ny, bz + r * nz
    if mu > 0.0:
        y0, y1, y2 = friction(y0, y1, y2, r0, r1, r2, nx, ny, nz, mu)
    return True, y0, y1, y2


@njit(cache=True, inline='always')
def contact_plane(x0, x1, x2, r0, r1, r2, sh, k, mu):
    """:func:`contact_of` a plane, friction ``mu`` (0: none): along its normal."""
    phi = plane_level(x0, x1, x2, sh, k)
    if phi >= 0.0:
        return False, x0, x1, x2
    nx, ny, nz = sh[k, R02], sh[k, R12], sh[k, R22]
    y0, y1, y2 = x0 - phi * nx, x1 - phi * ny, x2 - phi * nz
    if mu > 0.0:
        y0, y1, y2 = friction(y0, y1, y2, r0, r1, r2, nx, ny, nz, mu)
    return True, y0, y1, y2


@njit(cache=True, inline='always')
def contact_of(kind, x0, x1, x2, r0, r1, r2, sh, k, mu):
    """One node ``x`` (world [m]) out of shape ``k`` (of kind ``kind``)'s surface + margin,
    then the friction rule with ``mu`` (0: none) relative to the reference ``r``.  Returns
    ``(moved, y0, y1, y2)``; a node outside comes back as it is with ``moved`` false.

    Called with ``kind`` a constant (a kernel switches on ``sh[k, KIND]`` outside its loop
    and calls a loop written once with the constant in each branch), each branch compiles to
    the straight code of its kind; switched inside a loop, the branches join there and LLVM
    fuses the ellipsoid's multiply-adds differently from the head collider's (a few nodes in
    a thousand change in the last bit)."""
    if kind == ELLIPSOID:
        return contact_ellipsoid(x0, x1, x2, r0, r1, r2, sh, k, mu)
    if kind == PLANE:
        return contact_plane(x0, x1, x2, r0, r1, r2, sh, k, mu)
    return contact_round(x0, x1, x2, r0, r1, r2, sh, k, mu)


@njit(cache=True, inline='always')
def push_out(x0, x1, x2, r0, r1, r2, sh, k):
    """:func:`contact_of` shape ``k`` with its friction relative to the reference ``r`` (the
    guide solver's and the paper tracker's contact)."""
    return contact_of(int(sh[k, KIND]), x0, x1, x2, r0, r1, r2, sh, k, sh[k, FRICTION])


@njit(cache=True, inline='always')
def project(x0, x1, x2, sh, k):
    """A node inside shape ``k``'s surface + margin moved to the closest point of it, without
    friction: ``(moved, y0, y1, y2)`` (the collision-aware Follow-The-Leader pass's placements
    and the crease escape).  :func:`contact_of` without friction, but for the ellipsoid its
    refined projection whatever the depth (:func:`ellipsoid_projection`): the closest point,
    as the head's restoration (:func:`~hair_tracking.guides.ftl.restore_node`) and
    :func:`depth` take it."""
    shape = int(sh[k, KIND])
    if shape == ELLIPSOID:
        return ellipsoid_projection(x0, x1, x2, placed_ellipsoid(sh, k, 0.0))
    return contact_of(shape, x0, x1, x2, x0, x1, x2, sh, k, 0.0)


@njit(cache=True, inline='always')
def surface_normal(y0, y1, y2, sh, k):
    """Outward unit normal (world) of shape ``k`` at (or nearest to) ``y``, a point of its
    surface + margin."""
    kind = int(sh[k, KIND])
    if kind == ELLIPSOID:
        qx, qy, qz = to_local(y0, y1, y2, sh, k)
        nx, ny, nz = ellipsoid_normal(qx, qy, qz, sh[k, I0], sh[k, I1], sh[k, I2])
        return (sh[k, R00] * nx + sh[k, R01] * ny + sh[k, R02] * nz,
                sh[k, R10] * nx + sh[k, R11] * ny + sh[k, R12] * nz,
                sh[k, R20] * nx + sh[k, R21] * ny + sh[k, R22] * nz)
    if kind == PLANE:
        return sh[k, R02], sh[k, R12], sh[k, R22]
    bx, by, bz, ex, ey, ez = core_point(y0, y1, y2, sh, k)
    return round_normal(ex, ey, ez, ex * ex + ey * ey + ez * ez, sh, k)


@njit(cache=True, inline='always')
def outside_within(x0, x1, x2, sh, k, tol):
    """Whether ``x`` lies outside shape ``k``'s surface + margin or less than ``tol`` [m]
    inside it (the ellipsoid: ``F >= (1 - tol / a_max)^2``, which bounds the depth by
    ``tol``)."""
    kind = int(sh[k, KIND])
    if kind == ELLIPSOID:
        qx, qy, qz = to_local(x0, x1, x2, sh, k)
        f_ok = 1.0 - tol / max(sh[k, A0], sh[k, A1], sh[k, A2])
        f_ok = f_ok * f_ok
        return ellipsoid_level(qx, qy, qz, sh[k, I0], sh[k, I1], sh[k, I2]) >= f_ok
    if kind == PLANE:
        return plane_level(x0, x1, x2, sh, k) >= -tol
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    inner = max(sh[k, A0] - tol, 0.0)
    return ex * ex + ey * ey + ez * ez >= inner * inner


@njit(cache=True, inline='always')
def depth(x0, x1, x2, sh, k):
    """How deep [m] ``x`` lies inside shape ``k``'s surface + margin (0 outside): for the
    ellipsoid the distance to its surface point of :func:`surface_point`."""
    kind = int(sh[k, KIND])
    if kind == ELLIPSOID:
        qx, qy, qz = to_local(x0, x1, x2, sh, k)
        return ellipsoid_depth(qx, qy, qz, sh[k, A0], sh[k, A1], sh[k, A2], sh[k, I0],
                               sh[k, I1], sh[k, I2], int(sh[k, REFINE]))
    if kind == PLANE:
        return max(-plane_level(x0, x1, x2, sh, k), 0.0)
    bx, by, bz, ex, ey, ez = core_point(x0, x1, x2, sh, k)
    dd = ex * ex + ey * ey + ez * ez
    if dd * sh[k, I0] >= 1.0:
        return 0.0
    return sh[k, A0] - math.sqrt(dd)
