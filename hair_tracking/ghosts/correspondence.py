"""Ghost-to-guide correspondence: strand assignment (equation (1)) and node correspondence.

**Strand assignment.**  Each ghost (detail) strand ``d_j`` is assigned to the guide ``g_i`` that
minimises equation (1) of Park & Kim, taken from HairControl (Milliez et al. 2018)::

    d(d_j, g_i) = sum_k || d_{j,k} - prox(d_{j,k}, g_i) ||^2

with ``prox`` the *node* of ``g_i`` nearest to ghost node ``d_{j,k}``.  Everything is evaluated
on rest shapes in the head frame [m].  To scale to 10^5 ghosts x 10^4 guides only the
``candidates`` guides whose roots are nearest to the ghost's root are evaluated (exact k nearest
neighbours through a uniform grid); with ``candidates >= guides`` the result is the brute-force
minimum.  Ties are broken by the lower guide index, so the result is deterministic.

**Node correspondence.**  When ghost and guide have different node counts (or different segment
proportions), ghost node ``k`` corresponds to the point of its guide at the same *arc-length
fraction*: the guide segment ``seg`` and the interpolation weight ``t`` in [0, 1] such that the
point is ``(1 - t) g[seg] + t g[seg + 1]``.  With equal node counts and proportional segments this
is exactly node ``k`` (the paper's 1:1 correspondence).
"""
import math

from numba import njit, prange
import numpy as np


# ------------------------------------------------------------------ k nearest roots
def _check_points(name, p):
    p = np.ascontiguousarray(p, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f'{name} must be shaped (n, 3), got {p.shape}')
    if not np.all(np.isfinite(p)):
        raise ValueError(f'{name} contains NaN or infinite coordinates')
    return p


def build_grid(points: np.ndarray, per_cell: float):
    """Uniform grid over ``points`` (n, 3) for nearest-neighbour queries.

    The cell size is chosen so that a cell holds about ``per_cell`` points when the points lie on
    a surface (hair roots on a scalp).  Returns ``(origin, h, dims, cell_start, cell_items)``
    with the points of cell ``c`` being ``cell_items[cell_start[c]:cell_start[c + 1]]``.
    """
    n = points.shape[0]
    lo = points.min(axis=0)
    ext = points.max(axis=0) - lo
    cells_per_axis = int(min(512, max(1, math.ceil(math.sqrt(n / max(per_cell, 1.0))))))
    emax = float(ext.max())
    h = emax / cells_per_axis if emax > 0.0 else 1.0
    dims = np.minimum(np.floor(ext / h).astype(np.int64) + 1, cells_per_axis + 1)
    cell = _cell_of(points, lo, h, dims)
    counts = np.bincount(cell, minlength=int(np.prod(dims)))
    cell_start = np.zeros(counts.size + 1, dtype=np.int64)
    np.cumsum(counts, out=cell_start[1:])
    cell_items = np.argsort(cell, kind='stable').astype(np.int64)
    return lo, float(h), dims, cell_start, cell_items


def _cell_of(points, lo, h, dims):
    c = np.floor((points - lo) / h).astype(np.int64)
    c = np.clip(c, 0, dims - 1)
    return (c[:, 0] * dims[1] + c[:, 1]) * dims[2] + c[:, 2]


@njit(cache=True, inline='always')
def _insert(best_d, best_i, count, k, d, idx):
    """Insert (d, idx) into the sorted lists (lexicographic: distance, then index)."""
    if count == k:
        if d > best_d[k - 1] or (d == best_d[k - 1] and idx > best_i[k - 1]):
            return count
        pos = k - 1
    else:
        pos = count
        count += 1
    while pos > 0 and (best_d[pos - 1] > d or (best_d[pos - 1] == d and best_i[pos - 1] > idx)):
        best_d[pos] = best_d[pos - 1]
        best_i[pos] = best_i[pos - 1]
        pos -= 1
    best_d[pos] = d
    best_i[pos] = idx
    return count


@njit(cache=True, inline='always')
def _scan_cell(q, points, cell_start, cell_items, c, best_d, best_i, count, k):
    for m in range(cell_start[c], cell_start[c + 1]):
        i = cell_items[m]
        dx = points[i, 0] - q[0]
        dy = points[i, 1] - q[1]
        dz = points[i, 2] - q[2]
        count = _insert(best_d, best_i, count, k, dx * dx + dy * dy + dz * dz, i)
    return count


@njit(cache=True, nogil=True, parallel=True)
def knn_grid_kernel(queries, points, lo, h, dims, cell_start, cell_items, out_i, out_d):
    """For every query (Q, 3) the k = out_i.shape[1] nearest ``points`` (exact, by rings of
    grid cells; ties by lower index).  Writes indices to ``out_i`` and squared distances to
    ``out_d``, both sorted by (distance, index)."""
    k = out_i.shape[1]
    nx, ny, nz = dims[0], dims[1], dims[2]
    rmax = max(nx, max(ny, nz))
    for qi in prange(queries.shape[0]):
        q = queries[qi]
        best_d = out_d[qi]
        best_i = out_i[qi]
        count = 0
        cx = min(max(int(math.floor((q[0] - lo[0]) / h)), 0), nx - 1)
        cy = min(max(int(math.floor((q[1] - lo[1]) / h)), 0), ny - 1)
        cz = min(max(int(math.floor((q[2] - lo[2]) / h)), 0), nz - 1)
        for r in range(rmax + 1):
            # every point outside rings 0..r-1 is at least (r - 1) h away; after ring r, at
            # least r h: stop when k are known and the k-th is strictly closer than that
            for ix in range(max(cx - r, 0), min(cx + r, nx - 1) + 1):
                edge_x = ix == cx - r or ix == cx + r
                for iy in range(max(cy - r, 0), min(cy + r, ny - 1) + 1):
                    if edge_x or iy == cy - r or iy == cy + r:
                        for iz in range(max(cz - r, 0), min(cz + r, nz - 1) + 1):
                            c = (ix * ny + iy) * nz + iz
                            count = _scan_cell(q, points, cell_start, cell_items, c,
                                               best_d, best_i, count, k)
                    else:
                        if cz - r >= 0:
                            c = (ix * ny + iy) * nz + cz - r
                            count = _scan_cell(q, points, cell_start, cell_items, c,
                                               best_d, best_i, count, k)
                        if r > 0 and cz + r <= nz - 1:
                            c = (ix * ny + iy) * nz + cz + r
                            count = _scan_cell(q, points, cell_start, cell_items, c,
                                               best_d, best_i, count, k)
            if count == k:
                bound = r * h
                if best_d[k - 1] < bound * bound:
                    break


def nearest_roots(ghost_roots: np.ndarray, guide_roots: np.ndarray, k: int) -> np.ndarray:
    """(S, k') indices of the k' = min(k, G) guides whose roots are nearest to each ghost root,
    sorted by distance (ties: lower index first).  Roots in the head frame [m]."""
    ghost_roots = _check_points('ghost roots', ghost_roots)
    guide_roots = _check_points('guide roots', guide_roots)
    if guide_roots.shape[0] == 0:
        raise ValueError('there must be at least one guide strand')
    if int(k) < 1:
        raise ValueError(f'tracking.candidates must be >= 1, got {k!r}')
    k = min(int(k), guide_roots.shape[0])
    lo, h, dims, cell_start, cell_items = build_grid(guide_roots, per_cell=max(2.0, k / 2.0))
    out_i = np.empty((ghost_roots.shape[0], k), dtype=np.int64)
    out_d = np.empty((ghost_roots.shape[0], k))
    knn_grid_kernel(ghost_roots, guide_roots, lo, h, dims, cell_start, cell_items, out_i, out_d)
    return out_i


def near_other_strands(x: np.ndarray, radius: float) -> float:
    """The share of the nodes of strands ``x`` (S, N, 3) [m] that have a node of another strand
    within ``radius`` [m]: how much the strands run through one another (with no hair-hair
    interaction many lie in one shell).  Exact: a node's nearest neighbours
    (:func:`knn_grid_kernel`) are taken, twice as many each round, until one of another strand
    lies within ``radius`` or the farthest taken lies beyond it (a folded or curled strand
    may put many of its own nodes within ``radius``)."""
    x = np.asarray(x, dtype=np.float64)
    if not radius > 0.0:
        raise ValueError(f'radius must be > 0 m, got {radius!r}')
    points = _check_points('nodes', x.reshape(-1, 3))
    if x.shape[0] < 2 or x.shape[1] < 1:
        return 0.0
    per_strand = x.shape[1]
    strand = np.arange(points.shape[0]) // per_strand
    lo, h, dims, cell_start, cell_items = build_grid(points, per_cell=4.0)
    near = np.zeros(points.shape[0], dtype=bool)
    rows = np.arange(points.shape[0])
    k, r2 = 4, radius * radius
    while rows.size:
        k = min(k, points.shape[0])
        out_i = np.empty((rows.size, k), dtype=np.int64)
        out_d = np.empty((rows.size, k))
        knn_grid_kernel(points[rows], points, lo, h, dims, cell_start, cell_items, out_i, out_d)
        found = ((out_i // per_strand != strand[rows, None]) & (out_d <= r2)).any(axis=1)
        near[rows] = found
        rows = rows[~found & (out_d[:, -1] <= r2) & (k < points.shape[0])]
        k *= 2
    return float(near.mean())


# ------------------------------------------------------------------ equation (1)
@njit(cache=True, inline='always')
def correspondence_distance(ghost_rest, s, guide_rest, g, bound):
    """Equation (1): ``d(d_s, g_g) = sum_k || d_{s,k} - prox(d_{s,k}, g_g) ||^2`` [m^2] of ghost
    ``s`` of ``ghost_rest`` (S, N, 3) and guide ``g`` of ``guide_rest`` (G, M, 3), ``prox`` the
    guide's node nearest to the ghost node.  The sum stops as soon as it exceeds ``bound`` (a
    candidate that cannot win any more; ``np.inf``: the full sum)."""
    total = 0.0
    for j in range(ghost_rest.shape[1]):
        px = ghost_rest[s, j, 0]
        py = ghost_rest[s, j, 1]
        pz = ghost_rest[s, j, 2]
        dmin = np.inf
        for q in range(guide_rest.shape[1]):
            dx = px - guide_rest[g, q, 0]
            dy = py - guide_rest[g, q, 1]
            dz = pz - guide_rest[g, q, 2]
            d = dx * dx + dy * dy + dz * dz
            if d < dmin:
                dmin = d
        total += dmin
        if total > bound:        # cannot win any more (strictly worse)
            break
    return total


@njit(cache=True, nogil=True, parallel=True)
def equation1_kernel(ghost_rest, guide_rest, candidates, guide_of, cost):
    """Equation (1) over the candidate guides of every ghost: ``guide_of[s]`` the minimiser
    (ties: lower guide index), ``cost[s]`` its value [m^2]."""
    for s in prange(ghost_rest.shape[0]):
        best = np.inf
        best_g = -1
        for c in range(candidates.shape[1]):
            g = candidates[s, c]
            total = correspondence_distance(ghost_rest, s, guide_rest, g, best)
            if total < best or (total == best and g < best_g):
                best = total
                best_g = g
        guide_of[s] = best_g
        cost[s] = best


def assign_guides(ghost_rest: np.ndarray, guide_rest: np.ndarray, candidates: int):
    """Guide of every ghost by equation (1), pruned to the ``candidates`` nearest roots.

    ``ghost_rest`` (S, N, 3) and ``guide_rest`` (G, M, 3) are rest shapes in the head frame [m].
    Returns ``(guide_of (S,) int64, cost (S,) float64 [m^2])``.
    """
    ghost_rest = _check_strands('ghost rest shapes', ghost_rest)
    guide_rest = _check_strands('guide rest shapes', guide_rest)
    if guide_rest.shape[0] == 0:
        raise ValueError('there must be at least one guide strand')
    cand = nearest_roots(ghost_rest[:, 0], guide_rest[:, 0], candidates)
    guide_of = np.empty(ghost_rest.shape[0], dtype=np.int64)
    cost = np.empty(ghost_rest.shape[0])
    equation1_kernel(ghost_rest, guide_rest, cand, guide_of, cost)
    return guide_of, cost


def _check_strands(name, x):
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3 or x.shape[1] < 2:
        raise ValueError(f'{name} must be shaped (S, N, 3) with N >= 2, got {x.shape}')
    if not np.all(np.isfinite(x)):
        raise ValueError(f'{name} contain NaN or infinite coordinates')
    return x


# ------------------------------------------------------------------ node correspondence
def node_correspondence(ghost_rest_length: np.ndarray, guide_rest_length: np.ndarray,
                        guide_of: np.ndarray):
    """Guide segment and weight of every ghost node, by arc-length fraction.

    ``ghost_rest_length`` (S, N-1) and ``guide_rest_length`` (G, M-1) are rest segment lengths
    [m]; ``guide_of`` (S,) the guide of each ghost.  Returns ``seg`` (S, N) int64 in [0, M-2] and
    ``t`` (S, N) float64 in [0, 1]: ghost node ``k`` of ghost ``s`` corresponds to the guide point
    ``(1 - t) g[seg] + t g[seg + 1]`` whose arc-length fraction equals the node's.  Zero-length
    strands use evenly spaced fractions; zero-length guide segments are skipped.  Weights within
    1e-9 of 0 or 1 snap to the node, so equal node counts give exactly node-to-node
    correspondence.
    """
    # imported here: weights imports nothing from this module
    from hair_tracking.ghosts.weights import arc_fractions
    ghost_rest_length = np.asarray(ghost_rest_length, dtype=np.float64)
    guide_rest_length = np.asarray(guide_rest_length, dtype=np.float64)
    guide_of = np.asarray(guide_of)
    if guide_rest_length.ndim != 2 or guide_rest_length.shape[1] < 1:
        raise ValueError(f'guide rest lengths must be shaped (G, M-1) with M >= 2, got '
                         f'{guide_rest_length.shape}')
    if guide_of.shape != (ghost_rest_length.shape[0],):
        raise ValueError(f'guide_of must be shaped ({ghost_rest_length.shape[0]},), got '
                         f'{guide_of.shape}')
    if guide_of.size and (guide_of.min() < 0 or guide_of.max() >= guide_rest_length.shape[0]):
        raise ValueError('guide_of holds indices outside the guide set')
    f = arc_fractions(ghost_rest_length)                 # (S, N)
    gf = arc_fractions(guide_rest_length)[guide_of]      # (S, M)
    m1 = gf.shape[1] - 1                                 # number of guide segments
    # seg = last guide node whose fraction is <= f, limited to a valid segment
    seg = (gf[:, None, :] <= f[:, :, None]).sum(axis=2) - 1
    seg = np.clip(seg, 0, m1 - 1)
    rows = np.arange(f.shape[0])[:, None]
    f0 = gf[rows, seg]
    f1 = gf[rows, seg + 1]
    span = f1 - f0
    with np.errstate(divide='ignore', invalid='ignore'):
        t = np.where(span > 0.0, (f - f0) / np.where(span > 0.0, span, 1.0), 1.0)
    t = np.clip(t, 0.0, 1.0)
    t[t < 1e-9] = 0.0
    up = (t > 1.0 - 1e-9) & (seg < m1 - 1)
    seg[up] += 1
    t[up] = 0.0
    t[t > 1.0 - 1e-9] = 1.0
    return np.ascontiguousarray(seg.astype(np.int64)), np.ascontiguousarray(t)
