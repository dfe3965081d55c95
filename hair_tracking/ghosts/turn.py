"""The turn tracker: every ghost strand follows one guide, each of its segments turned as the
guide's segment at the same arc-length fraction turned since rest, so its lengths are exact by
construction and no length pass is needed.

Guides are some of the strands themselves (as for the blend tracker,
:func:`~hair_tracking.ghosts.stateless.choose_guides`), each ghost follows the guide with the
nearest root.  Per output frame, with ``R``, ``p`` the head pose, for ghost strand ``s`` (rest
nodes ``r_j``, head frame) and its guide read at the ghost's node fractions (``g_j`` now,
world; ``g0_j`` at rest, head frame; :func:`~hair_tracking.ghosts.stateless.guide_columns`):

1. every guide segment's turn ``M_j = T(R a_j -> b_j) R``, with ``a_j`` and ``b_j`` the unit
   directions of ``g0_j+1 - g0_j`` and ``g_j+1 - g_j`` and ``T(a -> b)`` the shortest rotation
   taking ``a`` to ``b`` (:func:`turn_matrix`);
2. roots (nodes 0 and 1) pinned at ``R r + p``; every further node
   ``x_j+1 = x_j + M_j (r_j+1 - r_j)``: the ghost's rest segment turned as its guide's;
3. a node that ends inside the head collider (radii + margin) is placed at its rest distance
   from its predecessor along its step with the inward part (along the collider's normal at the
   predecessor) removed, so it slides along the head, and moved radially onto the surface if the
   curvature still leaves it inside; the nodes after it follow from there.

A strand rigidly carried by the head stays exactly rigid (every ``M_j = R``); a strand that is
a guide reproduces the guide (its own segment directions at its rest lengths, exactly the guide
for FTL guides), its nodes left where the guide solver put them (no step 3).

Sources: transferring the rotation of guide segments instead of their positions, so that
interpolated strands keep their lengths, is the idea behind the rotation-based interpolation of
Hsu et al., "Real-time Physically Guided Hair Interpolation" (ACM TOG 43(4), 2024); the
one-guide case corresponds to AMD TressFX's follow hairs.  The shortest-arc rotation is the
standard ``T = c I + [v]x + v v^T / (1 + c)`` with ``v = a x b``, ``c = a . b``.

Layout: the ghosts are grouped by guide into blocks of :data:`LANES` strands (the last block of
a guide padded with idle lanes), so a block's nine turn entries at a node are shared by all its
lanes; a block is held node-major in a scratch array, every node one vector step for the whole
block, and the inside test a vector reduction; a block with a node inside the head fixes all its
lanes at that node in one branch-free vector pass.

:func:`reference_turn` is the plain-numpy statement of steps 1-3; the tests hold the compiled
kernel (:func:`turn_strands`) to it.
"""
from collections import namedtuple
import math
from typing import Tuple

import numpy as np
from numba import njit, prange

from hair_tracking.colliders.slide import quadric, slide_push_lane
from hair_tracking.core.model import HeadPose, StrandSet, part_rows
from hair_tracking.core.point_records import put_record
from hair_tracking.ghosts.blend import blend_weights
from hair_tracking.ghosts.stateless import (StatelessTracker, at_fractions, node_map,
                                            reference_contact, world_collider)
from hair_tracking.core.kernels import FASTMATH

#: Strands of one guide advanced together (one block): two AVX2 or one AVX-512 register of
#: float64 lanes.
LANES = 8
#: Work items of the kernel's parallel loop (each a run of blocks with its own scratch).
CHUNKS = 64
#: ``1 + a . b`` below which a turn is taken as a half turn (``a`` and ``b`` opposite).
HALF_TURN = 1e-9
#: Where an idle lane of a block sits (head frame, metres): far outside any collider.
IDLE_AT = 1e3
#: What a lane of a block holds: nothing, a ghost strand, or a strand that is a guide (the
#: collider acts on a guide's node only where step 2 moved it off the guide solver's node by
#: more than :data:`GUIDE_TOLERANCE`: a PBD or XPBD guide's stretched segment).
IDLE, GHOST, GUIDE = 0, 1, 2
#: [m], see :data:`GUIDE`.
GUIDE_TOLERANCE = 1e-6

#: The turn kernel's static data (:attr:`TurnTracker.model`), a plain tuple in these fields'
#: order (numba types a named tuple by encoding its class and field names on every call):
#: ``seg`` (B, N * 3 * lanes) float32 and ``roots`` (B, 2, 3, lanes) the blocks' rest shape
#: (:func:`block_rest`); ``kind`` (B, lanes) int8 what each lane holds (:data:`GUIDE`);
#: ``block_guide`` (B,) and ``block_strand`` (B, lanes) the blocks (:func:`group_blocks`);
#: ``u0`` (G, 3, N - 1) the guides' unit rest directions (:func:`rest_directions`).
TurnModel = namedtuple('TurnModel', ['seg', 'roots', 'kind', 'block_guide', 'block_strand',
                                     'u0'])
#: The turn's parameters (:attr:`TurnTracker.params`, a plain tuple): ``collide``: keep nodes
#: out of the ellipsoid ``axes`` (radii + margin) around ``center`` (head frame).
TurnParams = namedtuple('TurnParams', ['collide', 'center', 'axes'])


# ----------------------------------------------------------------------------- set-up
def group_blocks(guide_of: np.ndarray, guides: int,
                 lanes: int = LANES) -> Tuple[np.ndarray, np.ndarray]:
    """The ghosts grouped by guide into blocks of ``lanes``: ``(guide (B,) int64, strand (B,
    lanes) int64)``, strands in ascending order within a guide, -1 for an idle lane."""
    guide_of = np.asarray(guide_of, dtype=np.int64)
    order = np.argsort(guide_of, kind='stable')
    counts = np.bincount(guide_of, minlength=guides)
    per_guide = (counts + lanes - 1) // lanes
    block_guide = np.repeat(np.arange(guides), per_guide)
    strand = np.full((block_guide.shape[0], lanes), -1, dtype=np.int64)
    first_block = np.concatenate([[0], np.cumsum(per_guide)[:-1]])
    first_member = np.concatenate([[0], np.cumsum(counts)[:-1]])
    rank = np.arange(order.shape[0]) - first_member[guide_of[order]]
    strand[first_block[guide_of[order]] + rank // lanes, rank % lanes] = order
    return block_guide, strand


def block_rest(rest: np.ndarray, strand: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The blocks' rest shape in the kernel's layout: ``(segments (B, N * 3 * lanes) float32,
    roots (B, 2, 3, lanes) float64)``; segment ``j`` (``r_j+1 - r_j``, head frame) at row ``j``
    of each block's (N, 3, lanes) slab (row N - 1 unused), the first two rest nodes exact.  An
    idle lane has zero segments and its roots at :data:`IDLE_AT`."""
    rest = np.asarray(rest, dtype=np.float64)
    n_nodes = rest.shape[1]
    blocks, lanes = strand.shape
    seg = np.zeros((blocks, n_nodes, 3, lanes), dtype=np.float32)
    roots = np.zeros((blocks, 2, 3, lanes))
    roots[:, :, 2, :] = IDLE_AT
    used = strand >= 0
    b, lane = np.nonzero(used)
    s = strand[used]
    seg[b, :n_nodes - 1, :, lane] = np.diff(rest, axis=1)[s]
    roots[b, :, :, lane] = rest[s, :2]
    return np.ascontiguousarray(seg.reshape(blocks, -1)), roots


def rest_directions(guide_rest: np.ndarray) -> np.ndarray:
    """Unit directions (G, 3, N - 1) of the guides' rest segments, component-major (from the
    guides read at the ghosts' node fractions, (G, N, 3), head frame)."""
    d = np.diff(np.asarray(guide_rest, dtype=np.float64), axis=1)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    return np.ascontiguousarray(d.transpose(0, 2, 1))


def turn_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest rotation (3, 3) taking unit vector ``a`` to unit vector ``b``; opposite
    vectors give a half turn about an axis normal to ``a``."""
    c = float(a @ b)
    if 1.0 + c <= HALF_TURN:
        n = _normal_to(a)
        return 2.0 * np.outer(n, n) - np.eye(3)
    v = np.cross(a, b)
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return c * np.eye(3) + k + np.outer(v, v) / (1.0 + c)


def _normal_to(a):
    n = np.array([0.0, -a[2], a[1]]) if abs(a[0]) < 0.9 else np.array([-a[1], a[0], 0.0])
    return n / np.linalg.norm(n)


# ----------------------------------------------------------------------------- kernels
@njit(cache=True, inline='always', fastmath=FASTMATH, error_model='numpy')
def guide_turns(gcol, u0, rot, out, g):
    """Step 1 for guide ``g``: ``out[g]`` (9, N - 1) the turn ``M_j`` of each of its segments,
    row-major entries first, from ``gcol`` (G, 3, N) the guides at the ghosts' node fractions
    (world, :func:`~hair_tracking.ghosts.stateless.guide_columns`) and ``u0`` (G, 3, N - 1) their
    unit rest directions (head frame, :func:`rest_directions`)."""
    n_seg = u0.shape[2]
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    half = 0
    for j in range(n_seg):                   # vectorised along the guide
        bx = gcol[g, 0, j + 1] - gcol[g, 0, j]
        by = gcol[g, 1, j + 1] - gcol[g, 1, j]
        bz = gcol[g, 2, j + 1] - gcol[g, 2, j]
        inv = 1.0 / math.sqrt(bx * bx + by * by + bz * bz)
        bx, by, bz = bx * inv, by * inv, bz * inv
        a0, a1, a2 = u0[g, 0, j], u0[g, 1, j], u0[g, 2, j]
        ax = r00 * a0 + r01 * a1 + r02 * a2
        ay = r10 * a0 + r11 * a1 + r12 * a2
        az = r20 * a0 + r21 * a1 + r22 * a2
        c = ax * bx + ay * by + az * bz
        half += 1 if 1.0 + c <= HALF_TURN else 0
        vx, vy, vz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        h = 1.0 / max(1.0 + c, HALF_TURN)
        _store_turn(out, g, j, rot, (c + h * vx * vx, h * vx * vy - vz, h * vx * vz + vy,
                                     h * vx * vy + vz, c + h * vy * vy, h * vy * vz - vx,
                                     h * vx * vz - vy, h * vy * vz + vx, c + h * vz * vz))
    if half == 0:
        return
    for j in range(n_seg):                   # the rare half turns, again one by one
        bx = gcol[g, 0, j + 1] - gcol[g, 0, j]
        by = gcol[g, 1, j + 1] - gcol[g, 1, j]
        bz = gcol[g, 2, j + 1] - gcol[g, 2, j]
        a0, a1, a2 = u0[g, 0, j], u0[g, 1, j], u0[g, 2, j]
        ax = r00 * a0 + r01 * a1 + r02 * a2
        ay = r10 * a0 + r11 * a1 + r12 * a2
        az = r20 * a0 + r21 * a1 + r22 * a2
        c = (ax * bx + ay * by + az * bz) / math.sqrt(bx * bx + by * by + bz * bz)
        if 1.0 + c > HALF_TURN:
            continue
        if abs(ax) < 0.9:
            nx, ny, nz = 0.0, -az, ay
        else:
            nx, ny, nz = -ay, ax, 0.0
        f = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = nx * f, ny * f, nz * f
        _store_turn(out, g, j, rot, (2.0 * nx * nx - 1.0, 2.0 * nx * ny, 2.0 * nx * nz,
                                     2.0 * nx * ny, 2.0 * ny * ny - 1.0, 2.0 * ny * nz,
                                     2.0 * nx * nz, 2.0 * ny * nz, 2.0 * nz * nz - 1.0))


@njit(cache=True, inline='always')
def _store_turn(out, g, j, rot, t):
    """``out[g, :, j]`` = the entries of ``T R`` (``T`` given by its nine entries, row by
    row)."""
    t00, t01, t02, t10, t11, t12, t20, t21, t22 = t
    for k in range(3):
        c0, c1, c2 = rot[0, k], rot[1, k], rot[2, k]
        out[g, k, j] = t00 * c0 + t01 * c1 + t02 * c2
        out[g, 3 + k, j] = t10 * c0 + t11 * c1 + t12 * c2
        out[g, 6 + k, j] = t20 * c0 + t21 * c1 + t22 * c2


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _turn_blocks(target, model, pose, turns, collide, work, blocks):
    """Steps 2-3 for the blocks ``blocks = (b0, b1)``, ``b0 .. b1 - 1`` (``target``,
    ``model``, ``pose``, ``turns`` as :func:`turn_strands` takes them), ``work`` = ``(flat,
    geo)``: ``flat`` (2 * N * 3 * lanes) the scratch and ``geo`` the collider's constants
    (:func:`_contact_pass`; the guide's node is written here); returns the number of nodes moved
    by the collider and the number of points written that are not finite (counted with
    ``check`` only)."""
    out, out_rot, out_origin, moved, check = target                     # Placement
    seg, roots, kind, block_guide, block_strand, _ = model              # TurnModel
    gcol, rot, pos = pose                                               # GuidePose
    flat, geo = work
    b0, b1 = blocks
    n_nodes = out.shape[1]
    lanes = block_strand.shape[1]           # not a compile-time constant: LLVM vectorises
    slab = n_nodes * 3 * lanes
    # one scratch array for positions and segments, so the node loop reads and writes one
    # array (LLVM's overlap checks before the vector loop stay few)
    w = flat.reshape((2, n_nodes, 3, lanes))
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    c0, c1, c2 = geo[0], geo[1], geo[2]
    q0, q1, q2, q3, q4, q5 = geo[3], geo[4], geo[5], geo[6], geo[7], geo[8]
    contacts = 0
    bad = 0
    for b in range(b0, b1):
        g = block_guide[b]
        for i in range(slab):
            flat[slab + i] = seg[b, i]
        for j in range(2):                                   # roots ride with the head
            for lane in range(lanes):
                u0, u1, u2 = roots[b, j, 0, lane], roots[b, j, 1, lane], roots[b, j, 2, lane]
                w[0, j, 0, lane] = r00 * u0 + r01 * u1 + r02 * u2 + pos[0]
                w[0, j, 1, lane] = r10 * u0 + r11 * u1 + r12 * u2 + pos[1]
                w[0, j, 2, lane] = r20 * u0 + r21 * u1 + r22 * u2 + pos[2]
        for j in range(1, n_nodes - 1):
            m0, m1, m2 = turns[g, 0, j], turns[g, 1, j], turns[g, 2, j]
            m3, m4, m5 = turns[g, 3, j], turns[g, 4, j], turns[g, 5, j]
            m6, m7, m8 = turns[g, 6, j], turns[g, 7, j], turns[g, 8, j]
            for lane in range(lanes):                        # step 2, all lanes at once
                s0, s1, s2 = w[1, j, 0, lane], w[1, j, 1, lane], w[1, j, 2, lane]
                w[0, j + 1, 0, lane] = w[0, j, 0, lane] + m0 * s0 + m1 * s1 + m2 * s2
                w[0, j + 1, 1, lane] = w[0, j, 1, lane] + m3 * s0 + m4 * s1 + m5 * s2
                w[0, j + 1, 2, lane] = w[0, j, 2, lane] + m6 * s0 + m7 * s1 + m8 * s2
            inside = 0
            if collide:
                for lane in range(lanes):
                    e = quadric(w[0, j + 1, 0, lane] - c0, w[0, j + 1, 1, lane] - c1,
                                w[0, j + 1, 2, lane] - c2, q0, q1, q2, q3, q4, q5)
                    inside += 1 if e < 1.0 else 0
            if collide and inside > 0:                       # step 3
                geo[9] = gcol[g, 0, j + 1]
                geo[10] = gcol[g, 1, j + 1]
                geo[11] = gcol[g, 2, j + 1]
                contacts += _contact_pass(w, kind, b, j, geo)
        for lane in range(lanes):
            s = block_strand[b, lane]
            if s < 0:
                continue
            if check:
                for j in range(n_nodes):
                    bad += put_record(out, s, j, w[0, j, 0, lane], w[0, j, 1, lane],
                                      w[0, j, 2, lane], out_rot, out_origin, moved)
            else:
                for j in range(n_nodes):
                    out[s, j, 0] = w[0, j, 0, lane]
                    out[s, j, 1] = w[0, j, 1, lane]
                    out[s, j, 2] = w[0, j, 2, lane]
    return contacts, bad


@njit(cache=True, inline='always')
def _acts(kind, dx, dy, dz):
    """Whether the collider acts on a node of a lane of ``kind`` that lies ``d`` from its
    guide's node (see :data:`GUIDE`)."""
    moved = dx * dx + dy * dy + dz * dz > GUIDE_TOLERANCE * GUIDE_TOLERANCE
    return (kind == GHOST) | ((kind == GUIDE) & moved)         # no branches: vectorises


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _contact_pass(w, kind, b, j, geo):
    """Step 3 for node ``j + 1`` of every lane of the scratch ``w`` (block ``b``), one vector
    pass (selects, no branches; a function of its own, so LLVM vectorises its loop on its own
    terms): the contact model's slide and push of an ellipsoid for lanes side by side
    (:func:`~hair_tracking.colliders.slide.slide_push_lane`) on every node the collider acts on
    (:func:`_acts`).  ``geo``:
    ``c`` (3), Q's entries Q00 Q11 Q22 Q01 Q02 Q12, the guide's node ``j + 1`` (3).  Returns
    the number of nodes moved."""
    c = (geo[0], geo[1], geo[2])
    q = (geo[3], geo[4], geo[5], geo[6], geo[7], geo[8])
    g0, g1, g2 = geo[9], geo[10], geo[11]
    moved = 0
    for lane in range(w.shape[3]):
        nx, ny, nz = w[0, j + 1, 0, lane], w[0, j + 1, 1, lane], w[0, j + 1, 2, lane]
        acts = _acts(kind[b, lane], nx - g0, ny - g1, nz - g2)
        inside, x0, x1, x2 = slide_push_lane(
            (nx, ny, nz), (w[0, j, 0, lane], w[0, j, 1, lane], w[0, j, 2, lane]), c, q, acts)
        w[0, j + 1, 0, lane] = x0
        w[0, j + 1, 1, lane] = x1
        w[0, j + 1, 2, lane] = x2
        moved += 1 if inside else 0
    return moved


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def turn_strands(target, model, pose, params, turns):
    """Kernel, steps 1-3: every strand of a block (``block_strand``, :func:`group_blocks`)
    written into ``target`` (the fields of :data:`~hair_tracking.ghosts.stateless.Placement`:
    x y z into ``out`` (S, N, >= 3), world [m]; with ``check`` as point records,
    :func:`~hair_tracking.core.point_records.put_record`); ``model`` the fields of
    :data:`TurnModel`; ``pose`` the fields of :data:`~hair_tracking.ghosts.stateless.GuidePose`
    (the guides at the ghosts' node fractions,
    :func:`~hair_tracking.ghosts.stateless.guide_columns`, and the head pose); ``params`` the
    fields of :data:`TurnParams`; ``turns`` (G, 9, N - 1) receives the guides' turns (step 1, a
    parallel loop over the guides before the one over the blocks).  Returns the number of nodes
    the collider moved and whether every coordinate written is finite (always true without
    ``check``)."""
    gcol, rot, pos = pose
    collide, center, axes = params
    _, _, _, block_guide, block_strand, u0 = model                      # TurnModel
    out, _, _, _, _ = target                                            # Placement
    for g in prange(gcol.shape[0]):
        guide_turns(gcol, u0, rot, turns, g)
    geo = np.empty(12)       # the collider in the world (centre, Q), then the guide's node
    world_collider(rot, pos, center, axes, geo)
    n_blocks = block_guide.shape[0]
    n_chunks = min(n_blocks, CHUNKS)
    slab = 2 * out.shape[1] * 3 * block_strand.shape[1]
    contacts = 0
    bad = 0
    for c in prange(n_chunks):
        work = (np.empty(slab), geo.copy())   # the work item's scratch and constants
        moved_nodes, not_finite = _turn_blocks(
            target, model, pose, turns, collide, work,
            (c * n_blocks // n_chunks, (c + 1) * n_blocks // n_chunks))
        contacts += moved_nodes
        bad += not_finite
    return contacts, bad == 0


# ----------------------------------------------------------------------------- reference
def reference_turn(gx, grest, rest, guide_of, head: HeadPose, collider_axes=None,
                   center=(0.0, 0.0, 0.0), guide_index=()) -> np.ndarray:
    """Plain-numpy statement of one frame (steps 1-3 of the module docstring); returns the
    strands (S, N, 3), world frame.  ``gx``/``grest`` (G, M, 3) the guides now (world) and at
    rest (head frame); ``rest`` (S, N, 3) the strands at rest; ``guide_of`` (S,) each strand's
    guide; the strands ``guide_index`` are guides (step 3 only where step 2 moved a node off
    the guide's by more than :data:`GUIDE_TOLERANCE`).  Slow; for tests and for
    reading."""
    rot, pos = head.rotation, head.position
    s_count, n_nodes = rest.shape[:2]
    seg, t = node_map(n_nodes, gx.shape[1])
    g = at_fractions(gx, seg, t)
    g0 = at_fractions(grest, seg, t)
    out = np.empty((s_count, n_nodes, 3))
    guides = set(int(i) for i in guide_index)
    for s in range(s_count):
        k = int(guide_of[s])
        out[s, :2] = rest[s, :2] @ rot.T + pos
        for j in range(1, n_nodes - 1):
            a = rot @ _unit(g0[k, j + 1] - g0[k, j])                             # step 1
            b = _unit(g[k, j + 1] - g[k, j])
            step = turn_matrix(a, b) @ rot @ (rest[s, j + 1] - rest[s, j])        # step 2
            p = out[s, j] + step
            acts = s not in guides or np.linalg.norm(p - g[k, j + 1]) > GUIDE_TOLERANCE
            if collider_axes is not None and acts:                               # step 3
                p = reference_contact(p, out[s, j], np.linalg.norm(step), head, collider_axes,
                                      center)
            out[s, j + 1] = p
    return out


def _unit(v):
    return v / np.linalg.norm(v)


# ----------------------------------------------------------------------------- tracker
class TurnTracker(StatelessTracker):
    """Moves ``ghosts`` after ``guides`` when they are read (see the module docstring and
    :class:`~hair_tracking.ghosts.stateless.StatelessTracker`)."""

    def __init__(self, ghosts: StrandSet, guides: StrandSet, guide_index, scene, collider=None,
                 colliders=None):
        super().__init__(ghosts, guides, guide_index, scene, collider, colliders)
        near, _ = blend_weights(ghosts.rest[:, 0], guides.rest[:, 0], 1)
        self.guide_of = near[:, 0].astype(np.int64)
        self.guide_of[self.guide_index] = np.arange(guides.count)    # a guide follows itself
        self.block_guide, self.block_strand = group_blocks(self.guide_of, guides.count)
        seg, roots = block_rest(ghosts.rest, self.block_strand)
        kind = np.where(self.block_strand >= 0, GHOST, IDLE).astype(np.int8)
        kind[np.isin(self.block_strand, self.guide_index)] = GUIDE
        #: the kernel's static data: the fields of :data:`TurnModel` (a plain tuple)
        self.model = (seg, roots, kind, self.block_guide, self.block_strand,
                      rest_directions(at_fractions(guides.rest, self.seg, self.t)))
        #: the kernel's parameters: the fields of :data:`TurnParams` (a plain tuple)
        self.params = (self.collide, self.center, self.axes)
        self._turns = np.empty((guides.count, 9, ghosts.rest.shape[1] - 1))

    def _place(self, target) -> Tuple[int, bool]:
        """Steps 1-3 of the module docstring."""
        return turn_strands(target, self.model, self._pose, self.params, self._turns)

    def _place_part(self, part: int, parts: int) -> np.ndarray:
        """The strands of the blocks of the part (blocks hold strands of one guide, so a part
        is a set of guides' strands; :func:`~hair_tracking.core.model.part_rows` of the
        blocks)."""
        rows = part_rows(self.block_guide.shape[0], part, parts)
        m = self.model
        model = tuple(a[rows] for a in m[:5]) + (m[5],)
        turn_strands(self._x32_target, model, self._pose, self.params, self._turns)
        idx = self.block_strand[rows]
        return np.sort(idx[idx >= 0])

    def _place_rows(self, rows: slice, target) -> Tuple[int, bool]:
        """The blocks that hold a strand of ``rows`` (blocks go by guide, so a run of rows
        is part of several guides' blocks), each whole as in a whole placement; only the
        strands of ``rows`` are written, numbered from ``rows.start``."""
        bs = self.block_strand
        ours = (bs >= rows.start) & (bs < rows.stop)
        blocks = np.flatnonzero(ours.any(axis=1))
        strand = np.where(ours, bs - rows.start, -1)[blocks]
        m = self.model
        model = tuple(a[blocks] for a in m[:4]) + (strand, m[5])
        return turn_strands(target, model, self._pose, self.params, self._turns)
