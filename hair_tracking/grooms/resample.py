"""Strands of a file made simulation-ready: empty and degenerate strands skipped, a subset kept,
every strand resampled by arc length to a fixed node count (one compiled pass over the
vertices)."""
import math
from typing import Tuple

from numba import njit
import numpy as np

from hair_tracking.core.groom import scalp_order
from hair_tracking.grooms.polylines import Polylines

#: A strand shorter than this fraction of the longest is degenerate (a point, or vertices that
#: all coincide).
DEGENERATE_FRACTION = 1e-6


def strand_lengths(poly: Polylines) -> np.ndarray:
    """Arc length of each strand (S,), in the file's units."""
    out = np.empty(poly.count)
    _lengths_kernel(np.ascontiguousarray(poly.points), np.ascontiguousarray(poly.starts),
                    np.ascontiguousarray(poly.counts), out)
    return out


@njit(cache=True)
def _lengths_kernel(p, starts, counts, out):
    for s in range(starts.shape[0]):
        total = 0.0
        for i in range(starts[s], starts[s] + counts[s] - 1):
            total += _length(p, i)
        out[s] = total


def usable(poly: Polylines) -> Tuple[np.ndarray, np.ndarray, int, int]:
    """``(indices of the usable strands, every strand's length, empty, degenerate)``: a strand
    with fewer than two vertices is empty (a ``.data`` file's one-vertex strands are empty
    roots); one shorter than :data:`DEGENERATE_FRACTION` of the longest is degenerate."""
    lengths = strand_lengths(poly)
    empty = poly.counts < 2
    tiny = ~empty & (lengths <= DEGENERATE_FRACTION * max(float(lengths.max(initial=0.0)),
                                                          1e-300))
    keep = np.flatnonzero(~empty & ~tiny)
    return keep, lengths, int(empty.sum()), int(tiny.sum())


def spread_subset(roots: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` of the strands with roots ``roots`` (S, 3), evenly spread over the
    scalp and deterministic: every (S / count)-th strand along a Morton curve through the
    roots (:func:`~hair_tracking.core.groom.scalp_order`); sorted ascending.  All of them when
    ``count`` is 0 or at least S."""
    s = roots.shape[0]
    if count <= 0 or count >= s:
        return np.arange(s)
    order = scalp_order(roots)
    pick = np.floor((np.arange(count) + 0.5) * (s / count)).astype(np.int64)
    return np.sort(order[pick])


def resample(poly: Polylines, nodes: int) -> np.ndarray:
    """Every strand of ``poly`` (none empty) resampled to ``nodes`` points evenly spaced along
    its arc length, root and tip kept: (S, nodes, 3) float64.  A strand of zero length gives
    ``nodes`` copies of its root."""
    out = np.empty((poly.count, nodes, 3))
    _resample_kernel(np.ascontiguousarray(poly.points, dtype=np.float64),
                     np.ascontiguousarray(poly.starts, dtype=np.int64),
                     np.ascontiguousarray(poly.counts, dtype=np.int64), out)
    return out


@njit(cache=True)
def _resample_kernel(p, starts, counts, out):
    """:func:`resample` of the strands ``starts``, ``counts`` of ``p`` (P, 3) into ``out``
    (S, nodes, 3): each strand's arc length, then one walk along its segments, point ``j`` at
    ``j / (nodes - 1)`` of it (on the first segment that reaches that far; ties go to the
    later segment)."""
    nodes = out.shape[1]
    for s in range(starts.shape[0]):
        a, last = starts[s], starts[s] + counts[s] - 2          # the last segment's start
        total = 0.0
        for i in range(a, last + 1):
            total += _length(p, i)
        i, done, span = a, 0.0, _length(p, a)
        for j in range(nodes):
            want = total * (j / (nodes - 1))
            while i < last and done + span <= want:
                done += span
                i += 1
                span = _length(p, i)
            t = min(max((want - done) / span, 0.0), 1.0) if span > 0.0 else 0.0
            for k in range(3):
                out[s, j, k] = p[i, k] + t * (p[i + 1, k] - p[i, k])


@njit(cache=True, inline='always')
def _length(p, i):
    """Length of the segment from vertex ``i`` to ``i + 1`` of ``p`` (float64 whatever
    ``p``'s type)."""
    dx = float(p[i + 1, 0]) - float(p[i, 0])
    dy = float(p[i + 1, 1]) - float(p[i, 1])
    dz = float(p[i + 1, 2]) - float(p[i, 2])
    return math.sqrt(dx * dx + dy * dy + dz * dz)
