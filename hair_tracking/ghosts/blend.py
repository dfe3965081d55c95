"""The blend tracker: every ghost strand is its rest shape carried by a weighted blend of the
motions of a few nearby guides, without state of its own: evaluated when the hair is read (once
per output frame), however many head poses came in between.

Guides are some of the strands themselves
(:func:`~hair_tracking.ghosts.stateless.choose_guides`), so a ratio of 1:1 is full simulation:
a strand that is a guide is its guide's points, exactly as simulated for FTL guides (exact
lengths); the length pass puts PBD and XPBD guides' stretched segments back at their rest
lengths (:data:`GUIDE_LENGTH_TOLERANCE`), so no shown strand stretches. Per frame, for ghost
strand ``s`` with guides ``k`` and weights ``w_k`` (:func:`blend_weights`) and its node ``j``
(rest position ``r_j``, head frame):

1. every guide is read at the node's arc-length fraction, ``g_k,j`` (world) and ``g0_k,j``
   (rest, head frame) -- node to node when ghosts and guides have the same node count
   (:func:`~hair_tracking.ghosts.stateless.node_map`,
   :func:`~hair_tracking.ghosts.stateless.guide_columns`);
2. the node is the blend of the guides' points plus its rest offset from that blend carried
   rigidly by the head rotation ``R``:  ``x_j = sum_k w_k g_k,j + R o_j`` with
   ``o_j = r_j - sum_k w_k g0_k,j`` fixed at start -- the same as adding the weighted guide
   *deformations* ``g_k,j - (R g0_k,j + p)`` to the rigidly carried rest node ``R r_j + p``;
3. roots (nodes 0 and 1) are pinned at ``R r + p``; one Follow-The-Leader pass (Mueller, Kim &
   Chentanez 2012) puts every further node back at its rest distance from its predecessor; a
   node that would end inside the head collider (radii + margin) is placed at its rest distance
   along the direction with the inward part (along the collider's normal at the predecessor)
   removed, so it slides along the head, and is moved radially onto the surface if the
   curvature still leaves it inside.

Sources: blending the deformation of up to three guides, weighted by the distance between roots,
with the interpolated strand otherwise rigid, is Unreal Engine's groom interpolation; AMD
TressFX's follow hairs are the one-guide case (guide point plus a root offset).  The weights are
Shepard's inverse-distance weights (D. Shepard, "A two-dimensional interpolation function for
irregularly-spaced data", ACM 1968).  Unlike the paper's tracker
(:mod:`hair_tracking.ghosts.tracker`) nothing is integrated, so nothing drifts and nothing can
gain energy: the ghost's motion is its guides' motion.

Layout: step 1 writes the guides component-major (G, 3, N) and the rest offsets are kept the
same way (S, 3, N); step 3, a chain along each strand, runs on blocks of :data:`STRAND_BLOCK`
strands held node-major in a small scratch array, so the length pass and the inside test of a
block's strands are one vector operation per node; step 2 writes each strand's nodes straight
into its lane of that array, three guides and all three components in one pass along the
strand; the rare node inside the head is then fixed on its own.

:func:`reference_blend` is the plain-numpy statement of steps 1-3; the tests hold the compiled
kernel (:func:`blend_strands`) to it.
"""
from collections import namedtuple
import math
from typing import Tuple

import numpy as np
from numba import njit, prange

from hair_tracking.colliders.slide import push_quadric, quadric, slide_quadric
from hair_tracking.core.model import HeadPose, StrandSet, part_rows
from hair_tracking.core.point_records import put_record
from hair_tracking.ghosts.stateless import (StatelessTracker, at_fractions, node_map,
                                            reference_contact, world_collider)
from hair_tracking.core.kernels import FASTMATH

#: Guides blended per ghost by default (Unreal's groom interpolation uses up to three).
DEFAULT_GUIDES_PER_GHOST = 3
#: A guide strand's segment is put back at its rest length only when it is off by more than
#: this fraction (PBD, XPBD stretch), so FTL guides are shown exactly as simulated.
GUIDE_LENGTH_TOLERANCE = 1e-9
#: Exponent of the inverse-distance weights.
WEIGHT_POWER = 2.0
#: Strand-to-guide distances :func:`blend_weights` holds at a time.
WEIGHT_CHUNK = 1 << 22
#: Strands whose length passes run together, node by node: one vector register of float64 lanes
#: on AVX-512 (two on AVX2), so each node of the chain is one vector step for the whole block.
STRAND_BLOCK = 8
#: Work items of the blend's parallel loop (each a run of blocks with its own scratch row).
CHUNKS = 64
#: Guides blended in one pass along a strand (the kernels' guide lists of two or more guides are
#: padded to a multiple of it with zero weights; one guide runs a pass of its own).
GUIDE_GROUP = 3

#: The blend kernel's static data (:attr:`BlendTracker.model`), a plain tuple in these fields'
#: order (numba types a named tuple by encoding its class and field names on every call):
#: ``offset`` (S, 3, N) float32 the rest offsets ``o`` (head frame), component-major;
#: ``roots`` (S, 2, 3) the first two rest nodes in float64 (pinned exactly); ``rest_length``
#: (S, N-1) float32; ``guide`` (S, K) int32 and ``weight`` (S, K) float32 from
#: :func:`blend_weights`, padded by :func:`pad_guides`; ``is_guide`` (S,) the guide each strand
#: is, -1 for the others; ``guide_length`` (G, N-1) float64 the guides' rest lengths.
BlendModel = namedtuple('BlendModel', ['offset', 'roots', 'rest_length', 'guide', 'weight',
                                       'is_guide', 'guide_length'])
#: The blend's parameters (:attr:`BlendTracker.params`, a plain tuple): ``restore`` the FTL
#: length pass; ``collide``: keep nodes out of the ellipsoid ``axes`` (radii + margin) around
#: ``center`` (head frame).
BlendParams = namedtuple('BlendParams', ['restore', 'collide', 'center', 'axes'])


# ----------------------------------------------------------------------------- set-up
def blend_weights(roots: np.ndarray, guide_roots: np.ndarray, k: int,
                  power: float = WEIGHT_POWER) -> Tuple[np.ndarray, np.ndarray]:
    """The ``k`` guides with the nearest roots of every strand and their Shepard weights
    ``w_i ~ 1 / d_i^power``, normalised to sum 1: ``(guide (S, k) int32, weight (S, k)
    float32)``.  A strand whose root is a guide's root has weight 1 on that guide alone."""
    roots = np.asarray(roots, dtype=np.float64)
    guide_roots = np.asarray(guide_roots, dtype=np.float64)
    k = int(min(k, guide_roots.shape[0]))
    if k < 1:
        raise ValueError('blend_weights: need at least one guide')
    near = np.empty((roots.shape[0], k), dtype=np.int64)
    dn = np.empty((roots.shape[0], k))
    rows = max(1, WEIGHT_CHUNK // guide_roots.shape[0])     # bounded memory for 100 k strands
    for a in range(0, roots.shape[0], rows):
        r = roots[a:a + rows]
        d2 = (r[:, None, 0] - guide_roots[None, :, 0]) ** 2                       # (rows, G)
        d2 += (r[:, None, 1] - guide_roots[None, :, 1]) ** 2
        d2 += (r[:, None, 2] - guide_roots[None, :, 2]) ** 2
        near[a:a + rows] = _nearest(d2, k)
        dn[a:a + rows] = np.sqrt(np.take_along_axis(d2, near[a:a + rows], axis=1))
    exact = dn[:, 0] <= 1e-12
    w = 1.0 / np.maximum(dn, 1e-12) ** power
    w[exact] = 0.0
    w[exact, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    return near.astype(np.int32), w.astype(np.float32)


def _nearest(d2: np.ndarray, k: int) -> np.ndarray:
    """Columns of the ``k`` smallest entries of each row of ``d2``, ascending, ties to the lower
    column: ``np.argsort(d2, axis=1, kind='stable')[:, :k]`` without sorting whole rows (a
    partition finds each row's k-th value; rows with a tie at it are sorted in full)."""
    if k >= d2.shape[1]:
        return np.argsort(d2, axis=1, kind='stable')[:, :k]
    kth = np.partition(d2, k - 1, axis=1)[:, k - 1:k]
    mask = d2 <= kth
    plain = mask.sum(axis=1) == k
    out = np.empty((d2.shape[0], k), dtype=np.int64)
    cols = np.nonzero(mask[plain])[1].reshape(-1, k)             # ascending column order
    vals = np.take_along_axis(d2[plain], cols, axis=1)
    out[plain] = np.take_along_axis(cols, np.argsort(vals, axis=1, kind='stable'), axis=1)
    if not plain.all():
        out[~plain] = np.argsort(d2[~plain], axis=1, kind='stable')[:, :k]
    return out


def pad_guides(guide: np.ndarray, weight: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """``guide``/``weight`` (S, K) of :func:`blend_weights` with columns added to a multiple of
    :data:`GUIDE_GROUP`, repeating the first guide with weight 0 (the kernel's form; the blend
    is unchanged, a zero-weight term adds exactly nothing).  One guide (K = 1) is left as it
    is: the kernel follows it in a pass of its own."""
    k = guide.shape[1]
    extra = -k % GUIDE_GROUP if k > 1 else 0
    guide = np.concatenate([guide, np.repeat(guide[:, :1], extra, axis=1)], axis=1)
    weight = np.concatenate([weight, np.zeros((weight.shape[0], extra), weight.dtype)], axis=1)
    return np.ascontiguousarray(guide, dtype=np.int32), np.ascontiguousarray(weight,
                                                                             dtype=np.float32)


# ----------------------------------------------------------------------------- kernels
@njit(cache=True, inline='always')
def _deform(blk, lane, offset, rot, guide, weight, gcol, s):
    """Step 2 of strand ``s`` into lane ``lane`` of the block ``blk`` (nodes 2 on):
    ``R o_j + sum_k w_k g_k,j``, the guides three at a time (``guide``/``weight`` padded with
    zero weights to a multiple of :data:`GUIDE_GROUP`), every node's three components in one
    pass of straight-line arithmetic; a single guide (weight 1) is ``R o_j + g_j``, TressFX's
    follow hair."""
    n_nodes = blk.shape[0]
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    if guide.shape[1] == 1:
        g0 = guide[s, 0]
        for j in range(2, n_nodes):
            o0, o1, o2 = offset[s, 0, j], offset[s, 1, j], offset[s, 2, j]
            blk[j, 0, lane] = r00 * o0 + r01 * o1 + r02 * o2 + gcol[g0, 0, j]
            blk[j, 1, lane] = r10 * o0 + r11 * o1 + r12 * o2 + gcol[g0, 1, j]
            blk[j, 2, lane] = r20 * o0 + r21 * o1 + r22 * o2 + gcol[g0, 2, j]
        return
    for k in range(0, guide.shape[1], GUIDE_GROUP):
        g0, g1, g2 = guide[s, k], guide[s, k + 1], guide[s, k + 2]
        w0, w1, w2 = float(weight[s, k]), float(weight[s, k + 1]), float(weight[s, k + 2])
        for j in range(2, n_nodes):
            if k == 0:
                o0, o1, o2 = offset[s, 0, j], offset[s, 1, j], offset[s, 2, j]
                b0 = r00 * o0 + r01 * o1 + r02 * o2
                b1 = r10 * o0 + r11 * o1 + r12 * o2
                b2 = r20 * o0 + r21 * o1 + r22 * o2
            else:
                b0, b1, b2 = blk[j, 0, lane], blk[j, 1, lane], blk[j, 2, lane]
            blk[j, 0, lane] = b0 + w0 * gcol[g0, 0, j] + w1 * gcol[g1, 0, j] + \
                w2 * gcol[g2, 0, j]
            blk[j, 1, lane] = b1 + w0 * gcol[g0, 1, j] + w1 * gcol[g1, 1, j] + \
                w2 * gcol[g2, 1, j]
            blk[j, 2, lane] = b2 + w0 * gcol[g0, 2, j] + w1 * gcol[g1, 2, j] + \
                w2 * gcol[g2, 2, j]


@njit(cache=True, error_model='numpy', fastmath=FASTMATH)
def _blend_blocks(target, model, pose, restore, collide, geo, blocks):
    """Steps 2-3 for the blocks ``blocks = (b0, b1)``, ``b0 .. b1 - 1``, of
    :data:`STRAND_BLOCK` strands (``target``, ``model``, ``pose`` as :func:`blend_strands`
    takes them, ``geo`` the collider in the world: its centre, then the entries of ``Q``,
    :func:`~hair_tracking.ghosts.stateless.world_collider`); returns the number of nodes that
    were inside the collider and the number of points written that are not finite (counted
    with ``check`` only)."""
    out, out_rot, out_origin, moved, check = target                     # Placement
    offset, roots, rest_length, guide, weight, is_guide, guide_length = model   # BlendModel
    gcol, rot, pos = pose                                               # GuidePose
    cw, quad = geo[:3], geo[3:]
    b0, b1 = blocks
    n_strands, n_nodes = offset.shape[0], offset.shape[2]
    contacts = 0
    bad = 0
    r00, r01, r02 = rot[0, 0], rot[0, 1], rot[0, 2]
    r10, r11, r12 = rot[1, 0], rot[1, 1], rot[1, 2]
    r20, r21, r22 = rot[2, 0], rot[2, 1], rot[2, 2]
    c0, c1, c2 = cw[0], cw[1], cw[2]
    q0, q1, q2, q3, q4, q5 = quad[0], quad[1], quad[2], quad[3], quad[4], quad[5]
    centre, entries = (c0, c1, c2), (q0, q1, q2, q3, q4, q5)
    # a block node-major: x y z, rest length of the segment ending there, inside test, and
    # the length tolerance (-1: always restored; a guide: GUIDE_LENGTH_TOLERANCE, and no
    # contacts unless the length pass moved it: the guide solver has placed it)
    blk = np.empty((n_nodes, 6, STRAND_BLOCK))
    lanes = blk.shape[2]       # not a compile-time constant: LLVM vectorises the lane loop
    for b in range(b0, b1):
        s0 = b * STRAND_BLOCK
        for j in range(n_nodes):
            for lane in range(lanes):
                blk[j, 5, lane] = -1.0
        for lane in range(STRAND_BLOCK):
            s = s0 + lane
            if s >= n_strands:
                for j in range(n_nodes):         # a straight stand-in, never written back
                    blk[j, 0, lane] = 0.0
                    blk[j, 1, lane] = 0.0
                    blk[j, 2, lane] = 1e3 + j
                    blk[j, 3, lane] = 1.0
                continue
            if is_guide[s] >= 0:                 # a guide: its own points, then step 3
                g = is_guide[s]
                for j in range(n_nodes):
                    blk[j, 0, lane] = gcol[g, 0, j]
                    blk[j, 1, lane] = gcol[g, 1, j]
                    blk[j, 2, lane] = gcol[g, 2, j]
                    blk[j, 3, lane] = guide_length[g, j - 1] if j > 0 else 1.0
                    blk[j, 5, lane] = GUIDE_LENGTH_TOLERANCE
                continue
            _deform(blk, lane, offset, rot, guide, weight, gcol, s)      # step 2
            for j in range(2, n_nodes):
                blk[j, 3, lane] = float(rest_length[s, j - 1])
            for j in range(2):                   # roots ride with the head
                u0, u1, u2 = roots[s, j, 0], roots[s, j, 1], roots[s, j, 2]
                blk[j, 0, lane] = r00 * u0 + r01 * u1 + r02 * u2 + pos[0]
                blk[j, 1, lane] = r10 * u0 + r11 * u1 + r12 * u2 + pos[1]
                blk[j, 2, lane] = r20 * u0 + r21 * u1 + r22 * u2 + pos[2]
        if restore or collide:                   # step 3, node by node, all lanes at once
            for j in range(2, n_nodes):
                if restore:
                    for lane in range(lanes):
                        px, py, pz = blk[j - 1, 0, lane], blk[j - 1, 1, lane], \
                            blk[j - 1, 2, lane]
                        dx, dy, dz = blk[j, 0, lane] - px, blk[j, 1, lane] - py, \
                            blk[j, 2, lane] - pz
                        f = blk[j, 3, lane] / math.sqrt(dx * dx + dy * dy + dz * dz)
                        nx, ny, nz = blk[j, 0, lane], blk[j, 1, lane], blk[j, 2, lane]
                        if abs(f - 1.0) > blk[j, 5, lane]:
                            nx, ny, nz = px + f * dx, py + f * dy, pz + f * dz
                            blk[j, 5, lane] = -1.0       # moved: contacts apply from here
                        blk[j, 0, lane] = nx
                        blk[j, 1, lane] = ny
                        blk[j, 2, lane] = nz
                        blk[j, 4, lane] = quadric(nx - c0, ny - c1, nz - c2,
                                                  q0, q1, q2, q3, q4, q5)
                else:
                    for lane in range(lanes):
                        blk[j, 4, lane] = quadric(
                            blk[j, 0, lane] - c0, blk[j, 1, lane] - c1, blk[j, 2, lane] - c2,
                            q0, q1, q2, q3, q4, q5)
                if not collide:
                    continue
                inside = 0                       # any lane inside? (a vector test)
                for lane in range(lanes):
                    inside += 1 if blk[j, 4, lane] < 1.0 and blk[j, 5, lane] < 0.0 else 0
                if inside == 0:
                    continue
                for lane in range(STRAND_BLOCK):
                    if blk[j, 4, lane] >= 1.0 or blk[j, 5, lane] >= 0.0:
                        continue
                    contacts += 1
                    nx, ny, nz = blk[j, 0, lane], blk[j, 1, lane], blk[j, 2, lane]
                    if restore:
                        nx, ny, nz = slide_quadric(nx, ny, nz, blk[j - 1, 0, lane],
                                                   blk[j - 1, 1, lane], blk[j - 1, 2, lane],
                                                   blk[j, 3, lane], centre, entries)
                    nx, ny, nz = push_quadric(nx, ny, nz, centre, entries)
                    blk[j, 0, lane] = nx
                    blk[j, 1, lane] = ny
                    blk[j, 2, lane] = nz
        for lane in range(STRAND_BLOCK):
            s = s0 + lane
            if s >= n_strands:
                continue
            if check:
                for j in range(n_nodes):
                    bad += put_record(out, s, j, blk[j, 0, lane], blk[j, 1, lane],
                                      blk[j, 2, lane], out_rot, out_origin, moved)
            else:
                for j in range(n_nodes):
                    out[s, j, 0] = blk[j, 0, lane]
                    out[s, j, 1] = blk[j, 1, lane]
                    out[s, j, 2] = blk[j, 2, lane]
    return contacts, bad


@njit(cache=True, parallel=True, fastmath=FASTMATH)
def blend_strands(target, model, pose, params):
    """Kernel, steps 2-3: every strand's nodes written into ``target`` (the fields of
    :data:`~hair_tracking.ghosts.stateless.Placement`: x y z into ``out`` (S, N, >= 3), world
    [m]; with ``check`` as point records, :func:`~hair_tracking.core.point_records.put_record`);
    ``model`` the fields of :data:`BlendModel`; ``pose`` the fields of
    :data:`~hair_tracking.ghosts.stateless.GuidePose` (step 1,
    :func:`~hair_tracking.ghosts.stateless.guide_columns`, and the head pose); ``params`` the
    fields of :data:`BlendParams`. A strand that is guide ``is_guide[s] >= 0`` enters step 3 as
    that guide's ``gcol``, its segments held to ``guide_length`` within
    :data:`GUIDE_LENGTH_TOLERANCE` and left to the guide solver's contacts until the length
    pass moves it. Returns the number of nodes that were inside the collider and whether every
    coordinate written is finite (always true without ``check``)."""
    restore, collide, center, axes = params
    offset, _, _, _, _, _, _ = model                                    # BlendModel
    _, rot, pos = pose                                                  # GuidePose
    n_strands = offset.shape[0]
    geo = np.empty(9)                    # the collider in the world: centre, then Q
    world_collider(rot, pos, center, axes, geo)
    n_blocks = (n_strands + STRAND_BLOCK - 1) // STRAND_BLOCK
    n_chunks = min(n_blocks, CHUNKS)
    contacts = 0
    bad = 0
    for c in prange(n_chunks):
        inside, not_finite = _blend_blocks(
            target, model, pose, restore, collide, geo,
            (c * n_blocks // n_chunks, (c + 1) * n_blocks // n_chunks))
        contacts += inside
        bad += not_finite
    return contacts, bad == 0


# ----------------------------------------------------------------------------- reference
def rest_offsets(rest, guide_rest, guide, weight) -> np.ndarray:
    """``o_j = r_j - sum_k w_k g0_k,j`` (step 2) of every strand (S, N, 3), head frame:
    ``rest`` (S, N, 3) the strands, ``guide_rest`` (G, N, 3) the guides at the strands' node
    fractions, ``guide``/``weight`` (S, K) from :func:`blend_weights`."""
    w = np.asarray(weight, dtype=np.float64)
    return np.asarray(rest, dtype=np.float64) - np.einsum('sk,skjc->sjc', w,
                                                          guide_rest[guide])


def reference_blend(gx, grest, rest, rest_length, guide, weight, head: HeadPose,
                    restore: bool = True, collider_axes=None, center=(0.0, 0.0, 0.0),
                    is_guide=None, guide_length=None):
    """Plain-numpy statement of one blend step (steps 1-3 of the module docstring); returns the
    strands (S, N, 3), world frame.  ``gx``/``grest`` (G, M, 3) the guides now (world) and at
    rest (head frame); ``rest`` (S, N, 3) the strands at rest; a strand that is guide
    ``is_guide[s] >= 0`` enters step 3 as that guide's points (segments held to
    ``guide_length`` within :data:`GUIDE_LENGTH_TOLERANCE`; no contacts for a node the length
    pass left where the guide solver put it).  Slow; for tests and for reading."""
    rot, pos = head.rotation, head.position
    s_count, n_nodes = rest.shape[:2]
    seg, t = node_map(n_nodes, gx.shape[1])
    g = at_fractions(gx, seg, t)                                          # step 1
    offset = rest_offsets(rest, at_fractions(grest, seg, t), guide, weight)
    out = np.empty((s_count, n_nodes, 3))
    for s in range(s_count):
        own = is_guide is not None and is_guide[s] >= 0       # a guide: its own points
        for j in range(n_nodes):
            if own:
                p = g[is_guide[s], j]
                if j < 2:
                    out[s, j] = p
                    continue
            elif j < 2:
                out[s, j] = rot @ rest[s, j] + pos
                continue
            else:
                p = rot @ offset[s, j]                                      # step 2
                for k in range(guide.shape[1]):
                    p = p + float(weight[s, k]) * g[guide[s, k], j]
            length = float(rest_length[s, j - 1])                           # step 3
            if own and guide_length is not None:
                length = float(guide_length[is_guide[s], j - 1])
            prev = out[s, j - 1]
            placed = own                  # a guide node as the solver placed it: no contacts
            if restore:
                d = p - prev
                f = length / np.linalg.norm(d)
                if not own or abs(f - 1.0) > GUIDE_LENGTH_TOLERANCE:
                    p = prev + d * f
                    placed = False
            if collider_axes is not None and not placed:
                p = reference_contact(p, prev, length, head, collider_axes, center, restore)
            out[s, j] = p
    return out


# ----------------------------------------------------------------------------- tracker
class BlendTracker(StatelessTracker):
    """Moves ``ghosts`` after ``guides`` when they are read (see the module docstring and
    :class:`~hair_tracking.ghosts.stateless.StatelessTracker`); ``k`` guides are blended per
    ghost."""

    def __init__(self, ghosts: StrandSet, guides: StrandSet, guide_index, scene, collider=None,
                 k: int = DEFAULT_GUIDES_PER_GHOST, colliders=None):
        super().__init__(ghosts, guides, guide_index, scene, collider, colliders)
        self.guide_of, self.weight = blend_weights(ghosts.rest[:, 0], guides.rest[:, 0], k)
        guide_pad, weight_pad = pad_guides(self.guide_of, self.weight)
        #: the guide each strand is, -1 for the others (those copy their guide)
        self.is_guide = np.full(ghosts.count, -1, dtype=np.int64)
        self.is_guide[self.guide_index] = np.arange(guides.count)
        offset32 = np.ascontiguousarray(rest_offsets(
            ghosts.rest, at_fractions(guides.rest, self.seg, self.t), self.guide_of,
            self.weight).transpose(0, 2, 1), dtype=np.float32)
        #: the kernel's static data: the fields of :data:`BlendModel` (a plain tuple)
        self.model = (offset32, np.ascontiguousarray(ghosts.rest[:, :2], dtype=np.float64),
                      np.ascontiguousarray(ghosts.rest_length, dtype=np.float32), guide_pad,
                      weight_pad, self.is_guide,
                      np.ascontiguousarray(guides.rest_length, dtype=np.float64))
        #: the kernel's parameters: the fields of :data:`BlendParams` (a plain tuple)
        self.params = (bool(scene.tracking.length_restore), self.collide, self.center,
                       self.axes)

    def _place(self, target) -> Tuple[int, bool]:
        """Steps 2-3 of the module docstring."""
        return blend_strands(target, self.model, self._pose, self.params)

    def _place_part(self, part: int, parts: int) -> np.ndarray:
        """The strands of the part (:func:`~hair_tracking.core.model.part_rows`): the output
        and every per-strand input sliced to them, so the kernel places them alone."""
        rows = part_rows(self.ghosts.count, part, parts)
        self._place_rows(rows, (self._x32[rows],) + self._x32_target[1:])
        return np.arange(rows.start, rows.stop)

    def _place_rows(self, rows: slice, target) -> Tuple[int, bool]:
        """The strands ``rows`` (from a multiple of :data:`STRAND_BLOCK`, so they form the
        same blocks as in a whole placement): every per-strand input sliced to them."""
        m = self.model
        model = tuple(a[rows] for a in m[:6]) + (m[6],)
        return blend_strands(target, model, self._pose, self.params)
