"""Array kernels of the contact model: strands ``(S, N, 3)`` against a posed table (every shape
of a scene), built from the one-node functions of :mod:`hair_tracking.colliders.contact`.

:func:`collide_block` is the collision stage of a position-based substep for a block of
strands (a guide solver runs it block by block inside its own parallel loop); :func:`collide`
runs it over all strands; :func:`deepest` measures how deep the hair lies inside the shapes;
:func:`slide_push_strands` is the contact of the trackers without state (blend, turn) with
every shape, strand by strand.
Shapes are taken in table order: a node pushed out of one shape into another is pushed out of
that one next (one Gauss-Seidel pass, as a solver takes its constraints).
"""
import math

from numba import njit, prange
import numpy as np

from hair_tracking.colliders.bounds import box_near, boxes_meet, near, shape_box, strand_box
from hair_tracking.colliders.contact import (bounded_start, carried, depth, FASTMATH, push_out,
                                             surface_normal)
from hair_tracking.colliders.crease import escape, outside_all
from hair_tracking.colliders.shapes import FRICTION, KIND, PLANE
from hair_tracking.colliders.slide import level, slide_push

#: A node :func:`collide_block` pushed out of one shape (or :func:`slide_push_strands` slid out
#: of it) may stay this far [m] inside another (farther, it goes to the closest point outside
#: both, :mod:`~hair_tracking.colliders.crease`).
CREASE_TOLERANCE = 1e-7
#: Sweeps over the shapes a node of :func:`slide_push_strands` takes at most.
STRAND_SWEEPS = 16
#: Moves of a node :func:`slide_push_strands`'s sweeps leave inside a shape to the closest point
#: outside every shape and back to its rest length, at most.
STRAND_ESCAPES = 8
#: Strands whose nodes share the first bound test of :func:`slide_push_strands`.
STRAND_BLOCK = 64
#: Work items of :func:`slide_push_strands`'s parallel loop (each a run of blocks with its own
#: scratch).
CHUNKS = 64


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def collide_block(x, start, inv_mass, sh, cap, x_old, s0, s1):
    """The strands ``s0 <= s < s1`` of ``x`` (S, N, 3) world [m], in place: every node with
    ``inv_mass > 0`` near a shape of ``sh`` (:func:`~hair_tracking.colliders.bounds.near`) is
    pushed out of it with its friction relative to ``carried(start)`` (``start`` (S, N, 3) the
    nodes' positions at the start of the substep); with ``cap >= 0`` [m] the push-out velocity
    bound moves the node's entry of ``x_old`` (S, N, 3), the positions its velocity is measured
    from (:func:`~hair_tracking.colliders.contact.bounded_start`; ``x_old`` may be ``start``).
    Returns the number of nodes moved."""
    n = x.shape[1]
    moved_nodes = 0
    for s in range(s0, s1):
        for i in range(n):
            if inv_mass[s, i] <= 0.0:
                continue
            x0, x1, x2 = x[s, i, 0], x[s, i, 1], x[s, i, 2]
            t0, t1, t2 = start[s, i, 0], start[s, i, 1], start[s, i, 2]
            o0, o1, o2 = x_old[s, i, 0], x_old[s, i, 1], x_old[s, i, 2]
            hit = False
            for k in range(sh.shape[0]):
                if not near(x0, x1, x2, sh, k):
                    continue
                r0, r1, r2 = t0, t1, t2
                if sh[k, FRICTION] > 0.0 or cap >= 0.0:
                    r0, r1, r2 = carried(t0, t1, t2, sh, k)
                moved, y0, y1, y2 = push_out(x0, x1, x2, r0, r1, r2, sh, k)
                if not moved:
                    continue
                if cap >= 0.0:
                    n0, n1, n2 = surface_normal(y0, y1, y2, sh, k)
                    o0, o1, o2 = bounded_start(o0, o1, o2, y0, y1, y2, r0, r1, r2, n0, n1, n2,
                                               cap)
                x0, x1, x2 = y0, y1, y2
                hit = True
            if hit and not outside_all(x0, x1, x2, sh, CREASE_TOLERANCE):
                # pushed from one shape into another: the closest point outside both
                _, y0, y1, y2 = escape(x0, x1, x2, sh, CREASE_TOLERANCE)
                if cap >= 0.0:
                    e0, e1, e2 = y0 - x0, y1 - x1, y2 - x2
                    e = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                    if e > 0.0:
                        o0, o1, o2 = bounded_start(o0, o1, o2, y0, y1, y2, x0, x1, x2, e0 / e,
                                                   e1 / e, e2 / e, cap)
                x0, x1, x2 = y0, y1, y2
            if hit:
                x[s, i, 0], x[s, i, 1], x[s, i, 2] = x0, x1, x2
                if cap >= 0.0:
                    x_old[s, i, 0], x_old[s, i, 1], x_old[s, i, 2] = o0, o1, o2
                moved_nodes += 1
    return moved_nodes


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def collide(x, start, inv_mass, sh, cap, x_old):
    """:func:`collide_block` over all strands; returns the number of nodes moved."""
    return collide_block(x, start, inv_mass, sh, cap, x_old, 0, x.shape[0])


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def deepest(x, inv_mass, use_mass, sh, out):
    """``out[s]`` = the deepest [m] a node of strand ``s`` of ``x`` (S, N, 3) lies inside a
    shape of ``sh`` (pose it without margins to measure the bare shapes); only nodes with
    ``inv_mass > 0`` when ``use_mass``; 0 where none is inside."""
    for s in range(x.shape[0]):
        worst = 0.0
        for i in range(x.shape[1]):
            if use_mass and inv_mass[s, i] <= 0.0:
                continue
            for k in range(sh.shape[0]):
                if near(x[s, i, 0], x[s, i, 1], x[s, i, 2], sh, k):
                    d = depth(x[s, i, 0], x[s, i, 1], x[s, i, 2], sh, k)
                    if d > worst:
                        worst = d
        out[s] = worst


@njit(cache=True, nogil=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def slide_push_strands(x, rest_length, sh, first, lead):
    """The stateless trackers' contact (:func:`~hair_tracking.colliders.slide.slide_push`) of
    the strands ``x`` (S, N, 3) (float32 or float64, world [m], in place) with every shape of
    ``sh``, node by node from node ``first`` on: a node is first moved by its predecessor's
    displacement (the strand below a moved node follows it, its shape kept); then every shape
    that it is near (:func:`~hair_tracking.colliders.bounds.near`) and inside slides it at its
    rest segment's length ``rest_length[s, j - 1]`` from its predecessor and pushes it onto the
    surface, after which it is put back at the rest length along its new segment, in sweeps
    (:data:`STRAND_SWEEPS` at most) until one finds it inside no shape (a node slid out of
    one shape into an overlapping one slides out of that one next).  A node the sweeps leave
    inside a shape (in the crease where two overlapping shapes meet, whose sweeps shrink its
    depth slowly) goes to the closest point outside every shape
    (:func:`~hair_tracking.colliders.crease.escape`) and back to its rest length from its
    predecessor, up to :data:`STRAND_ESCAPES` times, so lengths stay exact.  The first ``lead``
    shapes (the head collider, which the tracker or solver has applied already) are tested
    only on nodes this pass moves.

    The bound tests go from the coarse to the fine, so that hair far from every shape costs
    one read of its nodes: the strands go in blocks of :data:`STRAND_BLOCK`; the box of a
    block's nodes from ``first`` on against each shape's box
    (:func:`~hair_tracking.colliders.bounds.shape_box`), then each strand's box
    (:func:`~hair_tracking.colliders.bounds.strand_box`) against the shapes its block's box
    meets; a strand whose box meets no shape after the ``lead`` ones is left as it is (none of
    its nodes can be moved, so none is carried).  In the others the pass starts at the first
    node inside a shape its box meets (a node tested exactly only inside the shape's box) and
    a node's tests run over those shapes until one moves it (then over all of them, as it may
    have left the box).  Each box contains every node it stands for, so the result is the
    same as each node testing every shape.  A node that is not finite is left as it is and
    carries nothing to the nodes after it.  Returns the number of nodes a shape moved."""
    boxes = np.empty((sh.shape[0], 6))
    for k in range(sh.shape[0]):
        boxes[k, 0], boxes[k, 1], boxes[k, 2], boxes[k, 3], boxes[k, 4], boxes[k, 5] = \
            shape_box(sh, k)
    blocks = (x.shape[0] + STRAND_BLOCK - 1) // STRAND_BLOCK
    chunks = min(blocks, CHUNKS)
    total = 0
    for c in prange(chunks):
        total += _slide_push_blocks(x, rest_length, (sh, boxes), (first, lead),
                                    (c * blocks // chunks, (c + 1) * blocks // chunks))
    return total


@njit(cache=True, fastmath=FASTMATH, error_model='numpy')
def _slide_push_blocks(x, rest_length, shapes, how, blocks):
    """:func:`slide_push_strands` of the blocks ``b0 <= b < b1`` (``shapes`` = ``(sh,
    boxes)``, ``boxes`` (K, 6) each shape's :func:`~hair_tracking.colliders.bounds.shape_box`;
    ``how`` = ``(first, lead)``, ``blocks`` = ``(b0, b1)``)."""
    first, lead = how
    sh, boxes = shapes
    count = sh.shape[0]
    box = np.empty((STRAND_BLOCK, 6))                   # each strand's box
    in_block = np.zeros(count, dtype=np.bool_)          # the shapes a block's box meets
    listed = np.zeros(count, dtype=np.bool_)            # the shapes a strand's box meets
    moved = 0
    b0, b1 = blocks
    for b in range(b0, b1):
        s0 = b * STRAND_BLOCK
        s1 = min(s0 + STRAND_BLOCK, x.shape[0])
        lo0 = lo1 = lo2 = math.inf
        hi0 = hi1 = hi2 = -math.inf
        for s in range(s0, s1):
            i = s - s0
            box[i, 0], box[i, 1], box[i, 2], box[i, 3], box[i, 4], box[i, 5] = \
                strand_box(x, s, first)
            lo0, lo1, lo2 = min(lo0, box[i, 0]), min(lo1, box[i, 1]), min(lo2, box[i, 2])
            hi0, hi1, hi2 = max(hi0, box[i, 3]), max(hi1, box[i, 4]), max(hi2, box[i, 5])
        any_shape = False
        for k in range(lead, count):
            in_block[k] = _box_meets(lo0, lo1, lo2, hi0, hi1, hi2, sh, boxes, k)
            any_shape |= in_block[k]
        if not any_shape:
            continue
        for s in range(s0, s1):
            i = s - s0
            near_any = False
            for k in range(lead, count):
                listed[k] = in_block[k] and _box_meets(box[i, 0], box[i, 1], box[i, 2],
                                                       box[i, 3], box[i, 4], box[i, 5], sh,
                                                       boxes, k)
                near_any |= listed[k]
            if not near_any:
                continue
            j0 = _first_inside(x, sh, boxes, (first, s), listed)
            if j0 < x.shape[1]:
                moved += _slide_push_strand(x, rest_length, sh, (j0, lead), s, listed)
    return moved


@njit(cache=True, inline='always')
def _box_meets(lo0, lo1, lo2, hi0, hi1, hi2, sh, boxes, k):
    """Whether the box ``lo .. hi`` may touch shape ``k``: it meets the shape's box
    (:func:`~hair_tracking.colliders.bounds.boxes_meet`; a plane:
    :func:`~hair_tracking.colliders.bounds.box_near`)."""
    if sh[k, KIND] == PLANE:
        return box_near(lo0, lo1, lo2, hi0, hi1, hi2, sh, k)
    return boxes_meet(lo0, lo1, lo2, hi0, hi1, hi2, boxes, k)


@njit(cache=True, inline='always')
def _first_inside(x, sh, boxes, where, listed):
    """The first node ``first ..`` of strand ``s`` (``where`` = ``(first, s)``) inside a
    shape ``listed`` (N for none): the nodes before it are in no shape that may move them, so
    the strand's pass starts there.  A node's exact test runs only inside the shape's box."""
    first, s = where
    j0 = x.shape[1]
    for k in range(sh.shape[0]):
        if not listed[k]:
            continue
        for j in range(first, j0):
            x0, x1, x2 = float(x[s, j, 0]), float(x[s, j, 1]), float(x[s, j, 2])
            if _box_meets(x0, x1, x2, x0, x1, x2, sh, boxes, k) and \
                    near(x0, x1, x2, sh, k) and level(x0, x1, x2, sh, k) < 0.0:
                j0 = j
                break
    return j0


@njit(cache=True, inline='always')
def _slide_push_strand(x, rest_length, sh, how, s, listed):
    """:func:`slide_push_strands` of strand ``s``, a node's tests over the shapes ``listed``
    until a shape moves it; returns the number of nodes a shape moved."""
    first, lead = how
    moved = 0
    d0 = d1 = d2 = 0.0                       # the displacement carried to the next node
    for j in range(first, x.shape[1]):
        o0, o1, o2 = float(x[s, j, 0]), float(x[s, j, 1]), float(x[s, j, 2])
        x0, x1, x2 = o0 + d0, o1 + d1, o2 + d2
        carried = d0 != 0.0 or d1 != 0.0 or d2 != 0.0
        p0, p1, p2 = float(x[s, j - 1, 0]), float(x[s, j - 1, 1]), float(x[s, j - 1, 2])
        length = rest_length[s, j - 1]
        hit = False
        for _ in range(STRAND_SWEEPS):
            again = False
            for k in range(sh.shape[0]):
                if k < lead and not (hit or carried):
                    continue
                if not (hit or carried or listed[k]):
                    continue              # the strand's box, which holds x, misses its bound
                if not near(x0, x1, x2, sh, k) or not level(x0, x1, x2, sh, k) < 0.0:
                    continue
                x0, x1, x2 = slide_push(x0, x1, x2, p0, p1, p2, length, True, sh, k)
                again = hit = True
            if not again:
                break
            x0, x1, x2 = _at_length(x0, x1, x2, p0, p1, p2, length)
        for _ in range(STRAND_ESCAPES):
            if not hit or outside_all(x0, x1, x2, sh, CREASE_TOLERANCE):
                break
            # slid from one shape into another and back: the closest point outside all
            x0, x1, x2 = escape(x0, x1, x2, sh, CREASE_TOLERANCE)[1:]
            x0, x1, x2 = _at_length(x0, x1, x2, p0, p1, p2, length)
        if hit:
            moved += 1
        d0 = d1 = d2 = 0.0
        if (hit or carried) and math.isfinite(x0 + x1 + x2 - o0 - o1 - o2):
            d0, d1, d2 = x0 - o0, x1 - o1, x2 - o2
        if d0 != 0.0 or d1 != 0.0 or d2 != 0.0:
            x[s, j, 0], x[s, j, 1], x[s, j, 2] = x0, x1, x2
    return moved


@njit(cache=True, inline='always')
def _at_length(x0, x1, x2, p0, p1, p2, length):
    """``x`` moved along ``x - p`` to ``length`` from ``p`` (as it is when ``x = p``)."""
    e0, e1, e2 = x0 - p0, x1 - p1, x2 - p2
    n = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if not n > 0.0:
        return x0, x1, x2
    f = length / n
    return p0 + f * e0, p1 + f * e1, p2 + f * e2
