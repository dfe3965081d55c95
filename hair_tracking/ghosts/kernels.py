"""numba kernels of ghost tracking: the guide frames and the fused per-group tracking step.

One call of :func:`track_groups` advances every ghost node one substep.  It runs in parallel
over *groups* (the ghosts of one guide; a group's nodes fit in the L1/L2 cache) and does, in
order (the letters of ``docs/ghosts.md``):

a. velocity transfer: the node moves by the displacement ``u dt`` of its target point on the
   guide (the guide point at the node's arc-length fraction, Park & Kim section 3);
b. weights, equations (4)-(5): ``pos* = pos + u dt (W* + w_tip + w_com)``, sum clamped;
c. offset feedback: pull toward ``guide point + Q rest_offset`` (``Q`` the guide segment frame);
d. centre-of-mass tracking (Park & Kim Fig. 1; Milliez et al. 2018): the group's centre of mass
   at each node index moves toward the centre of mass of its targets;
e. spread control (HairControl, Milliez et al. 2018, eqs. (2)-(3)): offsets from the centre of
   mass scaled toward the target variance;
f. length restoration: one Follow-The-Leader pass (Mueller, Kim & Chentanez 2012);
g. roots (nodes 0 and 1) pinned at the head-carried rest shape;
h. (optional) collision with the head ellipsoid, node by node after (f);
then ``v = (x_new - x_old) / dt``.

Conventions: world frame positions [m] and velocities [m/s]; rest data in the head frame;
``R`` (3, 3) and ``pos`` (3,) the head pose (``p_world = pos + R p_head``).  Every per-ghost
array of the kernel is stored in group order (row ``k`` belongs to ghost ``order[k]``); the
per-node ones (the state ``xb``, ``vb``, the rest offsets, the segment lengths) *block by block
(runs of consecutive groups, :func:`block_groups`), inside a block [node][axis][ghost]*
(:func:`group_blocks`), so that every stage is a unit-stride loop over ghosts that LLVM
vectorises.  The tracker keeps its ghosts' state in this
layout between substeps (:func:`copy_blocks` converts from and to the
``(S, N, 3)`` arrays of the user's order only when those are read or written): the two
transposes, scalar loops, cost as much as all stages together when they ran every substep.
Only the rest shapes ``rest`` stay ``(S, N, 3)`` in the user's order (read for the pinned roots
and the rare fallbacks), reached through ``order``.  No cross-thread reductions: results are
deterministic.
"""
from collections import namedtuple
import math

from numba import njit, prange, uint64
import numpy as np

from hair_tracking.ghosts.contacts import collide_lanes, CONTACT_ROWS
from hair_tracking.ghosts.spread import group_variance, spread_factor
from hair_tracking.ghosts.weights import com_weight, elastic_weight, ELASTIC_OFF, weighted_position
from hair_tracking.colliders.head import rotation_entries, world_center
from hair_tracking.core.kernels import parallel_and_serial


@njit(cache=True, inline='always')
def segment_frame_into(guide_x, tan_rest, gi, s, R, Q, q0):
    """``Q[q0, s]`` (3, 3) = R_min(R t_rest -> t_now) @ R for segment ``s`` of guide ``gi``
    (written through indices, not a view: creating views in the hot loops costs).

    ``R_min(a -> b) = c I + [a x b]_x + (a x b)(a x b)^T / (1 + c)``, ``c = a . b`` (the smallest
    rotation taking unit ``a`` onto unit ``b``, Rodrigues' formula).  Within 1e-6 of a half turn
    the rotation by pi about an axis perpendicular to ``a`` is used; a degenerate segment (zero
    length now or at rest) gives ``Q = R``.
    """
    ax = R[0, 0] * tan_rest[gi, s, 0] + R[0, 1] * tan_rest[gi, s, 1] + R[0, 2] * tan_rest[gi, s, 2]
    ay = R[1, 0] * tan_rest[gi, s, 0] + R[1, 1] * tan_rest[gi, s, 1] + R[1, 2] * tan_rest[gi, s, 2]
    az = R[2, 0] * tan_rest[gi, s, 0] + R[2, 1] * tan_rest[gi, s, 1] + R[2, 2] * tan_rest[gi, s, 2]
    bx = guide_x[gi, s + 1, 0] - guide_x[gi, s, 0]
    by = guide_x[gi, s + 1, 1] - guide_x[gi, s, 1]
    bz = guide_x[gi, s + 1, 2] - guide_x[gi, s, 2]
    na = ax * ax + ay * ay + az * az
    nb = math.sqrt(bx * bx + by * by + bz * bz)
    if na < 0.25 or not (nb > 1e-300) or not (nb < 1e300):
        for r in range(3):
            for c in range(3):
                Q[q0, s, r, c] = R[r, c]
        return
    bx /= nb
    by /= nb
    bz /= nb
    c = ax * bx + ay * by + az * bz
    m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
    if 1.0 + c < 1e-6:
        # half turn about p perpendicular to a: M = 2 p p^T - I
        if abs(ax) <= abs(ay) and abs(ax) <= abs(az):
            px, py, pz = 0.0, az, -ay          # a x e_x
        elif abs(ay) <= abs(az):
            px, py, pz = -az, 0.0, ax          # a x e_y
        else:
            px, py, pz = ay, -ax, 0.0          # a x e_z
        npn = math.sqrt(px * px + py * py + pz * pz)
        px /= npn
        py /= npn
        pz /= npn
        m00 = 2.0 * px * px - 1.0
        m01 = 2.0 * px * py
        m02 = 2.0 * px * pz
        m10 = m01
        m11 = 2.0 * py * py - 1.0
        m12 = 2.0 * py * pz
        m20 = m02
        m21 = m12
        m22 = 2.0 * pz * pz - 1.0
    else:
        vx = ay * bz - az * by
        vy = az * bx - ax * bz
        vz = ax * by - ay * bx
        k = 1.0 / (1.0 + c)
        m00 = c + k * vx * vx
        m01 = -vz + k * vx * vy
        m02 = vy + k * vx * vz
        m10 = vz + k * vy * vx
        m11 = c + k * vy * vy
        m12 = -vx + k * vy * vz
        m20 = -vy + k * vz * vx
        m21 = vx + k * vz * vy
        m22 = c + k * vz * vz
    for col in range(3):
        r0 = R[0, col]
        r1 = R[1, col]
        r2 = R[2, col]
        Q[q0, s, 0, col] = m00 * r0 + m01 * r1 + m02 * r2
        Q[q0, s, 1, col] = m10 * r0 + m11 * r1 + m12 * r2
        Q[q0, s, 2, col] = m20 * r0 + m21 * r1 + m22 * r2


@njit(cache=True, nogil=True, parallel=True)
def guide_frames_kernel(guide_x, tan_rest, R, out):
    """Frames of every guide segment: ``out[g, s]`` (3, 3) = ``R_min(R t_rest[g, s] -> t_now) R``
    (see :func:`segment_frame_into`).  ``guide_x`` (G, M, 3) world [m], ``tan_rest`` (G, M-1,
    3) unit rest tangents in the head frame (zero rows for degenerate segments)."""
    for g in prange(guide_x.shape[0]):
        for s in range(guide_x.shape[1] - 1):
            segment_frame_into(guide_x, tan_rest, g, s, R, out, g)


#: Fast-math flags of the tracking kernel: fused multiply-add and reassociation (so that LLVM
#: vectorises the loops over a group's ghosts, sums included); no flag that assumes finite input.
TRACK_FASTMATH = {'contract', 'reassoc'}

#: Rows of the per-chunk work space ``tmp`` of :func:`track_groups` (per lane of a block).
_DX, _DY, _DZ, _QX, _QY, _QZ, _TW, _FLAG, _C0, _C1, _C2, _CW = range(12)
_KERNEL_ROWS = 12
#: ... followed by the rows of the head contact stage (:mod:`hair_tracking.ghosts.contacts`).
TMP_ROWS = _KERNEL_ROWS + CONTACT_ROWS

#: Lanes (ghosts) a block of consecutive groups holds at most (a larger group is a block of its
#: own).  Every loop has a fixed cost (set-up, runtime alias checks, remainder), which loops
#: over single groups of 4-16 ghosts would pay again and again: packing groups into blocks of
#: a few dozen ghosts spreads it.
BLOCK_LANES = 64


#: The arguments of :func:`track_groups`, grouped as NVIDIA Warp / Newton separate a solver's
#: inputs; the fields are described in :func:`track_groups`.  The kernel takes them as plain
#: tuples in these fields' order (``tuple(GhostModel(...))``): numba types a named tuple by
#: encoding its class and field names on every call.
#: Static data of the ghosts and guides, built once
# (:class:`~hair_tracking.ghosts.tracker.GhostTracker`).
GhostModel = namedtuple('GhostModel', [
    'rest', 'seg_len', 'order', 'group_start', 'block_group', 'group_guide', 'group_row',
    'node_table', 'node_row', 'rest_off', 'root_rest', 'inv_len', 'var_target', 'tan_rest'])
#: The ghosts' state, advanced in place.
GhostState = namedtuple('GhostState', ['xb', 'vb'])
#: What drives one substep: the guides after / before it, the head pose, ``1 / dt``.
GuideMotion = namedtuple('GuideMotion', ['guide_x', 'guide_x_old', 'R', 'pos', 'inv_dt'])
#: The tracking parameters (switches, strengths, the fused head collider).
TrackParams = namedtuple('TrackParams', [
    'elastic_mode', 'use_tip', 'com_w', 'max_weight', 'k_off', 'k_com', 'spread', 'ftl',
    'collide', 'center', 'axes', 'friction', 'refine'])
#: Work space and per-call counters.
TrackWork = namedtuple('TrackWork', ['q_buf', 'buf', 'tmp', 'clamped', 'contacts'])


def chunk_count(blocks: int, threads: int) -> int:
    """Chunks of blocks that :func:`track_groups` spreads over ``threads`` threads."""
    return max(1, min(blocks, 4 * threads))


def block_groups(group_start: np.ndarray, lanes: int = BLOCK_LANES) -> np.ndarray:
    """(B+1,) first group of each block: consecutive groups packed while the block holds at
    most ``lanes`` ghosts (a larger group forms a block alone)."""
    starts = [0]
    sizes = np.diff(group_start)
    held = 0
    for g, size in enumerate(sizes):
        if held > 0 and held + size > lanes:
            starts.append(g)
            held = 0
        held += int(size)
    starts.append(sizes.size)
    return np.asarray(starts, dtype=np.int64)


def track_groups(model, state, motion, params, work):
    """One tracking substep of all ghosts, in place on ``state`` (see the module doc).

    Arguments: the fields of :data:`GhostModel`, :data:`GhostState`, :data:`GuideMotion`,
    :data:`TrackParams` and :data:`TrackWork` as five plain tuples, each in its fields' order
    (S ghosts of N nodes, G guides of M nodes, K groups in B blocks, U distinct node rows,
    C chunks, L the most lanes of a block, E the most groups of a block):
    state
      xb, vb (S * N * 3,)     ghost positions [m] / velocities [m/s], world, in the layout of
                              ``rest_off`` (:func:`copy_blocks`)
    model
      rest (S, N, 3)          ghost rest shapes, head frame [m] (roots and FTL fallback)
      seg_len (S * (N-1),)    ghost rest segment lengths [m], in the layout of ``rest_off``
      order (S,)              ghost index of group-order row k
      group_start (K+1,)      rows of group g: group_start[g] .. group_start[g+1]-1
      block_group (B+1,)      groups of block b: block_group[b] .. block_group[b+1]-1
                              (:func:`block_groups`)
      group_guide (K,)        guide of group g
      group_row (K,)          the node_table row shared by every ghost of group g, or -1
      node_table (U, N, 2)    per node: guide parameter ``seg + t`` and ``w_tip``
      node_row (S,)           row of node_table of each ghost (group order); ghosts with the
                              same arc-length layout share a row (all of them, for a groom with
                              evenly spaced nodes)
      rest_off (S * N * 3,)   target offset from the guide point, head frame [m], stored block
                              by block, inside a block as [node][axis][ghost] (see
                              :func:`group_blocks`)
      root_rest (S * R * 3,)  rest positions of the R = min(2, N) pinned root nodes, head frame
                              [m], in the layout of ``rest_off``
      inv_len (S,)            1 / ghost length [1/m] (group order)
      var_target (K, N)       target group variance (sum of squares) [m^2] for spread control
      tan_rest (G, M-1, 3)    unit rest tangents of the guides, head frame
    motion
      guide_x, guide_x_old    (G, M, 3) guides after / before this substep, world [m]
      R (3, 3), pos (3,)      head pose
      inv_dt                  1 / dt [1/s], the substep's inverse, computed by the caller:
                              computed in here, LLVM's reassociation (``TRACK_FASTMATH``)
                              would turn every ``(x_new - x_old) * (1 / dt)`` back into a
                              division, three vector divisions a node
    params
      elastic_mode            weights.ELASTIC_OFF / KEPT / CHANGED
      use_tip, com_w, max_weight, k_off, k_com, spread, ftl   switches and strengths
      collide                 (h) fused: push nodes out of the ellipsoid with semi-axes ``axes``
                              around ``center`` (head frame [m]), ``friction`` relative to the
                              node's start-of-substep position, ``refine`` projection refinements;
                              with ``ftl`` the pushed node is put back at its rest distance
                              (:func:`hair_tracking.guides.ftl.restore_node`)
    work
      q_buf (C, E, M-1, 3, 3) work space per chunk: the segment frames of the block's guides
      buf (C, 3 N L)          work space per chunk: the new positions of a block, [node][axis]
                              [ghost] (64 ghosts of 16 nodes: 24 KiB)
      tmp (C, TMP_ROWS L)     work space per chunk: per-ghost values of one node index
      clamped (B,) out        clamped weight sums per block;  contacts (C,) out  pushed nodes

    Each chunk (a contiguous range of blocks, the unit of parallel work) walks its blocks one
    at a time and a block node index by node index from the root, into ``buf``: group by group
    the centre of mass for w_com, then (a)-(c) in one loop over the group's ghosts with the
    guide point, its displacement and frame as scalars (:func:`_predict_group`; groups whose
    ghosts have different arc-length layouts go through per-lane rows of ``tmp``), summing for
    (d) as it goes, then (d) and (e); then (f) and (h) as one loop over all the block's ghosts
    (Follow-The-Leader finds node ``j - 1`` final).  Then the block's part of ``xb`` and ``vb`` is
    rewritten with ``v = (x_new - x_old) / dt`` in one contiguous loop.  Groups are independent:
    the result does not depend on the number of chunks or threads.
    """
    _, buf, _, _, _ = work                                              # TrackWork
    n_chunks = buf.shape[0]
    for c in prange(n_chunks):
        # the parallel loop's index is unsigned: as int64 the serial variant's loop shares this
        # compiled body instead of compiling its own
        _track_chunk(np.int64(c), n_chunks, model, state, motion, params, work)


track_groups, track_groups_serial = parallel_and_serial(
    track_groups, fastmath=TRACK_FASTMATH, error_model='numpy')


@njit(cache=True, fastmath=TRACK_FASTMATH, error_model='numpy')
def _track_chunk(c, n_chunks, model, state, motion, params, work):
    """Chunk ``c`` of :func:`track_groups` (its blocks ``c B / C .. (c+1) B / C - 1``).  A
    function of its own so that the parallel loop's body stays small (numba's parfor lowering
    copies the body's IR: the smaller the body, the shorter the compilation).  A block's arrays
    are viewed once, as (N, 3, n) [node][axis][ghost] (the per-node stages index them with the
    node ``j``, so the node loop creates no array)."""
    (rest, seg_len, order, group_start, block_group, group_guide, group_row, node_table,
     node_row, rest_off, root_rest, inv_len, var_target, tan_rest) = model      # GhostModel
    xb, vb = state                                                              # GhostState
    guide_x, guide_x_old, R, pos, inv_dt = motion                               # GuideMotion
    (elastic_mode, use_tip, com_w, max_weight, k_off, k_com, spread, ftl, collide, center, axes,
     friction, refine) = params                                                 # TrackParams
    q_buf, buf, tmp, clamped, contacts = work                                   # TrackWork
    n_nodes = rest.shape[1]
    m_last = guide_x.shape[1] - 2
    n_blocks = block_group.shape[0] - 1
    need_target = k_off > 0.0 or k_com > 0.0
    group_level = k_com > 0.0 or spread > 0.0
    cx, cy, cz = world_center(R, pos, center)
    contact = (rotation_entries(R), cx, cy, cz, axes[0], axes[1], axes[2], friction, refine)
    W = buf[c]
    Tc = tmp[c]
    Qc = q_buf[c]
    guide = (node_table, guide_x, guide_x_old, Qc, m_last)
    weights = (need_target, com_w, elastic_mode, use_tip, max_weight, k_off)
    n_contacts = 0
    for b in range(c * n_blocks // n_chunks, (c + 1) * n_blocks // n_chunks):
        g0 = block_group[b]
        g1 = block_group[b + 1]
        r0 = group_start[g0]
        n = group_start[g1] - r0
        clamped[b] = 0
        if n == 0:
            continue
        if need_target:     # frames Q of the segments of the block's guides
            for gg in range(g1 - g0):
                for sg in range(m_last + 1):
                    segment_frame_into(guide_x, tan_rest, group_guide[g0 + gg], sg, R, Qc, gg)
        # the block's state, old x and old v, (N, 3, n) [node][axis][ghost] views of the
        # block arrays, and the new positions in the work space; roots pinned (g)
        b0 = r0 * n_nodes * 3
        b1 = (r0 + n) * n_nodes * 3
        X0 = xb[b0:b1].reshape((n_nodes, 3, n))
        XN = W[:3 * n_nodes * n].reshape((n_nodes, 3, n))
        T = Tc[:TMP_ROWS * n].reshape((TMP_ROWS, n))
        n_roots = min(2, n_nodes)
        RB = root_rest[r0 * n_roots * 3:(r0 + n) * n_roots * 3].reshape((n_roots, 3, n))
        for j in range(n_roots):
            for a in range(3):      # contiguous loops over the block's ghosts (vectorise)
                ra0, ra1, ra2, pa = R[a, 0], R[a, 1], R[a, 2], pos[a]
                for kk in range(n):
                    XN[j, a, kk] = pa + ra0 * RB[j, 0, kk] + ra1 * RB[j, 1, kk] + \
                        ra2 * RB[j, 2, kk]
        n_clamped = 0
        # the block's old state, new positions, rest offsets (N, 3, n) and 1 / lengths (n,)
        block = (X0, vb[b0:b1].reshape((n_nodes, 3, n)), XN,
                 rest_off[b0:b1].reshape((n_nodes, 3, n)), inv_len[r0:r0 + n])
        # segment lengths (N-1, n), and what the contact stage reads of the strands
        len_b = seg_len[r0 * (n_nodes - 1):(r0 + n) * (n_nodes - 1)].reshape((n_nodes - 1, n))
        strands = (order, len_b, rest)
        WC = T[_KERNEL_ROWS:]
        for j in range(2, n_nodes):
            for gg in range(g1 - g0):       # per group: (a)-(c), then (d)-(e)
                g = g0 + gg
                lanes = (group_start[g] - r0, group_start[g + 1] - r0)
                row = group_row[g]
                if row >= 0:
                    # the usual case, one arc-length layout in the group: its guide point,
                    # displacement, frame and centre of mass are scalars of one loop
                    nc, sums = _predict_group(block, j, lanes, (group_guide[g], row, gg), guide,
                                              weights)
                else:
                    _targets(T, block, j, lanes, group_start[g], (group_guide[g], gg),
                             node_row, guide, need_target)
                    _com_lanes(X0, T, j, lanes, com_w)
                    nc = _predict(block, T, j, lanes, weights)
                    sums = _group_sums(XN, T, j, lanes)
                n_clamped += nc
                if group_level:
                    _group_stage(XN, j, lanes, (k_com, spread, var_target[g, j], need_target),
                                 sums)
            if ftl:
                _follow(XN, T, j, (n, r0), strands, R)
            if collide:
                n_contacts += collide_lanes(X0, XN, WC, j, (n, r0), strands, ftl, contact, R)
        clamped[b] = n_clamped
        # the new state: v = (x_new - x_old) / dt, then x = x_new (one contiguous loop)
        u0 = uint64(b0)
        for i in range(uint64(b1 - b0)):
            xn = W[i]
            vb[u0 + i] = (xn - xb[u0 + i]) * inv_dt
            xb[u0 + i] = xn
    contacts[c] = n_contacts


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _guide_point(gi, gp, guide_x, guide_x_old, m_last):
    """Guide ``gi`` at parameter ``gp`` (segment + fraction): (segment, point P [m],
    displacement ``u dt`` of that point over the substep [m])."""
    sg = min(int(gp), m_last)
    t = gp - sg
    u = 1.0 - t
    px = u * guide_x[gi, sg, 0] + t * guide_x[gi, sg + 1, 0]
    py = u * guide_x[gi, sg, 1] + t * guide_x[gi, sg + 1, 1]
    pz = u * guide_x[gi, sg, 2] + t * guide_x[gi, sg + 1, 2]
    dx = px - (u * guide_x_old[gi, sg, 0] + t * guide_x_old[gi, sg + 1, 0])
    dy = py - (u * guide_x_old[gi, sg, 1] + t * guide_x_old[gi, sg + 1, 1])
    dz = pz - (u * guide_x_old[gi, sg, 2] + t * guide_x_old[gi, sg + 1, 2])
    return sg, px, py, pz, dx, dy, dz


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _group_point(group, j, guide, need_target):
    """The guide point ``P`` of node ``j`` for a group (``group`` = ``(guide, node_table row,
    its frames' row)``) sharing one node_table row, its displacement ``u dt`` over the substep,
    w_tip and the segment frame ``Q`` (zero unless ``need_target``): (px, py, pz, dx, dy, dz,
    tw, q00 .. q22).  ``guide`` = ``(node_table, guide_x, guide_x_old, frames, m_last)``."""
    gi, row, fg = group
    node_table, guide_x, guide_x_old, frames, m_last = guide
    tw = node_table[row, j, 1]
    sg, px, py, pz, dx, dy, dz = _guide_point(gi, node_table[row, j, 0], guide_x, guide_x_old,
                                              m_last)
    q00 = q01 = q02 = q10 = q11 = q12 = q20 = q21 = q22 = 0.0
    if need_target:
        q00, q01, q02 = frames[fg, sg, 0, 0], frames[fg, sg, 0, 1], frames[fg, sg, 0, 2]
        q10, q11, q12 = frames[fg, sg, 1, 0], frames[fg, sg, 1, 1], frames[fg, sg, 1, 2]
        q20, q21, q22 = frames[fg, sg, 2, 0], frames[fg, sg, 2, 1], frames[fg, sg, 2, 2]
    return px, py, pz, dx, dy, dz, tw, q00, q01, q02, q10, q11, q12, q20, q21, q22


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _group_centre(X0, j, lanes, com_w):
    """w_com's inputs of one group (``lanes`` = ``(l0, l1)``: lanes ``l0 .. l1-1`` of the
    block's start positions ``X0`` (N, 3, n) at node ``j``): its centre of mass at the start of
    the substep and the weight per length (0 for a group of one ghost or with ``com_w``
    off)."""
    l0, l1 = lanes
    n = l1 - l0
    cw = com_w if com_w > 0.0 and n > 1 else 0.0
    u0 = uint64(l0)
    c0 = c1 = c2 = 0.0
    if cw > 0.0:
        for kk in range(uint64(n)):
            i = u0 + kk
            c0 += X0[j, 0, i]
            c1 += X0[j, 1, i]
            c2 += X0[j, 2, i]
        c0 /= n
        c1 /= n
        c2 /= n
    return c0, c1, c2, cw


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _predict_group(block, j, lanes, group, guide, weights):
    """(a)-(c) at node ``j`` for the lanes ``lanes = (l0, l1)`` of one group whose ghosts share
    one node_table row (the usual case; ``group``, ``guide`` as :func:`_group_point` takes them):
    the guide point, its displacement, w_tip, the segment frame and the group's centre of mass
    are scalars, and one loop over the group's ghosts writes the new positions.  ``block`` =
    ``(X0, V0, P, off, inv_len)``: the block's start positions, velocities, new positions and
    rest offsets (N, 3, n) and 1 / strand length (n,); ``weights`` = ``(need_target, com_w,
    elastic_mode, use_tip, max_weight, k_off)``.  Returns the clamped count and the sums over
    the group of the new positions and of the targets ``q = P + Q o`` (for (d)).

    Per lane the same arithmetic as :func:`_targets` + :func:`_com_lanes` + :func:`_predict`
    (which the rare groups with mixed layouts still take), without writing the per-group values
    out into a row per lane and reading them back, and with the sums of (d) taken in the same
    loop: two loops fewer per group and node index."""
    X0, V0, P, off, inv_len = block
    need_target, com_w, elastic_mode, use_tip, max_weight, k_off = weights
    (px, py, pz, dx, dy, dz, tw, q00, q01, q02, q10, q11, q12, q20, q21,
     q22) = _group_point(group, j, guide, need_target)
    c0, c1, c2, cw = _group_centre(X0, j, lanes, com_w)
    tip = (1.0 if use_tip else 0.0) * tw
    l0, l1 = lanes
    u0 = uint64(l0)
    n = uint64(l1 - l0)
    n_clamped = 0
    xs0 = xs1 = xs2 = qs0 = qs1 = qs2 = 0.0
    for kk in range(n):             # (the invariant branch is unswitched by LLVM)
        i = u0 + kk
        w = elastic_weight(dx, dy, dz, V0[j, 0, i], V0[j, 1, i], V0[j, 2, i], elastic_mode)
        o0 = off[j, 0, i]
        o1 = off[j, 1, i]
        o2 = off[j, 2, i]
        t0 = px + q00 * o0 + q01 * o1 + q02 * o2
        t1 = py + q10 * o0 + q11 * o1 + q12 * o2
        t2 = pz + q20 * o0 + q21 * o1 + q22 * o2
        y0, y1, y2, clamped = _moved((X0[j, 0, i], X0[j, 1, i], X0[j, 2, i]), w, tip,
                                     (c0, c1, c2, cw), inv_len[i], (dx, dy, dz), (t0, t1, t2),
                                     (max_weight, k_off))
        n_clamped += clamped
        P[j, 0, i] = y0
        P[j, 1, i] = y1
        P[j, 2, i] = y2
        xs0 += y0
        xs1 += y1
        xs2 += y2
        qs0 += t0
        qs1 += t1
        qs2 += t2
    return n_clamped, (xs0, xs1, xs2, qs0, qs1, qs2)


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _targets(T, block, j, lanes, k0, group, node_row, guide, need_target):
    """Lanes ``lanes = (l0, l1)`` of a block, the ghosts of one group (``group`` = ``(guide,
    its frames' row)``; group order rows from ``k0``) whose arc-length layouts differ (each its
    own node_table row, ``node_row``): at node ``j`` the displacement ``u dt`` of each ghost's
    guide point (a) into T[_DX.._DZ], the target ``q = P + Q o`` (c) into T[_QX.._QZ] (if
    ``need_target``) and w_tip into T[_TW].  ``block`` and ``guide`` as
    :func:`_predict_group` takes them.  (Groups sharing one layout take
    :func:`_predict_group`.)

    The lanes of a group are indexed with unsigned integers (``uint64``): numba wraps negative
    signed indices around, and that select turns the loop's loads into gathers LLVM does not
    vectorise; views of the lanes (indices from 0) vectorise too but cost an allocation each,
    which small groups would pay once per group and node."""
    off = block[3]
    gi, fg = group
    node_table, guide_x, guide_x_old, frames, m_last = guide
    l0, l1 = lanes
    u0 = uint64(l0)
    n = uint64(l1 - l0)
    for kk in range(n):
        i = u0 + kk
        r = node_row[uint64(k0) + kk]
        T[_TW, i] = node_table[r, j, 1]
        sg, px, py, pz, dx, dy, dz = _guide_point(gi, node_table[r, j, 0], guide_x, guide_x_old,
                                                  m_last)
        T[_DX, i] = dx
        T[_DY, i] = dy
        T[_DZ, i] = dz
        if need_target:
            o0 = off[j, 0, i]
            o1 = off[j, 1, i]
            o2 = off[j, 2, i]
            px += (frames[fg, sg, 0, 0] * o0 + frames[fg, sg, 0, 1] * o1 +
                   frames[fg, sg, 0, 2] * o2)
            py += (frames[fg, sg, 1, 0] * o0 + frames[fg, sg, 1, 1] * o1 +
                   frames[fg, sg, 1, 2] * o2)
            pz += (frames[fg, sg, 2, 0] * o0 + frames[fg, sg, 2, 1] * o1 +
                   frames[fg, sg, 2, 2] * o2)
        T[_QX, i] = px
        T[_QY, i] = py
        T[_QZ, i] = pz


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _com_lanes(X0, T, j, lanes, com_w):
    """w_com's inputs for the lanes ``lanes`` (one group, mixed layouts): the group's centre
    of mass at the start of the substep into T[_C0.._C2] and the weight per length into T[_CW]
    (see :func:`_group_centre`)."""
    c0, c1, c2, cw = _group_centre(X0, j, lanes, com_w)
    l0, l1 = lanes
    u0 = uint64(l0)
    for kk in range(uint64(l1 - l0)):
        i = u0 + kk
        T[_C0, i] = c0
        T[_C1, i] = c1
        T[_C2, i] = c2
        T[_CW, i] = cw


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _predict(block, T, j, lanes, weights):
    """(a)-(c) at node ``j`` for the lanes ``lanes`` (a group with mixed layouts) from the
    per-lane rows of ``T``: the new position = old position + ``u dt`` (1 + W), pulled by
    ``k_off`` toward the target; ``block``, ``weights`` as :func:`_predict_group` takes them.
    Returns the number of clamped weight sums.  Branch-free loops (switched-off terms enter
    with a factor 0), so that they vectorise."""
    V0 = block[1]
    elastic_mode, use_tip = weights[2], weights[3]
    tip_f = 1.0 if use_tip else 0.0
    n_clamped = 0
    l0, l1 = lanes
    u0 = uint64(l0)
    n = uint64(l1 - l0)
    if elastic_mode != ELASTIC_OFF:
        for kk in range(n):
            i = u0 + kk
            w = elastic_weight(T[_DX, i], T[_DY, i], T[_DZ, i], V0[j, 0, i], V0[j, 1, i],
                               V0[j, 2, i], elastic_mode)
            n_clamped += _advance(block, T, j, i, w, tip_f, weights)
    else:
        for kk in range(n):
            n_clamped += _advance(block, T, j, u0 + kk, 0.0, tip_f, weights)
    return n_clamped


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _moved(xo, w, tip, centre, ilen, d, t, limits):
    """(a)-(c) for one node at ``xo`` (x, y, z) given its elastic weight ``w`` (equation (4)):
    w_com (``centre`` = ``(c0, c1, c2, cw)``: the group centre and weight per length; ``ilen``
    1 / strand length), then equation (5) with w_tip ``tip``
    (:func:`~hair_tracking.ghosts.weights.weighted_position`: the move by the guide
    displacement ``d`` times (1 + W), W clamped to ``limits[0]``) and the pull by ``limits[1]``
    toward the target ``t``.  Returns the new position and 1 if the weight sum was clamped.
    The one per-node formula of both paths (:func:`_predict_group`, :func:`_advance`)."""
    xo0, xo1, xo2 = xo
    c0, c1, c2, cw = centre
    t0, t1, t2 = t
    max_weight, k_off = limits
    e0 = xo0 - c0
    e1 = xo1 - c1
    e2 = xo2 - c2
    w_com = com_weight(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), ilen, cw)
    x0, x1, x2, clamped = weighted_position(xo0, xo1, xo2, d[0], d[1], d[2], w, tip, w_com,
                                            max_weight)
    return (x0 + k_off * (t0 - x0), x1 + k_off * (t1 - x1), x2 + k_off * (t2 - x2), clamped)


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _advance(block, T, j, kk, w, tip_f, weights):
    """Lane ``kk`` of :func:`_predict`: :func:`_moved` with the per-lane values of ``T``
    (w_tip, centre, weight per length, displacement, target) into the new positions; 1 if
    clamped."""
    X0, _, P, _, inv_len = block
    P[j, 0, kk], P[j, 1, kk], P[j, 2, kk], clamped = _moved(
        (X0[j, 0, kk], X0[j, 1, kk], X0[j, 2, kk]), w, tip_f * T[_TW, kk],
        (T[_C0, kk], T[_C1, kk], T[_C2, kk], T[_CW, kk]), inv_len[kk],
        (T[_DX, kk], T[_DY, kk], T[_DZ, kk]), (T[_QX, kk], T[_QY, kk], T[_QZ, kk]),
        (weights[4], weights[5]))
    return clamped


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _group_sums(P, T, j, lanes):
    """Sums over the lanes ``lanes`` of the predicted positions ``P`` (N, 3, n) at node ``j``
    and of the targets ``T[_QX.._QZ]`` (groups with mixed layouts; :func:`_predict_group` sums
    as it goes)."""
    l0, l1 = lanes
    u0 = uint64(l0)
    xs0 = xs1 = xs2 = qs0 = qs1 = qs2 = 0.0
    for kk in range(uint64(l1 - l0)):                 # one loop for all six sums
        i = u0 + kk
        xs0 += P[j, 0, i]
        xs1 += P[j, 1, i]
        xs2 += P[j, 2, i]
        qs0 += T[_QX, i]
        qs1 += T[_QY, i]
        qs2 += T[_QZ, i]
    return xs0, xs1, xs2, qs0, qs1, qs2


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _group_stage(P, j, lanes, stage, sums):
    """(d) centre-of-mass tracking and (e) spread control of node ``j`` of one group (the
    lanes ``lanes`` of the block), on the predicted positions ``P`` (N, 3, n) in place;
    ``stage`` = ``(k_com, spread, var_target, have_target)``, ``sums`` the sums of the group's
    predicted positions ``xs*`` and of its targets ``qs*``."""
    k_com, spread, var_target, have_target = stage
    xs0, xs1, xs2, qs0, qs1, qs2 = sums
    l0, l1 = lanes
    n = l1 - l0
    u0 = uint64(l0)
    count = uint64(n)
    m0 = xs0 / n
    m1 = xs1 / n
    m2 = xs2 / n
    # (d) shift toward the centre of mass of the targets
    d0 = d1 = d2 = 0.0
    if k_com > 0.0 and have_target:
        d0 = k_com * (qs0 / n - m0)
        d1 = k_com * (qs1 / n - m1)
        d2 = k_com * (qs2 / n - m2)
    # (e) scale about the shifted centre toward the target variance
    f = 1.0
    if spread > 0.0 and n > 1:
        f = spread_factor(group_variance(P, j, u0, count, (m0, m1, m2)), var_target, spread)
    # x -> c + f (x + d - c) with c = m + d, i.e. x -> m + d + f (x - m)
    for kk in range(count):
        i = u0 + kk
        P[j, 0, i] = m0 + d0 + f * (P[j, 0, i] - m0)
        P[j, 1, i] = m1 + d1 + f * (P[j, 1, i] - m1)
        P[j, 2, i] = m2 + d2 + f * (P[j, 2, i] - m2)


@njit(cache=True, inline='always', fastmath=TRACK_FASTMATH, error_model='numpy')
def _follow(P, T, j, lanes, strands, R):
    """(f) Follow-The-Leader: node ``j`` of the block's lanes (``P`` (N, 3, n) the new
    positions, ``lanes`` = ``(n, k0)``: the lanes and the group-order row of the first) put at
    its rest length from node ``j - 1`` (final), along the current direction; a node without a
    direction continues along its head-carried rest segment (``strands`` = ``(order, seg_len,
    rest)``: the ghost of each group-order row, the block's rest lengths (N-1, n), the rest
    shapes; ``R`` the head rotation)."""
    n, k0 = lanes
    order, seg_len, rest = strands
    n_bad = 0
    for kk in range(n):
        d0 = P[j, 0, kk] - P[j - 1, 0, kk]
        d1 = P[j, 1, kk] - P[j - 1, 1, kk]
        d2 = P[j, 2, kk] - P[j - 1, 2, kk]
        nd = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        ok = nd > 1e-300 and nd < 1e300
        sc = seg_len[j - 1, kk] / nd if ok else 0.0
        T[_FLAG, kk] = 0.0 if ok else 1.0
        n_bad += 0 if ok else 1
        P[j, 0, kk] = P[j - 1, 0, kk] + d0 * sc
        P[j, 1, kk] = P[j - 1, 1, kk] + d1 * sc
        P[j, 2, kk] = P[j - 1, 2, kk] + d2 * sc
    if n_bad == 0:
        return
    for kk in range(n):
        if T[_FLAG, kk] == 0.0:
            continue
        s = order[k0 + kk]
        r0 = rest[s, j, 0] - rest[s, j - 1, 0]
        r1 = rest[s, j, 1] - rest[s, j - 1, 1]
        r2 = rest[s, j, 2] - rest[s, j - 1, 2]
        P[j, 0, kk] = P[j - 1, 0, kk] + R[0, 0] * r0 + R[0, 1] * r1 + R[0, 2] * r2
        P[j, 1, kk] = P[j - 1, 1, kk] + R[1, 0] * r0 + R[1, 1] * r1 + R[1, 2] * r2
        P[j, 2, kk] = P[j - 1, 2, kk] + R[2, 0] * r0 + R[2, 1] * r1 + R[2, 2] * r2


@njit(cache=True, nogil=True)
def copy_blocks(x, v, order, block_rows, xb, vb, into_blocks, with_v):
    """Ghost state between the user's ``x``, ``v`` (S, N, 3) and the kernel's ``xb``, ``vb``
    (S * N * 3,) (block by block, [node][axis][ghost]; see :func:`group_blocks`): into the
    blocks if ``into_blocks``, else out of them; the velocities only ``with_v`` (positions
    for output need half the memory traffic).  ``block_rows`` (B+1,): the first group-order
    row of each block."""
    n_nodes = x.shape[1]
    for g in range(block_rows.shape[0] - 1):
        k0 = block_rows[g]
        n = block_rows[g + 1] - k0
        base = k0 * n_nodes * 3
        for kk in range(n):
            s = order[k0 + kk]
            for j in range(n_nodes):
                for a in range(3):
                    i = base + (j * 3 + a) * n + kk
                    if into_blocks:
                        xb[i] = x[s, j, a]
                        if with_v:
                            vb[i] = v[s, j, a]
                    else:
                        x[s, j, a] = xb[i]
                        if with_v:
                            v[s, j, a] = vb[i]


def group_blocks(a: np.ndarray, block_rows: np.ndarray) -> np.ndarray:
    """(S, ...) per-ghost data in group order -> the flat layout of ``rest_off`` and ``seg_len``
    in :func:`track_groups`: block by block (``block_rows`` (B+1,), the first row of each),
    inside a block the ghost index last (for (S, N, 3) data [node][axis][ghost])."""
    a = np.asarray(a, dtype=np.float64)
    per = a[0].size if a.shape[0] else 0
    out = np.empty(a.size)
    axes = tuple(range(1, a.ndim)) + (0,)
    for g in range(block_rows.size - 1):
        k0, k1 = int(block_rows[g]), int(block_rows[g + 1])
        out[k0 * per:k1 * per] = a[k0:k1].transpose(axes).reshape(-1)
    return out


def rest_tangents(rest: np.ndarray) -> np.ndarray:
    """Unit directions (S, N - 1, 3) of the segments of ``rest`` (S, N, 3), zero rows for
    degenerate segments (shorter than 1e-12 m): the ``tan_rest`` of
    :func:`segment_frame_into`."""
    tan = np.diff(np.asarray(rest, dtype=np.float64), axis=1)
    norm = np.linalg.norm(tan, axis=2, keepdims=True)
    return np.ascontiguousarray(np.where(norm > 1e-12, tan / np.where(norm > 1e-12, norm, 1.0),
                                         0.0))


def guide_frames(guide_x: np.ndarray, tan_rest: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(G, M-1, 3, 3) frame of every guide segment (see :func:`segment_frame_into`)."""
    out = np.empty((guide_x.shape[0], guide_x.shape[1] - 1, 3, 3))
    guide_frames_kernel(np.ascontiguousarray(guide_x, dtype=np.float64),
                        np.ascontiguousarray(tan_rest, dtype=np.float64),
                        np.ascontiguousarray(rotation, dtype=np.float64), out)
    return out
