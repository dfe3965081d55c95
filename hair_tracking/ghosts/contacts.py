"""Head contact of the ghost nodes at one node index of a block, the pushed nodes side by side.

Stage (h) of the ghost kernel (:mod:`hair_tracking.ghosts.kernels`): every node inside the
collision ellipsoid is moved to the surface with friction (the contact model's
:func:`~hair_tracking.colliders.contact.ellipsoid_contact`) and, with length restoration, put
back at its rest distance from its predecessor outside the surface
(:func:`hair_tracking.guides.ftl.restore_node`).

Hair resting on the head keeps 10-15 % of the ghost nodes in contact every substep (gravity
pulls them in by ``g dt^2``).  Done node by node, each contact is a chain of about ten
dependent square roots and divisions plus a hard-to-predict branch.  This module does the same
arithmetic (the contact model's functions) in passes over the *pushed nodes only*, laid out
contiguously, so that LLVM vectorises them:

1. the inside test of all lanes (vectorised: the compaction is a separate loop, which keeps
   this one free of stores that depend on the test), then a branch-free compaction of the
   pushed lanes' indices;
2. their positions, start positions, predecessors, rest segments and lengths gathered into rows
   of the work space;
3. one loop without data-dependent branches (``select``s instead): the radial projection, the
   normal-line refinements unrolled (``refine`` <= :data:`MAX_VECTOR_REFINE`), friction, and the
   first FTL placement with its acceptance test;
4. results written back; the few placements that are still inside go on through the scalar
   :func:`~hair_tracking.guides.ftl.restore_node` from its second placement on.

The result is the node-by-node computation's (the same formulas in the same order; the tests
compare both).  More refinements than :data:`MAX_VECTOR_REFINE` take the node-by-node path.
"""
import math

from numba import njit

from hair_tracking.colliders.contact import (contact_depth_class, ellipsoid_contact,
                                             ellipsoid_level, local_of, push_sorted,
                                             sort_by_depth_class, surface_point, world_of)
from hair_tracking.guides.ftl import ellipsoid_of, FTL_TINY_SQ, restore_f_ok, restore_node

#: Normal-line refinements the vectorised pass unrolls (the ellipsoid default is 2).
MAX_VECTOR_REFINE = 2

#: Rows of the contact work space (per pushed node), after the kernel's own rows.
(_FLAG, _IDX, _PX, _PY, _PZ, _SX, _SY, _SZ, _BX, _BY, _BZ, _EX, _EY, _EZ, _LEN,
 _MORE) = range(16)
CONTACT_ROWS = 16


@njit(cache=True, inline='always', error_model='numpy')
def collide_lanes(X0, P, W, j, lanes, strands, ftl, contact, rot):
    """(h) at node ``j`` of a block's lanes: ``P`` (N, 3, n) the new positions (node ``j``
    changed in place, node ``j - 1`` final), ``X0`` (N, 3, n) the start-of-substep positions
    (friction reference); ``lanes`` = ``(n, k0)`` the lanes and the group-order row of the
    first; ``strands`` = ``(order, seg_len, rest)``: the ghost of each group-order row, the
    block's rest lengths (N-1, n) and the rest shapes; ``contact`` the head
    collider placed by the head pose (:data:`~hair_tracking.colliders.head.Contact`: the
    ellipsoid's semi-axes ``a``, margin included, around the world point ``c``) and ``rot``
    (3, 3) the head rotation (for :func:`~hair_tracking.guides.ftl.restore_node`).  ``W`` is
    work space of at least (:data:`CONTACT_ROWS`, n).  Returns the number of pushed nodes."""
    n, k0 = lanes
    order, seg_len, rest = strands
    r, cx, cy, cz, ax, ay, az, friction, refine = contact
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    # 1. inside test of every lane (vectorises), then the pushed lanes' indices compacted: those
    # the contact's fast path takes first (m_fast of them), then the deeper ones
    n_in = 0
    for kk in range(n):
        q0, q1, q2 = local_of(P[j, 0, kk], P[j, 1, kk], P[j, 2, kk], r, cx, cy, cz)
        depth_class = contact_depth_class(ellipsoid_level(q0, q1, q2, ix, iy, iz))
        W[_FLAG, kk] = depth_class
        n_in += 1 if depth_class != 0.0 else 0
    if n_in == 0:
        return 0
    m_fast, m = sort_by_depth_class(W, (_FLAG, _IDX, _MORE), n)   # _MORE: scratch until 3.
    if refine > MAX_VECTOR_REFINE:
        return _collide_scalar(X0, P, W, j, (m, k0), strands, ftl, contact, rot)
    # 2. gather
    for c in range(m):
        kk = int(W[_IDX, c])
        W[_PX, c] = P[j, 0, kk]
        W[_PY, c] = P[j, 1, kk]
        W[_PZ, c] = P[j, 2, kk]
        W[_SX, c] = X0[j, 0, kk]
        W[_SY, c] = X0[j, 1, kk]
        W[_SZ, c] = X0[j, 2, kk]
        if ftl:
            s = order[k0 + kk]
            W[_BX, c] = P[j - 1, 0, kk]
            W[_BY, c] = P[j - 1, 1, kk]
            W[_BZ, c] = P[j - 1, 2, kk]
            W[_EX, c] = rest[s, j, 0] - rest[s, j - 1, 0]
            W[_EY, c] = rest[s, j, 1] - rest[s, j - 1, 1]
            W[_EZ, c] = rest[s, j, 2] - rest[s, j - 1, 2]
            W[_LEN, c] = seg_len[j - 1, kk]
    # 3. the arithmetic of every pushed node, without branches (the contact model's: its fast
    # path, then its refined projection), then the first placement
    push_sorted(W, (_PX, _PY, _PZ, _SX, _SY, _SZ), m_fast, m, contact, (ix, iy, iz))
    f_ok = restore_f_ok(ax, ay, az)
    for c in range(m):
        wx, wy, wz = W[_PX, c], W[_PY, c], W[_PZ, c]
        more = 0.0
        if ftl:     # the first placement of restore_node, its test as a flag
            bx, by, bz = W[_BX, c], W[_BY, c], W[_BZ, c]
            ux, uy, uz = wx - bx, wy - by, wz - bz
            l2 = ux * ux + uy * uy + uz * uz
            ex, ey, ez = W[_EX, c], W[_EY, c], W[_EZ, c]
            le2 = ex * ex + ey * ey + ez * ez
            rl = W[_LEN, c]
            use_d = l2 > FTL_TINY_SQ
            use_e = le2 > FTL_TINY_SQ
            # ftl_direction: the current segment, else the head-carried rest segment, else -z
            vx = ux if use_d else (r[0] * ex + r[1] * ey + r[2] * ez if use_e else 0.0)
            vy = uy if use_d else (r[3] * ex + r[4] * ey + r[5] * ez if use_e else 0.0)
            vz = uz if use_d else (r[6] * ex + r[7] * ey + r[8] * ez if use_e else -1.0)
            g = rl / math.sqrt(l2 if use_d else (le2 if use_e else 1.0))
            wx, wy, wz = bx + g * vx, by + g * vy, bz + g * vz
            hx, hy, hz = local_of(wx, wy, wz, r, cx, cy, cz)
            more = 0.0 if ellipsoid_level(hx, hy, hz, ix, iy, iz) >= f_ok else 1.0
        W[_PX, c] = wx
        W[_PY, c] = wy
        W[_PZ, c] = wz
        W[_MORE, c] = more
    # 4. scatter; the placements still inside continue node by node
    for c in range(m):
        kk = int(W[_IDX, c])
        wx, wy, wz = W[_PX, c], W[_PY, c], W[_PZ, c]
        if ftl and W[_MORE, c] != 0.0:
            hx, hy, hz = local_of(wx, wy, wz, r, cx, cy, cz)
            yx, yy, yz = surface_point(hx, hy, hz, ax, ay, az, refine)
            wx, wy, wz = restore_node(
                world_of(yx, yy, yz, r, cx, cy, cz), (W[_BX, c], W[_BY, c], W[_BZ, c]),
                W[_LEN, c], (W[_EX, c], W[_EY, c], W[_EZ, c]), rot, ellipsoid_of(contact), 1)
        P[j, 0, kk] = wx
        P[j, 1, kk] = wy
        P[j, 2, kk] = wz
    return m


@njit(cache=True, inline='always', error_model='numpy')
def _collide_scalar(X0, P, W, j, pushed, strands, ftl, contact, rot):
    """:func:`collide_lanes` node by node for the ``m`` pushed lanes listed in ``W[_IDX]``
    (more refinements than the vectorised pass unrolls; ``pushed`` = ``(m, k0)``)."""
    m, k0 = pushed
    order, seg_len, rest = strands
    for c in range(m):
        kk = int(W[_IDX, c])
        moved, y0, y1, y2 = ellipsoid_contact(P[j, 0, kk], P[j, 1, kk], P[j, 2, kk],
                                              X0[j, 0, kk], X0[j, 1, kk], X0[j, 2, kk], contact)
        if moved and ftl:
            s = order[k0 + kk]
            y0, y1, y2 = restore_node(
                (y0, y1, y2), (P[j - 1, 0, kk], P[j - 1, 1, kk], P[j - 1, 2, kk]),
                seg_len[j - 1, kk],
                (rest[s, j, 0] - rest[s, j - 1, 0], rest[s, j, 1] - rest[s, j - 1, 1],
                 rest[s, j, 2] - rest[s, j - 1, 2]), rot, ellipsoid_of(contact), 0)
        P[j, 0, kk] = y0
        P[j, 1, kk] = y1
        P[j, 2, kk] = y2
    return m
