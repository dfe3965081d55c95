"""The blend tracker: every ghost strand is its rest shape carried by a weighted blend of the
motions of a few nearby guides, evaluated once per output frame, without state of its own.

Guides are some of the strands themselves (:func:`choose_guides`), so a ratio of 1:1 is full
simulation: a strand that is a guide has weight 1 on itself and is reproduced exactly.  Per
frame, for ghost strand ``s`` and node ``j`` (rest position ``r`` in the head frame):

1. every guide node ``m`` gets an affine map ``A_m(r) = D_m r + c_m`` that carries the guide's
   rest point onto its current point and turns vectors with the guide there:
   ``D_m = Rot(R t_rest -> t_now) R`` (``R`` the head rotation, ``t`` the tangent of the segment
   that ends at ``m``, ``Rot`` the smallest rotation between two directions) and
   ``c_m = g_m - D_m g_rest_m`` (:func:`guide_affines`);
2. the ghost node is the weighted sum over its ``K`` guides of their maps at the node's
   arc-length fraction: ``x = sum_k w_k A_k,j(r)`` -- linear blend skinning with the guides as
   bones, the weights fixed at start (:func:`blend_weights`);
3. roots (nodes 0 and 1) are pinned at ``R r + p``; one Follow-The-Leader pass (Mueller, Kim &
   Chentanez 2012) puts every further node back at its rest distance from its predecessor; a
   node that would end inside the head collider (radii + margin) is placed at its rest distance
   along the direction with the inward part (along the collider's normal at the predecessor)
   removed, so it slides along the head, and is moved radially onto the surface if the
   curvature still leaves it inside.

Sources: linear blend skinning of interpolated hairs from guide hairs, with weights from the
distance between roots, is how Unreal Engine's groom interpolation and AMD TressFX's follow hairs
drive render strands from simulated guides (neither carries per-strand state; TressFX uses one
guide, Unreal up to three); the weights are Shepard's inverse-distance weights (D. Shepard, "A
two-dimensional interpolation function for irregularly-spaced data", ACM 1968).  Unlike the
paper's tracker (:mod:`hair_tracking.ghosts.tracker`) nothing is integrated, so nothing drifts
and nothing can gain energy: the ghost's motion is its guides' motion.

:func:`reference_blend` is the plain-numpy statement of steps 1-3; the tests hold the compiled
kernels (:func:`guide_affines`, :func:`blend_strands`) to it.
"""
import math
from typing import Dict, Optional, Tuple

import numpy as np
from numba import njit, prange

from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.point_records import points_to_records
from hair_tracking.guides.collision import outside_distance

#: Guides blended per ghost by default (Unreal's groom interpolation uses up to three).
DEFAULT_GUIDES_PER_GHOST = 3
#: Exponent of the inverse-distance weights.
WEIGHT_POWER = 2.0
#: Strands one thread blends together: their length passes run node by node across the block,
#: so the CPU overlaps the strands' dependency chains (each node is placed from its predecessor).
STRAND_BLOCK = 8
#: Work items of the blend's parallel loop (each a run of blocks with its own scratch row).
CHUNKS = 64


# ----------------------------------------------------------------------------- set-up
def choose_guides(roots: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` strands spread evenly over the scalp: farthest-point sampling of the
    root positions (S, 3), starting from the root nearest their centroid; deterministic.
    Sorted ascending."""
    roots = np.asarray(roots, dtype=np.float64)
    s = roots.shape[0]
    if not 1 <= count <= s:
        raise ValueError(f'guides: need 1..{s} guides among {s} strands, got {count}')
    if count == s:
        return np.arange(s)
    first = int(np.argmin(np.sum((roots - roots.mean(axis=0)) ** 2, axis=1)))
    chosen = [first]
    dist = np.sum((roots - roots[first]) ** 2, axis=1)
    for _ in range(count - 1):
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.sum((roots - roots[nxt]) ** 2, axis=1))
    return np.sort(np.asarray(chosen, dtype=np.int64))


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
    d2 = np.sum((roots[:, None, :] - guide_roots[None, :, :]) ** 2, axis=2)      # (S, G)
    near = np.argsort(d2, axis=1, kind='stable')[:, :k]
    dn = np.sqrt(np.take_along_axis(d2, near, axis=1))
    exact = dn[:, 0] <= 1e-12
    w = 1.0 / np.maximum(dn, 1e-12) ** power
    w[exact] = 0.0
    w[exact, 0] = 1.0
    w /= w.sum(axis=1, keepdims=True)
    return near.astype(np.int32), w.astype(np.float32)


def node_map(ghost_nodes: int, guide_nodes: int) -> Tuple[np.ndarray, np.ndarray]:
    """Guide segment and parameter of each ghost node index at its arc-length fraction
    ``j / (N - 1)`` (the groom spaces nodes evenly along each strand): ``(seg (N,) int64,
    t (N,) float64)``; equal node counts map node to node exactly."""
    f = np.arange(ghost_nodes) / max(1, ghost_nodes - 1) * (guide_nodes - 1)
    seg = np.minimum(np.floor(f).astype(np.int64), guide_nodes - 2)
    t = f - seg
    t[np.abs(t) < 1e-12] = 0.0
    return seg, t


# ----------------------------------------------------------------------------- kernels
@njit(cache=True, inline='always')
def _unit(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    if n > 0.0:
        return x / n, y / n, z / n
    return x, y, z


@njit(cache=True)
def _node_affine(gx, grest, g, m, rot, out):
    """``out[m]`` (12,) = the map of guide ``g``'s node ``m`` (row-major D, then c)."""
    a = m - 1 if m > 0 else 0
    b = a + 1
    # rest tangent, carried into the world by the head rotation
    rx = grest[g, b, 0] - grest[g, a, 0]
    ry = grest[g, b, 1] - grest[g, a, 1]
    rz = grest[g, b, 2] - grest[g, a, 2]
    ux, uy, uz = _unit(rot[0, 0] * rx + rot[0, 1] * ry + rot[0, 2] * rz,
                       rot[1, 0] * rx + rot[1, 1] * ry + rot[1, 2] * rz,
                       rot[2, 0] * rx + rot[2, 1] * ry + rot[2, 2] * rz)
    vx, vy, vz = _unit(gx[g, b, 0] - gx[g, a, 0], gx[g, b, 1] - gx[g, a, 1],
                       gx[g, b, 2] - gx[g, a, 2])
    # smallest rotation taking u onto v: I + [k]x + [k]x^2 / (1 + c), k = u x v, c = u . v
    kx, ky, kz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    c = ux * vx + uy * vy + uz * vz
    if c > -0.999999:
        f = 1.0 / (1.0 + c)
        q00, q01, q02 = 1.0 - (ky * ky + kz * kz) * f, -kz + kx * ky * f, ky + kx * kz * f
        q10, q11, q12 = kz + kx * ky * f, 1.0 - (kx * kx + kz * kz) * f, -kx + ky * kz * f
        q20, q21, q22 = -ky + kx * kz * f, kx + ky * kz * f, 1.0 - (kx * kx + ky * ky) * f
    else:                    # opposite directions: half a turn about an axis normal to u
        px, py, pz = (0.0, -uz, uy) if abs(ux) < 0.9 else (-uz, 0.0, ux)
        px, py, pz = _unit(px, py, pz)
        q00, q01, q02 = 2.0 * px * px - 1.0, 2.0 * px * py, 2.0 * px * pz
        q10, q11, q12 = 2.0 * py * px, 2.0 * py * py - 1.0, 2.0 * py * pz
        q20, q21, q22 = 2.0 * pz * px, 2.0 * pz * py, 2.0 * pz * pz - 1.0
    for j in range(3):
        out[m, j] = q00 * rot[0, j] + q01 * rot[1, j] + q02 * rot[2, j]
        out[m, 3 + j] = q10 * rot[0, j] + q11 * rot[1, j] + q12 * rot[2, j]
        out[m, 6 + j] = q20 * rot[0, j] + q21 * rot[1, j] + q22 * rot[2, j]
    for i in range(3):
        out[m, 9 + i] = gx[g, m, i] - (out[m, 3 * i] * grest[g, m, 0]
                                       + out[m, 3 * i + 1] * grest[g, m, 1]
                                       + out[m, 3 * i + 2] * grest[g, m, 2])


@njit(cache=True, parallel=True)
def guide_affines(gx, grest, rot, seg, t, out):
    """Kernel, step 1: ``out`` (G, 12, N) the map of every guide at every ghost node index
    (``seg``, ``t`` from :func:`node_map`: the maps of the two guide nodes around the node's
    fraction, interpolated linearly).  ``gx`` (G, M, 3) guides now, world [m]; ``grest``
    (G, M, 3) their rest shapes, head frame; ``rot`` the head rotation."""
    m_nodes = gx.shape[1]
    for g in prange(gx.shape[0]):
        node = np.empty((m_nodes, 12))
        for m in range(m_nodes):
            _node_affine(gx, grest, g, m, rot, node)
        for j in range(seg.shape[0]):
            a, u = seg[j], t[j]
            if u == 0.0:
                for i in range(12):
                    out[g, i, j] = node[a, i]
            else:
                for i in range(12):
                    out[g, i, j] = node[a, i] + u * (node[a + 1, i] - node[a, i])


@njit(cache=True, inline='always')
def _push_out(nx, ny, nz, cw, quad):
    """A world point inside the ellipsoid ``(x - cw)^T Q (x - cw) < 1`` (``cw`` its centre in
    the world, ``quad`` the 6 entries of ``Q = R diag(1 / axes^2) R^T``: Q00 Q11 Q22 Q01 Q02
    Q12) moved radially onto it; a point outside is returned as it is."""
    dx, dy, dz = nx - cw[0], ny - cw[1], nz - cw[2]
    e = _quad_form(dx, dy, dz, quad)
    if not 0.0 < e < 1.0:
        return nx, ny, nz
    f = 1.0 / math.sqrt(e)
    return cw[0] + f * dx, cw[1] + f * dy, cw[2] + f * dz


@njit(cache=True, inline='always')
def _quad_form(dx, dy, dz, quad):
    return quad[0] * dx * dx + quad[1] * dy * dy + quad[2] * dz * dz + \
        2.0 * (quad[3] * dx * dy + quad[4] * dx * dz + quad[5] * dy * dz)


@njit(cache=True, inline='always')
def _inside(nx, ny, nz, cw, quad):
    return _quad_form(nx - cw[0], ny - cw[1], nz - cw[2], quad) < 1.0


@njit(cache=True, inline='always')
def _slide(nx, ny, nz, px, py, pz, length, cw, quad):
    """The node at ``length`` from its predecessor ``p`` in the direction of ``n`` with the
    inward part (along the collider's normal at ``p``'s level) removed: it slides along the
    surface instead of into it."""
    ex, ey, ez = px - cw[0], py - cw[1], pz - cw[2]
    gx = quad[0] * ex + quad[3] * ey + quad[4] * ez           # outward normal Q (p - c)
    gy = quad[3] * ex + quad[1] * ey + quad[5] * ez
    gz = quad[4] * ex + quad[5] * ey + quad[2] * ez
    gx, gy, gz = _unit(gx, gy, gz)
    dx, dy, dz = nx - px, ny - py, nz - pz
    inward = dx * gx + dy * gy + dz * gz
    if inward < 0.0:
        dx, dy, dz = dx - inward * gx, dy - inward * gy, dz - inward * gz
    d = math.sqrt(dx * dx + dy * dy + dz * dz)
    if d <= 0.0:
        return nx, ny, nz
    f = length / d
    return px + f * dx, py + f * dy, pz + f * dz


@njit(cache=True, parallel=True)
def blend_strands(x, rest, roots, rest_length, guide, weight, affine, rot, pos, restore,
                  collide, center, axes, is_guide, gx):
    """Kernel, steps 2-3: ``x`` (S, N, 3) world [m] receives every strand; ``rest`` (S, 3, N)
    float32 head frame, component-major; ``roots`` (S, 2, 3) its first two nodes in float64
    (pinned exactly); ``rest_length`` (S, N-1) float32; ``guide`` (S, K) int32 and ``weight``
    (S, K) float32 from :func:`blend_weights`; ``affine`` (G, 12, N) from
    :func:`guide_affines`; ``restore``: the FTL length pass; ``collide``: push nodes out of the
    ellipsoid ``axes`` (radii + margin) around ``center`` (head frame).  A strand that is guide
    ``is_guide[s] >= 0`` is that guide's positions ``gx`` (G, N, 3), copied.  Returns the number
    of nodes pushed out."""
    n_strands, n_nodes = x.shape[0], x.shape[1]
    n_k = guide.shape[1]
    contacts = 0
    cw = np.empty(3)                                  # the collider's centre in the world
    for i in range(3):
        cw[i] = rot[i, 0] * center[0] + rot[i, 1] * center[1] + rot[i, 2] * center[2] + pos[i]
    inv = 1.0 / (axes * axes)
    quad = np.empty(6)
    for i, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        quad[i] = rot[a, 0] * rot[b, 0] * inv[0] + rot[a, 1] * rot[b, 1] * inv[1] + \
            rot[a, 2] * rot[b, 2] * inv[2]
    n_blocks = (n_strands + STRAND_BLOCK - 1) // STRAND_BLOCK
    n_chunks = min(n_blocks, CHUNKS)
    for c in prange(n_chunks):
        acc = np.empty((3, n_nodes))            # one strand's blended nodes, [axis][node]
        for b in range(c * n_blocks // n_chunks, (c + 1) * n_blocks // n_chunks):
            s0 = b * STRAND_BLOCK
            s1 = min(n_strands, s0 + STRAND_BLOCK)
            for s in range(s0, s1):          # the blend: every node on its own
                if is_guide[s] >= 0:
                    x[s] = gx[is_guide[s]]
                    continue
                acc[:, :] = 0.0
                r = rest[s]
                for k in range(n_k):
                    w = float(weight[s, k])
                    a = affine[guide[s, k]]
                    # contiguous in j; unsigned, so numba adds no negative-index wraparound
                    # and LLVM vectorises the loop
                    for j in range(np.uint64(2), np.uint64(n_nodes)):
                        r0, r1, r2 = r[0, j], r[1, j], r[2, j]
                        acc[0, j] += w * (a[0, j] * r0 + a[1, j] * r1 + a[2, j] * r2
                                          + a[9, j])
                        acc[1, j] += w * (a[3, j] * r0 + a[4, j] * r1 + a[5, j] * r2
                                          + a[10, j])
                        acc[2, j] += w * (a[6, j] * r0 + a[7, j] * r1 + a[8, j] * r2
                                          + a[11, j])
                for j in range(2):           # roots ride with the head
                    r0, r1, r2 = roots[s, j, 0], roots[s, j, 1], roots[s, j, 2]
                    x[s, j, 0] = rot[0, 0] * r0 + rot[0, 1] * r1 + rot[0, 2] * r2 + pos[0]
                    x[s, j, 1] = rot[1, 0] * r0 + rot[1, 1] * r1 + rot[1, 2] * r2 + pos[1]
                    x[s, j, 2] = rot[2, 0] * r0 + rot[2, 1] * r1 + rot[2, 2] * r2 + pos[2]
                for j in range(2, n_nodes):
                    x[s, j, 0] = acc[0, j]
                    x[s, j, 1] = acc[1, j]
                    x[s, j, 2] = acc[2, j]
            if not (restore or collide):
                continue
            # lengths and contacts: node by node across the block's strands, so that the
            # chains of the strands (each node placed from its predecessor) overlap in the CPU
            for j in range(2, n_nodes):
                for s in range(s0, s1):
                    if is_guide[s] >= 0:
                        continue
                    px, py, pz = x[s, j - 1, 0], x[s, j - 1, 1], x[s, j - 1, 2]
                    nx, ny, nz = x[s, j, 0], x[s, j, 1], x[s, j, 2]
                    length = float(rest_length[s, j - 1])
                    if restore:
                        dx, dy, dz = nx - px, ny - py, nz - pz
                        d = math.sqrt(dx * dx + dy * dy + dz * dz)
                        if d > 0.0:
                            f = length / d
                            nx, ny, nz = px + f * dx, py + f * dy, pz + f * dz
                    if collide and _inside(nx, ny, nz, cw, quad):
                        contacts += 1
                        if restore:
                            nx, ny, nz = _slide(nx, ny, nz, px, py, pz, length, cw, quad)
                        nx, ny, nz = _push_out(nx, ny, nz, cw, quad)
                    x[s, j, 0] = nx
                    x[s, j, 1] = ny
                    x[s, j, 2] = nz
    return contacts


# ----------------------------------------------------------------------------- reference
def _rotation_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    u = u / np.linalg.norm(u)
    v = v / np.linalg.norm(v)
    k = np.cross(u, v)
    c = float(u @ v)
    if c <= -0.999999:
        p = np.array([0.0, -u[2], u[1]]) if abs(u[0]) < 0.9 else np.array([-u[2], 0.0, u[0]])
        p /= np.linalg.norm(p)
        return 2.0 * np.outer(p, p) - np.eye(3)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + kx + kx @ kx / (1.0 + c)


def reference_blend(gx, grest, rest, rest_length, guide, weight, head: HeadPose,
                    restore: bool = True, collider_axes=None, center=(0.0, 0.0, 0.0),
                    is_guide=None, roots=None):
    """Plain-numpy statement of one blend step (steps 1-3 of the module docstring); returns the
    strands (S, N, 3), world frame; a strand that is guide ``is_guide[s] >= 0`` is that guide;
    ``roots`` (S, 2, 3) the first two rest nodes (default: ``rest``'s).
    Slow; for tests and for reading."""
    rot, pos = head.rotation, head.position
    g_count, m_nodes = gx.shape[:2]
    s_count, n_nodes = rest.shape[:2]
    seg, t = node_map(n_nodes, m_nodes)
    maps = np.empty((g_count, m_nodes, 3, 4))
    for g in range(g_count):
        for m in range(m_nodes):
            a = max(m - 1, 0)
            d = _rotation_between(rot @ (grest[g, a + 1] - grest[g, a]), gx[g, a + 1] - gx[g, a])
            d = d @ rot
            maps[g, m, :, :3] = d
            maps[g, m, :, 3] = gx[g, m] - d @ grest[g, m]
    at = maps[:, seg]
    nxt = maps[:, np.minimum(seg + 1, m_nodes - 1)]
    at = at + t[None, :, None, None] * (nxt - at)                       # (G, N, 3, 4)
    out = np.empty((s_count, n_nodes, 3))
    center = np.asarray(center, dtype=np.float64)
    roots = np.asarray(rest[:, :2] if roots is None else roots, dtype=np.float64)
    for s in range(s_count):
        if is_guide is not None and is_guide[s] >= 0:
            out[s] = gx[is_guide[s]]
            continue
        r = rest[s].astype(np.float64)
        for j in range(n_nodes):
            if j < 2:
                out[s, j] = rot @ roots[s, j] + pos
                continue
            p = np.zeros(3)
            for k in range(guide.shape[1]):
                a = at[guide[s, k], j]
                p += float(weight[s, k]) * (a[:, :3] @ r[j] + a[:, 3])
            if restore:
                d = p - out[s, j - 1]
                p = out[s, j - 1] + d * (float(rest_length[s, j - 1]) / np.linalg.norm(d))
            if collider_axes is not None:
                qm = rot @ np.diag(1.0 / np.asarray(collider_axes) ** 2) @ rot.T
                cw = rot @ center + pos
                if (p - cw) @ qm @ (p - cw) < 1.0:
                    prev = out[s, j - 1]
                    if restore:                    # slide along the surface, not into it
                        n = qm @ (prev - cw)
                        n /= np.linalg.norm(n)
                        d = p - prev
                        d = d - min(0.0, float(d @ n)) * n
                        p = prev + d * (float(rest_length[s, j - 1]) / np.linalg.norm(d))
                    e = float((p - cw) @ qm @ (p - cw))
                    if 0.0 < e < 1.0:              # still inside: radially onto the surface
                        p = cw + (p - cw) / np.sqrt(e)
            out[s, j] = p
    return out


# ----------------------------------------------------------------------------- tracker
class BlendTracker:
    """Moves ``ghosts`` after ``guides`` once per output frame (see the module docstring).

    ``guides`` must be some of the ghost strands: ``guide_index[i]`` is the ghost strand that
    guide ``i`` is (``ghosts.rest[guide_index] == guides.rest``).  ``k`` guides are blended per
    ghost; ``collider``, when given and ``scene.tracking.collide`` is true, is the head collider
    (a :class:`~hair_tracking.guides.collision.Collider`).  The ghost state is ``ghosts.x``
    (world frame); ghosts carry no velocity of their own (``ghosts.v`` stays zero).
    """

    def __init__(self, ghosts: StrandSet, guides: StrandSet, guide_index, scene, collider=None,
                 k: int = DEFAULT_GUIDES_PER_GHOST):
        self.ghosts = ghosts
        self.guides = guides
        self.guide_index = np.asarray(guide_index, dtype=np.int64)
        if self.guide_index.shape != (guides.count,) or \
                not np.allclose(ghosts.rest[self.guide_index], guides.rest):
            raise ValueError('BlendTracker: the guides must be some of the ghost strands '
                             '(guide_index names them)')
        tr = scene.tracking
        self.restore = bool(tr.length_restore)
        self.guide_of, self.weight = blend_weights(ghosts.rest[:, 0], guides.rest[:, 0], k)
        #: the guide each strand is, -1 for the others (those copy their guide)
        self.is_guide = np.full(ghosts.count, -1, dtype=np.int64)
        self.is_guide[self.guide_index] = np.arange(guides.count)
        self.seg, self.t = node_map(ghosts.rest.shape[1], guides.rest.shape[1])
        self._rest32 = np.ascontiguousarray(ghosts.rest.transpose(0, 2, 1), dtype=np.float32)
        self._roots = np.ascontiguousarray(ghosts.rest[:, :2], dtype=np.float64)
        self._len32 = np.ascontiguousarray(ghosts.rest_length, dtype=np.float32)
        self._affine = np.empty((guides.count, 12, ghosts.rest.shape[1]))
        self.collide = bool(tr.collide and collider is not None)
        if self.collide:
            # as the guide solver does: no more margin than the rest clearance of any free node
            # and half the shortest segment, so no ghost is pushed out of its own rest shape
            clearance = outside_distance(ghosts.rest[:, 2:] - collider.center, collider.radii)
            margin = min(collider.margin, float(clearance.min()),
                         0.5 * float(ghosts.rest_length.min()))
            self._axes = np.ascontiguousarray(collider.radii + max(0.0, margin),
                                              dtype=np.float64)
            self._center = np.ascontiguousarray(collider.center, dtype=np.float64)
        else:
            self._axes, self._center = np.ones(3), np.zeros(3)
        self.stats: Dict[str, int] = {'ghosts': int(ghosts.count), 'steps': 0, 'contacts': 0,
                                      'parallel': 1}

    def step(self, dt: float, guide_x_old: Optional[np.ndarray], head: HeadPose,
             substeps: int = 1) -> None:
        """Place every ghost from the guides now (``dt``, ``guide_x_old`` and ``substeps`` are
        accepted for the simulator's interface and not needed: the blend has no state)."""
        rot = np.ascontiguousarray(head.rotation, dtype=np.float64)
        pos = np.ascontiguousarray(head.position, dtype=np.float64)
        guide_affines(self.guides.x, self.guides.rest, rot, self.seg, self.t,
                      self._affine)
        x = self.ghosts.x
        self.stats['contacts'] = int(blend_strands(
            x, self._rest32, self._roots, self._len32, self.guide_of, self.weight, self._affine,
            rot, pos, self.restore, self.collide, self._center, self._axes, self.is_guide,
            self.guides.x))
        self.stats['steps'] += 1

    def reset(self, head: HeadPose) -> None:
        """Rest shape carried by ``head``."""
        self.ghosts.place_at(head)

    def positions(self) -> np.ndarray:
        """The ghost positions (S, N, 3), world frame [m] (the live array: read only)."""
        return self.ghosts.x

    def write_records(self, words, stride, rot=None, origin=None) -> bool:
        """float32 x y z of every ghost node into point records (as
        :func:`~hair_tracking.core.point_records.points_to_records`)."""
        return points_to_records(words, stride, self.ghosts.x, rot, origin)
