"""Follow-The-Leader (FTL) guide strands: exactly inextensible in one root-to-tip pass.

Müller, Kim & Chentanez 2012, "Fast Simulation of Inextensible Hair and Fur": after prediction,
walk the strand from the root to the tip and put every node at its rest distance from its
(already placed) predecessor, along the current direction::

    p_i <- p_{i-1} + r_{i-1} (p_i - p_{i-1}) / |p_i - p_{i-1}|,    d_i = p_i(new) - p_i(old)

The correction ``d_i`` is recorded; the velocity update then subtracts ``s_damp d_{i+1} / dt``
from node ``i`` (see :func:`hair_tracking.guides.integrate.finalize_block`), which removes the
large
unphysical whip of plain FTL; ``s_damp`` 0.8–0.9 is usual (it adds numerical damping, Han &
Harada 2013). Nodes 0 and 1 are the attached roots and are not moved. A known property of the
correction: in a strand resting under gravity the positions stay put but the stored velocities do
not vanish (each substep gravity's prediction is undone by the pass, and ``v_i = s_damp (v_{i+1} +
g dt)`` settles at up to ``s_damp g dt / (1 - s_damp)``, 0.37 m/s at dt = 1/240 s and
``s_damp = 0.9``); use displacements, not ``v``, to judge whether FTL hair is at rest.

Bending comes first: a Jacobi sweep of the second-neighbour distance constraints with
``bend_stiffness`` (:func:`hair_tracking.guides.pbd_constraints.jacobi_bend_block`: the gradient
of their energy, not a Gauss–Seidel sweep, so that bent strands come to rest), then the FTL pass
restores the lengths exactly.  A substep longer than the bending's reference step runs as
several inner steps of gravity, the sweep and the pass (:func:`ftl_block`,
:func:`hair_tracking.guides.solver.ftl_inner_steps`), the corrections ``d_i`` of their passes
summed. ``iterations`` of the scene does not apply to FTL.

Degenerate input: if a segment has collapsed (``|p_i - p_{i-1}| < 1e-12`` m) the node is placed
along the segment's rest direction carried by the head (``R (rest_i - rest_{i-1})``); a
zero rest length places the node on its predecessor. No NaN can arise.
"""
from collections import namedtuple
import math

import numpy as np
from numba import njit, prange

from hair_tracking.colliders.bounds import near
from hair_tracking.colliders.contact import (ellipsoid_contact, ellipsoid_level, local_of,
                                             outside_within, surface_point)
from hair_tracking.colliders.crease import escape
from hair_tracking.colliders.head import placed, placed_shape, rotation_entries, to_head
from hair_tracking.core.kernels import BLOCK, FASTMATH, parallel_and_serial
from hair_tracking.guides.integrate import (carry_rigid_block, finalize_block, max_step_sq_block,
                                            predict_block, shape_pulled, shape_spring)
from hair_tracking.guides.pbd_constraints import jacobi_bend_block
from hair_tracking.guides.split import split_due

#: Static data of :func:`ftl_step`: ``rest`` (S, N, 3) head frame [m], ``inv_mass`` (S, N),
#: ``rest_length`` (S, N-1), ``bend_rest`` (S, N-2) second-neighbour rest distances [m],
#: ``bend_w`` from :func:`hair_tracking.guides.pbd_constraints.pair_weights` with gap 2.
FtlModel = namedtuple('FtlModel', ['rest', 'inv_mass', 'rest_length', 'bend_rest', 'bend_w'])
#: Parameters of :func:`ftl_step`: inner steps of a substep (:func:`ftl_block`), the bending
#: stiffness (0: no bending), the velocity correction ``s_damp`` 0..1, the displacement clamp
#: [m] (0: off), whether to finalize.
FtlParams = namedtuple('FtlParams', ['inner_steps', 'bend_stiffness', 's_damp', 'max_disp',
                                     'do_finalize'])
#: Work space of the FTL kernels: ``corr`` (S, N, 3) the FTL corrections, ``x_ref`` (S, N, 3)
#: the friction reference (the start-of-substep positions carried rigidly with the head;
#: written when the collider has friction), and for a run of substeps ``counts`` (B, K, 2)
#: int64, ``steps`` (B, K) or (B, 0) and ``before`` (S, N, 3) (``B`` the block count, ``K``
#: the substeps); :func:`ftl_advance` takes them with a head axis (a place axis on the
#: positions' shapes).
FtlWork = namedtuple('FtlWork', ['corr', 'x_ref', 'counts', 'steps', 'before'])
#: What drives a run of substeps of one head: ``rots`` (K + 1, 3, 3), ``poss`` (K + 1, 3) the
#: head poses at the start and at the end of every substep, ``rels`` (K, 3, 3) with
#: ``rels[k] = rots[k + 1] rots[k]^T``, and the constant fields of
#: :data:`~hair_tracking.guides.integrate.StepMotion` (:func:`ftl_advance` takes the poses
#: with a head axis).
RunDrive = namedtuple('RunDrive', ['rots', 'poss', 'rels', 'gravity', 'damp', 'dt', 'shock',
                                   'shape'])

#: Work items of :func:`ftl_advance`'s parallel loop (each a run of blocks).
CHUNKS = 64
#: Below this squared segment length [m²] the current direction is unreliable.
FTL_TINY_SQ = 1e-24


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_pass_block(x, rest, rest_length, rot, corr, s0, s1, add, collide):
    """FTL pass over strands ``s0..s1-1`` in place; ``corr`` (S, N, 3) receives the ``d_i``
    (``add``: added to what it holds, a later inner step of :func:`ftl_block`).

    ``rot`` (3, 3) is the head rotation (only used for collapsed segments).  ``collide``:
    ``None``, or ``(x_ref, inv_mass, contact)`` for the pass aware of the head collider: the
    friction reference (S, N, 3), the inverse masses and the collider placed by the head pose
    (:data:`~hair_tracking.colliders.head.Contact`).  Then, node ``i`` of the block's strands
    placed, every free one (``inv_mass > 0``) inside the collider goes through
    :func:`contact_node` before node ``i + 1`` is placed (the inside test of a node index in
    the placement's loop, without branches; the contacts after it).  Returns the nodes the
    collider moved.  (One function for both: numba compiles each variant with the other's
    branches removed.)
    """
    n = x.shape[1]
    for s in range(s0, s1):
        for i in range(2):
            if not add:
                corr[s, i, 0] = 0.0
                corr[s, i, 1] = 0.0
                corr[s, i, 2] = 0.0
    pushed = 0
    if collide is not None:
        x_ref, inv_mass, contact = collide
        rot9, cx, cy, cz, ax, ay, az, _, _ = contact
        ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    for i in range(2, n):
        inside = 0
        for s in range(s0, s1):
            r = rest_length[s, i - 1]
            dx = x[s, i, 0] - x[s, i - 1, 0]
            dy = x[s, i, 1] - x[s, i - 1, 1]
            dz = x[s, i, 2] - x[s, i - 1, 2]
            dx, dy, dz, f = ftl_direction(
                dx, dy, dz, r, rest[s, i, 0] - rest[s, i - 1, 0],
                rest[s, i, 1] - rest[s, i - 1, 1], rest[s, i, 2] - rest[s, i - 1, 2], rot)
            nx = x[s, i - 1, 0] + f * dx
            ny = x[s, i - 1, 1] + f * dy
            nz = x[s, i - 1, 2] + f * dz
            if add:
                corr[s, i, 0] += nx - x[s, i, 0]
                corr[s, i, 1] += ny - x[s, i, 1]
                corr[s, i, 2] += nz - x[s, i, 2]
            else:
                corr[s, i, 0] = nx - x[s, i, 0]
                corr[s, i, 1] = ny - x[s, i, 1]
                corr[s, i, 2] = nz - x[s, i, 2]
            x[s, i, 0] = nx
            x[s, i, 1] = ny
            x[s, i, 2] = nz
            if collide is not None:
                qx, qy, qz = local_of(nx, ny, nz, rot9, cx, cy, cz)
                hit = inv_mass[s, i] > 0.0 and ellipsoid_level(qx, qy, qz, ix, iy, iz) < 1.0
                inside |= (1 if hit else 0) << (s - s0)
        if collide is not None:
            while inside:
                k = 0
                while not (inside >> k) & 1:
                    k += 1
                inside &= inside - 1
                pushed += contact_node(x, x_ref, rest, rest_length, rot, corr, contact, s0 + k,
                                       i)
    return pushed


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def contact_node(x, x_ref, rest, rest_length, rot, corr, contact, s, i):
    """Node ``i`` of strand ``s``, just placed by the FTL pass, against the head collider
    ``contact``: if inside, moved to the surface with friction relative to ``x_ref[s, i]``
    (:func:`~hair_tracking.colliders.contact.ellipsoid_contact`, whose fast path takes most
    contacts: hair resting on the head, a fraction of a millimetre deep) and put back at its rest
    distance from its predecessor outside the surface (:func:`restore_node`; that placement is
    added to ``corr``, the push is not).  Returns 1 if the node was inside, else 0."""
    moved, y0, y1, y2 = ellipsoid_contact(x[s, i, 0], x[s, i, 1], x[s, i, 2], x_ref[s, i, 0],
                                          x_ref[s, i, 1], x_ref[s, i, 2], contact)
    if not moved:
        return 0
    px, py, pz = restore_node(
        (y0, y1, y2), (x[s, i - 1, 0], x[s, i - 1, 1], x[s, i - 1, 2]), rest_length[s, i - 1],
        (rest[s, i, 0] - rest[s, i - 1, 0], rest[s, i, 1] - rest[s, i - 1, 1],
         rest[s, i, 2] - rest[s, i - 1, 2]), rot, ellipsoid_of(contact), 0)
    corr[s, i, 0] += px - y0
    corr[s, i, 1] += py - y1
    corr[s, i, 2] += pz - y2
    x[s, i, 0] = px
    x[s, i, 1] = py
    x[s, i, 2] = pz
    return 1


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def ftl_direction(dx, dy, dz, r, ex, ey, ez, rot):
    """``(d, f)`` of one FTL placement ``p = b + f d`` at rest length ``r`` along ``d`` (the
    current segment ``p - b``); a collapsed segment (``|d|^2 <= FTL_TINY_SQ``) continues along the
    rest segment ``e`` (head frame) carried by the head rotation ``rot``, a zero rest segment
    along -z with ``f = r``."""
    l2 = dx * dx + dy * dy + dz * dz
    if l2 > FTL_TINY_SQ:
        return dx, dy, dz, r / math.sqrt(l2)
    le2 = ex * ex + ey * ey + ez * ez
    if le2 > FTL_TINY_SQ:
        return (rot[0, 0] * ex + rot[0, 1] * ey + rot[0, 2] * ez,
                rot[1, 0] * ex + rot[1, 1] * ey + rot[1, 2] * ez,
                rot[2, 0] * ex + rot[2, 1] * ey + rot[2, 2] * ez, r / math.sqrt(le2))
    return 0.0, 0.0, -1.0, r


#: Surface projections per node in :func:`restore_node` at most (the tolerance below ends most
#: contacts after one or two).  Long segments need more: with 10 cm segments (1.5 m strands,
#: 'ftl segment 100 mm' of the quick stability matrix) and ghosts tracked once per pose, 4 left
#: ghost nodes 6.2 mm inside the head (margin 4 mm); 8 leave none inside.
RESTORE_ITERATIONS = 8
#: Depth [m] inside the collision surface at which :func:`restore_node` stops iterating.  The
#: alternating placements converge geometrically: on the bundled walk with the default head, a
#: pushed ghost node lies a median 2 um (90th percentile 15 um) inside after the first placement
#: and 0.03 um after the second, so iterating to the strict surface spent all the projections
#: (then four) on sub-micrometre depths in most contacts (and still ended a few um inside).
#: 10 um is 0.25 % of the default 4 mm margin.
RESTORE_TOLERANCE = 1e-5
#: A node of :func:`ftl_restore_shapes` whose squared distance from its predecessor is within
#: this fraction of the rest length's square, and which lies outside (as
#: :data:`RESTORE_TOLERANCE` accepts), is left where it is, and so is every node before the first
#: that is not: the pass would put it back within about 1e-12 m of itself.  Only strands a shape
#: pushed are walked again, from their first pushed node.
RESTORE_LENGTH_TOLERANCE = 1e-10


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def restore_f_ok(ax, ay, az):
    """``F(q)`` from which :func:`restore_node` accepts a placement (see RESTORE_TOLERANCE)."""
    f_ok = 1.0 - RESTORE_TOLERANCE / max(ax, ay, az)
    return f_ok * f_ok


#: The ellipsoid of the collision-aware FTL pass, a plain tuple in these fields' order: its
#: centre in the world ``cx, cy, cz`` [m], its semi-axes ``ax, ay, az`` [m] (the margin
#: included, head axes) and the projection refinements ``refine``
#: (:func:`ellipsoid_of`).
Ellipsoid = namedtuple('Ellipsoid', ['cx', 'cy', 'cz', 'ax', 'ay', 'az', 'refine'])


@njit(cache=True, inline='always')
def ellipsoid_of(contact):
    """The :data:`Ellipsoid` of a :data:`~hair_tracking.colliders.head.Contact`."""
    _, cx, cy, cz, ax, ay, az, _, refine = contact                     # Contact
    return cx, cy, cz, ax, ay, az, refine


@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def restore_node(p, b, r, e, rot, ellipsoid, first):
    """One node of the collision-aware FTL pass (:func:`contact_node`): ``p`` put at the rest
    distance ``r`` from its predecessor ``b`` and out of the ellipsoid (:data:`Ellipsoid`:
    semi-axes ``a``, world centre ``c``, turned by the head rotation ``rot`` (3, 3)), at most
    :data:`RESTORE_ITERATIONS` times: it stops as soon as a placement lies outside or less than
    :data:`RESTORE_TOLERANCE` inside (``F(q) >= (1 - tol / a_max)^2``, which bounds the depth
    by ``tol``).  ``e`` is the rest segment in the head frame, the direction used when ``p``
    and ``b`` coincide.  World [m]; ``p``, ``b``, ``e`` are (x, y, z) tuples.  ``first`` (0
    normally): the placements already made, for a caller that made the first ones itself
    (``p`` is then the surface point the next placement starts from).  Returns the node (x, y,
    z).  The rotation is the matrix here, not a contact's entries
    (:func:`~hair_tracking.colliders.contact.local_of`): the pass's placements follow its
    arithmetic to the last bit."""
    px, py, pz = p
    bx, by, bz = b
    ex, ey, ez = e
    cx, cy, cz, ax, ay, az, refine = ellipsoid
    ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
    f_ok = restore_f_ok(ax, ay, az)
    for k in range(first, RESTORE_ITERATIONS + 1):
        dx, dy, dz, f = ftl_direction(px - bx, py - by, pz - bz, r, ex, ey, ez, rot)
        px, py, pz = bx + f * dx, by + f * dy, bz + f * dz
        if k == RESTORE_ITERATIONS:
            break
        qx, qy, qz = to_head(px, py, pz, rot, cx, cy, cz)
        if qx * qx * ix + qy * qy * iy + qz * qz * iz >= f_ok:
            break
        yx, yy, yz = surface_point(qx, qy, qz, ax, ay, az, refine)
        px = rot[0, 0] * yx + rot[0, 1] * yy + rot[0, 2] * yz + cx
        py = rot[1, 0] * yx + rot[1, 1] * yy + rot[1, 2] * yz + cy
        pz = rot[2, 0] * yx + rot[2, 1] * yy + rot[2, 2] * yz + cz
    return px, py, pz


@njit(cache=True, nogil=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def ftl_restore_shapes(x, x_old, rest, rest_length, rot, sh, corr, cap):
    """Kernel: a collision-aware FTL pass against every shape of the posed table ``sh`` (the
    body's bust), run after their contact (:func:`~hair_tracking.colliders.kernels.collide`)
    moved nodes, which stretches their segments.

    Each strand is walked from its first node off its rest distance
    (:data:`RESTORE_LENGTH_TOLERANCE`) or more than :data:`RESTORE_TOLERANCE` inside a shape:
    each node is put at its rest distance from its predecessor (:func:`ftl_direction`, ``rot``
    the head rotation for a collapsed segment), and while that point lies inside a shape it is
    moved to the closest point outside every shape (:func:`~hair_tracking.colliders.crease.escape`:
    a surface, or the crease where two overlapping shapes meet) and put back at the rest
    distance, up to :data:`RESTORE_ITERATIONS` times, so lengths stay exact.

    The push-out velocity bound holds for the walk too: of a node's correction ``c``, at most
    ``cap`` [m] (``cap < 0``: no bound) is motion, added to ``corr`` (the velocity update damps
    it like the first pass's); the rest is applied to ``x_old`` as well (as
    :func:`~hair_tracking.colliders.contact.bounded_start` does), so a strand pushed far by a
    shape that jumped or appeared is moved without being launched.  Returns the number of
    strands walked."""
    walked = 0
    for s in prange(x.shape[0]):
        walked += _restore_shapes_strand(x, x_old, rest, rest_length, rot, sh, corr, cap, s)
    return walked


@njit(cache=True, inline='always')
def _inside_shape(x0, x1, x2, sh):
    """The first shape of ``sh`` that ``x`` lies more than :data:`RESTORE_TOLERANCE` inside,
    -1 for none."""
    for k in range(sh.shape[0]):
        if near(x0, x1, x2, sh, k) and not outside_within(x0, x1, x2, sh, k, RESTORE_TOLERANCE):
            return k
    return -1


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _restore_shapes_strand(x, x_old, rest, rest_length, rot, sh, corr, cap, s):
    """:func:`ftl_restore_shapes` of strand ``s``; 1 if walked, else 0."""
    n = x.shape[1]
    start = n
    for i in range(2, n):
        dx, dy, dz = x[s, i, 0] - x[s, i - 1, 0], x[s, i, 1] - x[s, i - 1, 1], \
            x[s, i, 2] - x[s, i - 1, 2]
        r2 = rest_length[s, i - 1] * rest_length[s, i - 1]
        if abs(dx * dx + dy * dy + dz * dz - r2) > RESTORE_LENGTH_TOLERANCE * r2 or \
                _inside_shape(x[s, i, 0], x[s, i, 1], x[s, i, 2], sh) >= 0:
            start = i
            break
    for i in range(start, n):
        ox, oy, oz = x[s, i, 0], x[s, i, 1], x[s, i, 2]
        bx, by, bz = x[s, i - 1, 0], x[s, i - 1, 1], x[s, i - 1, 2]
        ex, ey, ez = rest[s, i, 0] - rest[s, i - 1, 0], rest[s, i, 1] - rest[s, i - 1, 1], \
            rest[s, i, 2] - rest[s, i - 1, 2]
        r = rest_length[s, i - 1]
        px, py, pz = ox, oy, oz
        for it in range(RESTORE_ITERATIONS + 1):
            dx, dy, dz, f = ftl_direction(px - bx, py - by, pz - bz, r, ex, ey, ez, rot)
            px, py, pz = bx + f * dx, by + f * dy, bz + f * dz
            if it == RESTORE_ITERATIONS:
                break
            k = _inside_shape(px, py, pz, sh)
            if k < 0:
                break
            _, px, py, pz = escape(px, py, pz, sh, RESTORE_TOLERANCE)
        cx, cy, cz = px - ox, py - oy, pz - oz
        c = math.sqrt(cx * cx + cy * cy + cz * cz)
        keep = 1.0 if cap < 0.0 or c <= cap else cap / c
        corr[s, i, 0] += keep * cx
        corr[s, i, 1] += keep * cy
        corr[s, i, 2] += keep * cz
        if keep < 1.0:
            x_old[s, i, 0] += (1.0 - keep) * cx
            x_old[s, i, 1] += (1.0 - keep) * cy
            x_old[s, i, 2] += (1.0 - keep) * cz
        x[s, i, 0] = px
        x[s, i, 1] = py
        x[s, i, 2] = pz
    return 1 if start < n else 0


def ftl_step(model, state, motion, params, corr):
    """Kernel: one FTL substep of all strands (predict, bending, FTL pass, finalize).

    ``model``, ``state``, ``motion``, ``params``: the fields of :data:`FtlModel`,
    :data:`~hair_tracking.guides.integrate.GuideState`,
    :data:`~hair_tracking.guides.integrate.StepMotion`,
    :data:`FtlParams` as plain tuples; ``corr`` (S, N, 3) receives the FTL corrections (needed by
    :func:`hair_tracking.guides.integrate.finalize` when a collider runs before finalizing).
    Returns the clamped node count (0 when not finalizing).
    """
    x, _, _ = state                                                     # GuideState
    nblk = (x.shape[0] + BLOCK - 1) // BLOCK
    clamped = 0
    for blk in prange(nblk):
        clamped += ftl_step_block(model, state, motion, params, corr, np.int64(blk))
    return clamped


ftl_step, ftl_step_serial = parallel_and_serial(ftl_step, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_step_block(model, state, motion, params, corr, blk):
    """Block ``blk`` of :func:`ftl_step`; returns its clamped node count."""
    x, v, x_old = state                                                 # GuideState
    _, inv_mass, _, _, _ = model                                        # FtlModel
    _, _, _, _, _, _, dt, _, _ = motion                                 # StepMotion
    inner_steps, bend_stiffness, s_damp, max_disp, do_finalize = params     # FtlParams
    s0 = blk * BLOCK
    s1 = min(s0 + BLOCK, x.shape[0])
    ftl_block(model, state, motion, inner_steps, bend_stiffness, s_damp, corr, s0, s1, None)
    if do_finalize:
        return finalize_block(x, v, x_old, inv_mass, corr, s0, s1, dt, max_disp, s_damp)
    return 0


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_block(model, state, motion, inner_steps, bend_stiffness, s_damp, corr, s0, s1,
              collide):
    """Predict, the bending sweep and the FTL pass of the strands ``s0 <= s < s1`` in
    ``inner_steps`` inner steps: a substep up to the collision and finalize (:func:`ftl_step`,
    :func:`ftl_collide_step`).

    With more than one, the substep ``dt`` runs as that many steps ``h = dt / inner_steps`` of
    gravity and the free nodes' own motion (:func:`inner_predict_block`), each followed by the
    sweep and the pass; the roots move a share of the head's motion in each
    (:func:`place_roots_block`, along the straight line: exact where the substep ends).  The
    corrections of the passes are summed into ``corr``; ``collide`` (``None`` or
    :func:`ftl_pass_block`'s) acts in the last inner step's pass, and finalize once on the
    whole substep (finalize's velocity is the mean of the inner steps').  At rest the hair so
    settles where substeps of ``h`` leave it.  Returns the nodes the collider moved."""
    x, v, x_old = state
    rest, inv_mass, rest_length, bend_rest, bend_w = model              # FtlModel
    rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock, shape = motion   # StepMotion
    h = dt / inner_steps
    damp_h = damp ** (1.0 / inner_steps) if inner_steps > 1 else damp
    predict_block(state, rest, inv_mass,
                  (rot, pos, rot_rel, pos_prev, gravity, damp_h, h, shock, shape), s0, s1)
    pushed = 0
    for r in range(inner_steps):
        if inner_steps > 1:
            place_roots_block(x, x_old, rest, rot, pos, (r + 1) / inner_steps, s0, s1)
        if r > 0:
            inner_predict_block(state, inv_mass, corr, gravity, (damp_h, h, s_damp), r == 1,
                                s0, s1, (shape, rest, rot, pos))
        if bend_stiffness > 0.0:
            jacobi_bend_block(x, bend_rest, bend_w, bend_stiffness, s0, s1)
        if collide is not None:
            if r == inner_steps - 1:
                pushed = ftl_pass_block(x, rest, rest_length, rot, corr, s0, s1, r > 0,
                                        collide)
                continue
        ftl_pass_block(x, rest, rest_length, rot, corr, s0, s1, r > 0, None)
    return pushed


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def place_roots_block(x, x_old, rest, rot, pos, t, s0, s1):
    """The roots (nodes 0 and 1) of strands ``s0 <= s < s1`` at the fraction ``t`` of the way
    from their start ``x_old`` to where the head pose ``rot``, ``pos`` puts them (``t`` 1: there
    exactly): the head's motion spread over the inner steps of :func:`ftl_block`, so the
    velocity of an inner step holds its share of it."""
    for s in range(s0, s1):
        for i in range(2):
            for d in range(3):
                end = rot[d, 0] * rest[s, i, 0] + rot[d, 1] * rest[s, i, 1] + \
                    rot[d, 2] * rest[s, i, 2] + pos[d]
                x[s, i, d] = end if t >= 1.0 else x_old[s, i, d] + t * (end - x_old[s, i, d])


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def inner_predict_block(state, inv_mass, corr, gravity, step, first, s0, s1, pull):
    """The prediction of an inner step ``h`` [s] after the first (see :func:`ftl_block`) of the
    free nodes of strands ``s0 <= s < s1``: each node's velocity over the inner step before,
    ``(x - x_start) / h - s_damp corr_{i+1} / h`` with that step's FTL correction (as
    :func:`~hair_tracking.guides.integrate.finalize_block` sets it), damped (``damp`` the
    factor of ``h``) and accelerated by ``gravity``, then moved on by it.

    ``v`` holds, between inner steps, ``-x_start / h + s_damp corr_{i+1} / h`` of the step to
    come (``corr`` the sum of the passes so far), so that no start positions are stored;
    ``first``: the step before was the first, whose start is ``x_old`` and whose correction is
    all of ``corr``.  Finalize overwrites ``v``.  ``state``: the fields of
    :data:`~hair_tracking.guides.integrate.GuideState`; ``step``: ``(damp, h, s_damp)``;
    ``pull``: ``(shape, rest, rot, pos)``, the spring toward the rest shape carried by the head
    pose at the end of the substep (as :func:`~hair_tracking.guides.integrate.predict_block`'s,
    ``shape`` 0: none)."""
    x, v, x_old = state
    damp, h, s_damp = step
    shape, rest, rot, pos = pull
    spring = shape_spring(shape, h)
    n = x.shape[1]
    inv_h = 1.0 / h
    gx, gy, gz = gravity[0] * h, gravity[1] * h, gravity[2] * h
    for s in range(s0, s1):
        for i in range(2, n):
            if inv_mass[s, i] <= 0.0:
                continue
            cx, cy, cz = 0.0, 0.0, 0.0
            if i + 1 < n:
                cx = s_damp * corr[s, i + 1, 0] * inv_h
                cy = s_damp * corr[s, i + 1, 1] * inv_h
                cz = s_damp * corr[s, i + 1, 2] * inv_h
            px, py, pz = x[s, i, 0], x[s, i, 1], x[s, i, 2]
            if first:
                vx = (px - x_old[s, i, 0]) * inv_h - cx
                vy = (py - x_old[s, i, 1]) * inv_h - cy
                vz = (pz - x_old[s, i, 2]) * inv_h - cz
            else:
                vx = px * inv_h + v[s, i, 0] - cx
                vy = py * inv_h + v[s, i, 1] - cy
                vz = pz * inv_h + v[s, i, 2] - cz
            v[s, i, 0] = cx - px * inv_h
            v[s, i, 1] = cy - py * inv_h
            v[s, i, 2] = cz - pz * inv_h
            vx = vx * damp + gx
            vy = vy * damp + gy
            vz = vz * damp + gz
            if shape > 0.0:
                vx, vy, vz = shape_pulled(vx, vy, vz, px, py, pz, rest[s, i], rot, pos,
                                          spring)
            x[s, i, 0] = px + vx * h
            x[s, i, 1] = py + vy * h
            x[s, i, 2] = pz + vz * h


def ftl_collide_step(model, state, motion, params, work, collider):
    """Kernel: one FTL substep of all strands with the head collider, block by block (the
    block's strands stay in cache): :func:`ftl_step`'s predict and bending, then the FTL pass
    aware of the collider (:func:`ftl_pass_block` with ``collide``: node by node from the root,
    each node placed at its rest distance and, when inside, pushed out with friction and placed
    again, :func:`contact_node`; in the last inner step of a long substep), then finalize.

    The ghosts' contact (:mod:`hair_tracking.ghosts.contacts`) follows the same rule.  A node
    so never ends inside through a later node's push (as after a projection of single nodes,
    which stretches their segments and needs a second pass), and only the nodes in contact
    cost more than the plain pass.

    ``work``: ``(corr, x_ref)``, the first two fields of :data:`FtlWork`; ``collider``: the
    fields of :data:`~hair_tracking.colliders.head.ColliderModel`.  Without ``params``'
    ``do_finalize`` the substep stops before finalize (a body's contact comes next; the
    clamped count is then 0).  Returns ``(clamped, contacts)``.
    """
    rot, pos, _, _, _, _, _, _, _ = motion                              # StepMotion
    x, _, _ = state                                                     # GuideState
    cx, cy, cz, ax, ay, az, fr, refine = placed_shape(collider, rot, pos)
    n = x.shape[0]
    nblk = (n + BLOCK - 1) // BLOCK
    clamped = 0
    contacts = 0
    for blk in prange(nblk):
        s0 = np.int64(blk) * BLOCK
        contact = (rotation_entries(rot), cx, cy, cz, ax, ay, az, fr, refine)
        c, p = ftl_collide_block(model, state, motion, params, work, contact, s0,
                                 min(s0 + BLOCK, n))
        clamped += c
        contacts += p
    return clamped, contacts


ftl_collide_step, ftl_collide_step_serial = parallel_and_serial(
    ftl_collide_step, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_collide_block(model, state, motion, params, work, contact, s0, s1):
    """One FTL substep with the head collider of the strands ``s0 <= s < s1``
    (:func:`ftl_collide_step`'s loop body; ``contact`` the collider placed by the substep's
    head pose, :data:`~hair_tracking.colliders.head.Contact`); returns ``(clamped,
    contacts)``."""
    x, v, x_old = state                                                 # GuideState
    rest, inv_mass, rest_length, bend_rest, bend_w = model              # FtlModel
    rot, pos, rot_rel, pos_prev, gravity, damp, dt, shock, _ = motion   # StepMotion
    inner_steps, bend_stiffness, s_damp, max_disp, do_finalize = params     # FtlParams
    corr, x_ref = work                                                  # FtlWork[:2]
    _, _, _, _, _, _, _, friction, _ = contact                          # Contact
    ref = x_ref if friction > 0.0 else x_old
    if friction > 0.0:
        carry_rigid_block(x, rot_rel, pos_prev, pos, x_ref, s0, s1)
    pushed = ftl_block(model, state, motion, inner_steps, bend_stiffness, s_damp, corr, s0, s1,
                       (ref, inv_mass, contact))
    if not do_finalize:
        return 0, pushed
    return finalize_block(x, v, x_old, inv_mass, corr, s0, s1, dt, max_disp, s_damp), pushed


def ftl_advance(model, state, drive, params, collide, collider, work, stop, slots):
    """Kernel: ``K`` FTL substeps of the guides of every head ``h`` of a run, one groom worn on
    several heads (one head: a run of a single person's guides).  Head ``h``'s guides are
    ``x[slots[h]]`` of the state's arrays shaped ``(C, G, N, 3)`` (``C`` places), and each
    head has its own poses, so its own roots and its own collider placement.  Strands do not
    interact, so this is exactly ``K`` calls of :func:`ftl_collide_step` (with a collider) or
    of :func:`ftl_step` finalizing (without) for each head, one after another.  The work items
    of the one parallel region are (head, run of blocks) pairs: without a stop rule every block
    of :data:`~hair_tracking.core.kernels.BLOCK` strands runs all ``K`` substeps before the
    next (its strands stay in cache); with one, all blocks of all heads take a substep before
    the next, and the run stops before the first substep whose split estimate (``stop``)
    exceeds the limit for any head.

    ``model``: :data:`FtlModel` (the groom, shared); ``state``: ``(x, v, x_old)`` each
    ``(C, G, N, 3)``; ``drive``: the fields of :data:`RunDrive` with a head axis on ``rots``
    (H, K + 1, 3, 3), ``poss`` (H, K + 1, 3) and ``rels`` (H, K, 3, 3): the head poses at the
    start and at the end of every substep, ``rels[h, k] = rots[h, k + 1] rots[h, k]^T``, and
    :data:`~hair_tracking.guides.integrate.StepMotion`'s constant fields; ``params``:
    :data:`FtlParams` (``do_finalize`` true: every substep finalizes); ``collide``: whether the
    head collider ``collider`` (:data:`~hair_tracking.colliders.head.ColliderModel`) acts;
    ``work``: the fields of :data:`FtlWork`, ``corr``, ``x_ref`` and ``before`` shaped like
    ``x``, ``counts`` (H, B, K, 2) and ``steps`` (H, B, K) or (H, B, 0): on return
    ``counts[h, b, k]`` holds the clamped and the collider-moved node counts of block ``b`` in
    substep ``k`` and ``steps[h, 0]`` head ``h``'s largest squared node displacement of every
    substep [m^2] (NaN when one is NaN; not measured, and ``before`` not touched, when
    ``steps`` is (H, B, 0)).  ``stop``: ``(rigid (H, K), limit, gdt2)``, active when
    ``limit > 0`` and the displacements are measured: substep ``k + 1`` is not taken when
    ``max(rigid[h, k + 1], speed dt) + gdt2 > limit`` for a head ``h`` with ``speed`` the
    largest displacement of its substep ``k`` over ``dt`` (the split rule,
    :func:`~hair_tracking.guides.split.split_due`).  Returns the substeps taken.
    """
    heads, n_sub, nblk, chunks, limited = _run_plan(state, drive, work, stop, slots)
    done = n_sub
    if limited:
        for k in range(n_sub):
            for j in prange(heads * chunks):
                _head_run(model, state, drive, params, collide, collider, work, slots,
                          (np.int64(j), chunks, nblk, k, k + 1))
            if _any_split(drive, work, stop, k, nblk, heads):
                done = k + 1
                break
    else:
        for j in prange(heads * chunks):
            _head_run(model, state, drive, params, collide, collider, work, slots,
                      (np.int64(j), chunks, nblk, np.int64(0), n_sub))
        for h in range(heads):
            _measured(_work_of(work, h, 0), n_sub, nblk)
    return done


ftl_advance, ftl_advance_serial = parallel_and_serial(
    ftl_advance, fastmath=FASTMATH, error_model='numpy')


@njit(cache=True, inline='always')
def _run_plan(state, drive, work, stop, slots):
    """``(heads, substeps, blocks a head, chunks a head, limited)`` of a run of
    :func:`ftl_advance`: ``limited`` when the stop rule applies (the displacements measured and
    a limit given)."""
    x, _, _ = state                                                     # GuideState
    _, _, rels, _, _, _, _, _ = drive                                   # RunDrive
    _, _, _, steps, _ = work                                            # FtlWork
    _, limit, _ = stop
    n_sub = rels.shape[1]
    nblk = (x.shape[1] + BLOCK - 1) // BLOCK
    measure = steps.shape[2] == n_sub
    return slots.shape[0], n_sub, nblk, min(nblk, CHUNKS), measure and limit > 0.0


@njit(cache=True, inline='always')
def _head_run(model, state, drive, params, collide, collider, work, slots, item):
    """Work item ``item = (j, chunks, blocks, k0, k1)``: chunk ``j % chunks`` of head
    ``j // chunks``'s ``blocks`` blocks through the substeps ``k0 <= k < k1``."""
    j, chunks, nblk, k0, k1 = item
    h = j // chunks
    c = j - h * chunks
    s = slots[h]
    x, v, x_old = state                                                 # GuideState
    ftl_advance_blocks(model, (x[s], v[s], x_old[s]), _drive_of(drive, h),
                       params, collide, collider, _work_of(work, h, s),
                       (c * nblk // chunks, (c + 1) * nblk // chunks), (k0, k1))


@njit(cache=True, inline='always')
def _drive_of(drive, h):
    """Head ``h``'s :data:`RunDrive` (its poses without the head axis)."""
    rots, poss, rels, gravity, damp, dt, shock, shape = drive
    return (rots[h], poss[h], rels[h], gravity, damp, dt, shock, shape)


@njit(cache=True, inline='always')
def _work_of(work, h, s):
    """Head ``h``'s :data:`FtlWork` (its place ``s``), without the head axis."""
    corr, x_ref, counts, steps, before = work
    return (corr[s], x_ref[s], counts[h], steps[h], before[s])


@njit(cache=True)
def _any_split(drive, work, stop, k, nblk, heads):
    """Whether any head's stop rule ends the run after substep ``k`` (every head's largest
    displacement of the substep gathered first)."""
    rigid, limit, gdt2 = stop
    split = False
    for h in range(heads):
        if _split_after(_drive_of(drive, h), _work_of(work, h, 0), (rigid[h], limit, gdt2),
                        k, nblk):
            split = True
    return split


@njit(cache=True)
def _split_after(drive, work, stop, k, nblk):
    """Whether one head's run stops after substep ``k`` (:func:`ftl_advance`'s stop rule),
    with the substep's largest displacement gathered into ``steps[0, k]`` first (``drive``,
    ``work``, ``stop``: that head's)."""
    _, _, rels, _, _, dt, _, _ = drive                                  # RunDrive
    _, _, _, steps, _ = work                                            # FtlWork
    far = _column_max(steps, k, nblk)
    rigid, limit, gdt2 = stop
    return k + 1 < rels.shape[0] and split_due(far, dt, rigid[k + 1], gdt2, limit)


@njit(cache=True)
def _measured(work, n_sub, nblk):
    """Every substep's largest displacement into ``steps[0]`` (when measured; one head's
    ``work``)."""
    _, _, _, steps, _ = work                                            # FtlWork
    if steps.shape[1] == n_sub:
        for k in range(n_sub):
            _column_max(steps, k, nblk)


@njit(cache=True)
def run_counts(counts, done):
    """One head's clamped and collider-moved node counts of a run of :func:`ftl_advance`
    (``counts`` (B, K, 2), ``done`` substeps taken): ``(clamped, clamped_total, contacts,
    contacts_total)`` of the last substep and of all."""
    last = np.zeros(2, dtype=np.int64)
    total = np.zeros(2, dtype=np.int64)
    for blk in range(counts.shape[0]):
        for k in range(done):
            for j in range(2):
                total[j] += counts[blk, k, j]
        for j in range(2):
            last[j] += counts[blk, done - 1, j]
    return last[0], total[0], last[1], total[1]


@njit(cache=True)
def _column_max(steps, k, nblk):
    """``steps[0, k]`` = the largest of ``steps[:nblk, k]`` (NaN when one is); returned."""
    far = steps[0, k]
    for blk in range(1, nblk):
        if not steps[blk, k] <= far:
            far = steps[blk, k]
    steps[0, k] = far
    return far


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def ftl_advance_blocks(model, state, drive, params, collide, collider, work, blocks, substeps):
    """:func:`ftl_advance` for the blocks ``blocks = (b0, b1)``, each through the substeps
    ``substeps = (k0, k1)``."""
    b0, b1 = blocks
    for blk in range(b0, b1):
        ftl_advance_block(model, state, drive, params, collide, collider, work, blk, substeps)


@njit(cache=True, inline='always')
def ftl_advance_block(model, state, drive, params, collide, collider, work, blk, substeps):
    """:func:`ftl_advance_blocks` for block ``blk``."""
    x, v, x_old = state                                                 # GuideState
    _, inv_mass, _, _, _ = model                                        # FtlModel
    rots, poss, rels, gravity, damp, dt, shock, shape = drive           # RunDrive
    inner_steps, bend_stiffness, s_damp, max_disp, _ = params           # FtlParams
    corr, x_ref, counts, steps, before = work                           # FtlWork
    measure = steps.shape[1] > 0
    s0 = blk * BLOCK
    s1 = min(s0 + BLOCK, x.shape[0])
    k0, k1 = substeps
    for k in range(k0, k1):
        rot, pos = rots[k + 1], poss[k + 1]
        motion = (rot, pos, rels[k], poss[k], gravity, damp, dt, shock, shape)
        if measure:
            for s in range(s0, s1):
                for i in range(x.shape[1]):
                    for d in range(3):
                        before[s, i, d] = x[s, i, d]
        if collide:
            c, p = ftl_collide_block(model, state, motion, params, (corr, x_ref),
                                     placed(collider, rot, pos), s0, s1)
        else:
            ftl_block(model, state, motion, inner_steps, bend_stiffness, s_damp, corr, s0,
                      s1, None)
            c = finalize_block(x, v, x_old, inv_mass, corr, s0, s1, dt, max_disp, s_damp)
            p = 0
        counts[blk, k, 0] = c
        counts[blk, k, 1] = p
        if measure:
            steps[blk, k] = max_step_sq_block(x, before, s0, s1)
