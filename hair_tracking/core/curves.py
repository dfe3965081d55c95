"""Smooth output curves through strand nodes: cubic Bezier (equation (6)) and Catmull-Rom.

Both resample strands ``(S, N, 3)`` to ``(S, P, 3)`` points (any frame, metres in, metres out).
The ``P`` output points are spread evenly in *node-index* space: point ``p`` sits at
``u = p (N - 1) / (P - 1)``, i.e. ``u = 2.5`` is halfway between nodes 2 and 3 (halfway in the
curve parameter of that span).  With ``P - 1`` a multiple of ``N - 1`` some output points fall
exactly on nodes; the first and last output points are always the root and the tip.

**Bezier** (Park & Kim, equation (6) with the cubic Bernstein coefficient 3, not the printed 2)::

    pos(t) = (1-t)^3 P1 + 3 (1-t)^2 t P2 + 3 (1-t) t^2 P3 + t^3 P4

Consecutive groups of four nodes share their end node (nodes 0-3, 3-6, 6-9, ...), so the curve
is continuous and passes through nodes 0, 3, 6, ... and the tip; the nodes in between are control
points it does not pass through.  When ``N - 1`` is not a multiple of 3, the last group has fewer
nodes and is a Bezier curve of lower degree through the same end nodes: 2 nodes left -> a line
segment (degree 1), 3 nodes -> a quadratic.  A span of degree ``d`` covers ``d`` units of ``u``.

**Catmull-Rom** (centripetal, ``alpha = 0.5``; Yuksel, Schaefer & Keyser 2011, "Parameterization
and applications of Catmull-Rom curves"), evaluated with the Barry-Goldman pyramid.  It
interpolates every node.  End tangents: the missing neighbours beyond the root and the tip are
reflections, ``x[-1] = 2 x[0] - x[1]`` and ``x[N] = 2 x[N-1] - x[N-2]``, which makes the end
spans leave the end nodes along the end segments.  Coincident nodes are handled: a zero-length
span yields its node; a zero-length neighbouring span borrows the middle span's knot interval.
"""
from functools import lru_cache
import math

from numba import njit, prange
import numpy as np

CURVES = ('bezier', 'catmull_rom')


def resample(x: np.ndarray, points: int, kind: str) -> np.ndarray:
    """Strands ``x`` (S, N, 3) as ``points`` points each along a smooth curve of ``kind``
    ('bezier' or 'catmull_rom'); returns a new (S, points, 3) float64 array."""
    if kind == 'bezier':
        return bezier(x, points)
    if kind == 'catmull_rom':
        return catmull_rom(x, points)
    raise ValueError(f'output.curve: {kind!r} is not one of {", ".join(CURVES)}')


def bezier(x: np.ndarray, points: int) -> np.ndarray:
    """Piecewise Bezier curves of equation (6) through every third node, sampled at ``points``
    points per strand (see the module doc).  (S, N, 3) -> (S, points, 3)."""
    x, points = _check(x, points)
    idx, w = bezier_stencil(x.shape[1], points)
    out = np.empty((x.shape[0], points, 3))
    apply_stencil(x, idx, w, out)
    return out


def catmull_rom(x: np.ndarray, points: int) -> np.ndarray:
    """Centripetal Catmull-Rom curves through all nodes, ``points`` points per strand.
    (S, N, 3) -> (S, points, 3)."""
    x, points = _check(x, points)
    seg, s = _node_space(x.shape[1], points)
    out = np.empty((x.shape[0], points, 3))
    catmull_rom_kernel(x, seg, s, 0.5, out)
    return out


def _check(x, points):
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f'strands must be shaped (S, N, 3), got {x.shape}')
    if x.shape[1] < 2:
        raise ValueError(f'strands need at least 2 nodes for a curve, got {x.shape[1]}')
    if isinstance(points, bool) or int(points) != points or points < 2:
        raise ValueError(f'output.points_per_strand must be an integer >= 2, got {points!r}')
    return x, int(points)


@lru_cache(maxsize=64)
def _node_space(n: int, points: int):
    """Span index (P,) in [0, N-2] and local parameter (P,) in [0, 1] of every output point."""
    u = np.arange(points, dtype=np.float64) * (n - 1) / (points - 1)
    seg = np.minimum(np.floor(u).astype(np.int64), n - 2)
    s = u - seg
    s[-1] = 1.0
    seg.flags.writeable = False
    s.flags.writeable = False
    return seg, s


def bernstein(degree: int, i: int, t: float) -> float:
    """Weight of control point ``i`` of a Bezier curve of ``degree`` at parameter ``t``:
    ``C(degree, i) (1 - t)^(degree - i) t^i``; for degree 3 the four weights of equation (6),
    ``(1-t)^3, 3 (1-t)^2 t, 3 (1-t) t^2, t^3``."""
    return math.comb(degree, i) * (1.0 - t) ** (degree - i) * t ** i


@lru_cache(maxsize=64)
def bezier_stencil(n: int, points: int):
    """Node indices (P, 4) and weights (P, 4) of the Bezier output points (see module doc)."""
    spans = []                      # (first node, degree)
    first = 0
    while first < n - 1:
        deg = min(3, n - 1 - first)
        spans.append((first, deg))
        first += deg
    idx = np.zeros((points, 4), dtype=np.int64)
    w = np.zeros((points, 4))
    for p in range(points):
        u = p * (n - 1) / (points - 1)
        c = min(int(u // 3), len(spans) - 1)
        first, deg = spans[c]
        t = min(max((u - first) / deg, 0.0), 1.0)
        if p == points - 1:
            t = 1.0
        for i in range(deg + 1):
            idx[p, i] = first + i
            w[p, i] = bernstein(deg, i, t)
        for i in range(deg + 1, 4):
            idx[p, i] = first + deg
    idx.flags.writeable = False
    w.flags.writeable = False
    return idx, w


@njit(cache=True, nogil=True, parallel=True)
def apply_stencil(x, idx, w, out):
    """out[s, p] = sum_i w[p, i] x[s, idx[p, i]] for every strand (a fixed linear resampling)."""
    for s in prange(x.shape[0]):
        for p in range(idx.shape[0]):
            for a in range(3):
                out[s, p, a] = (w[p, 0] * x[s, idx[p, 0], a] + w[p, 1] * x[s, idx[p, 1], a] +
                                w[p, 2] * x[s, idx[p, 2], a] + w[p, 3] * x[s, idx[p, 3], a])


@njit(cache=True, nogil=True, parallel=True)
def catmull_rom_kernel(x, seg, loc, alpha, out):
    """Catmull-Rom points of every strand: output point p lies on span seg[p] (nodes seg[p] and
    seg[p] + 1, non-decreasing in p) at local parameter loc[p] in [0, 1], with knot intervals
    |dP|^alpha.  Each point is the Barry & Goldman (1988) pyramid of linear interpolations,
    multiplied out into weights of the four nodes; what depends only on the span (the nodes,
    the knot intervals and their reciprocals) is computed once per span."""
    n = x.shape[1]
    tiny = 1e-9
    for s in prange(x.shape[0]):
        span = -1
        p0x = p0y = p0z = p1x = p1y = p1z = p2x = p2y = p2z = p3x = p3y = p3z = 0.0
        d01 = d12 = r01 = r12 = r23 = r02 = r13 = 1.0
        for p in range(seg.shape[0]):
            i = seg[p]
            u = loc[p]
            if u == 0.0:
                for a in range(3):
                    out[s, p, a] = x[s, i, a]
                continue
            if u == 1.0:
                for a in range(3):
                    out[s, p, a] = x[s, i + 1, a]
                continue
            if i != span:
                span = i
                # the four points, with reflected neighbours beyond the ends
                if i > 0:
                    p0x, p0y, p0z = x[s, i - 1, 0], x[s, i - 1, 1], x[s, i - 1, 2]
                else:
                    p0x = 2.0 * x[s, 0, 0] - x[s, 1, 0]
                    p0y = 2.0 * x[s, 0, 1] - x[s, 1, 1]
                    p0z = 2.0 * x[s, 0, 2] - x[s, 1, 2]
                if i + 2 < n:
                    p3x, p3y, p3z = x[s, i + 2, 0], x[s, i + 2, 1], x[s, i + 2, 2]
                else:
                    p3x = 2.0 * x[s, n - 1, 0] - x[s, n - 2, 0]
                    p3y = 2.0 * x[s, n - 1, 1] - x[s, n - 2, 1]
                    p3z = 2.0 * x[s, n - 1, 2] - x[s, n - 2, 2]
                p1x, p1y, p1z = x[s, i, 0], x[s, i, 1], x[s, i, 2]
                p2x, p2y, p2z = x[s, i + 1, 0], x[s, i + 1, 1], x[s, i + 1, 2]
                d01 = (p1x - p0x) ** 2 + (p1y - p0y) ** 2 + (p1z - p0z) ** 2
                d12 = (p2x - p1x) ** 2 + (p2y - p1y) ** 2 + (p2z - p1z) ** 2
                d23 = (p3x - p2x) ** 2 + (p3y - p2y) ** 2 + (p3z - p2z) ** 2
                if alpha == 0.5:                 # |dP|^0.5 from |dP|^2, without pow
                    d01 = math.sqrt(math.sqrt(d01))
                    d12 = math.sqrt(math.sqrt(d12))
                    d23 = math.sqrt(math.sqrt(d23))
                else:
                    d01 = d01 ** (0.5 * alpha)
                    d12 = d12 ** (0.5 * alpha)
                    d23 = d23 ** (0.5 * alpha)
                if d12 > tiny:
                    if not (d01 > tiny):
                        d01 = d12
                    if not (d23 > tiny):
                        d23 = d12
                    r01 = 1.0 / d01
                    r12 = 1.0 / d12
                    r23 = 1.0 / d23
                    r02 = 1.0 / (d01 + d12)
                    r13 = 1.0 / (d12 + d23)
            if not (d12 > tiny):        # a collapsed span: its (single) point
                out[s, p, 0] = p1x + u * (p2x - p1x)
                out[s, p, 1] = p1y + u * (p2y - p1y)
                out[s, p, 2] = p1z + u * (p2z - p1z)
                continue
            # knots t0 = -d01, t1 = 0, t2 = d12, t3 = d12 + d23; t = u d12
            t = u * d12
            a1a = -t * r01                  # A1 = a1a P0 + a1b P1
            a1b = (t + d01) * r01
            c1 = (d12 - t) * r12            # A2 = c1 P1 + c2 P2, and C = c1 B1 + c2 B2
            c2 = t * r12
            a3a = (d12 + d23 - t) * r23     # A3 = a3a P2 + a3b P3
            a3b = (t - d12) * r23
            b1a = (d12 - t) * r02           # B1 = b1a A1 + b1b A2
            b1b = (t + d01) * r02
            b2a = (d12 + d23 - t) * r13     # B2 = b2a A2 + b2b A3
            b2b = t * r13
            on_a2 = c1 * b1b + c2 * b2a     # weight of A2 in C
            w0 = c1 * b1a * a1a
            w1 = c1 * b1a * a1b + on_a2 * c1
            w2 = on_a2 * c2 + c2 * b2b * a3a
            w3 = c2 * b2b * a3b
            out[s, p, 0] = w0 * p0x + w1 * p1x + w2 * p2x + w3 * p3x
            out[s, p, 1] = w0 * p0y + w1 * p1y + w2 * p2y + w3 * p3y
            out[s, p, 2] = w0 * p0z + w1 * p1z + w2 * p2z + w3 * p3z
