"""Strands of a file made simulation-ready: empty and degenerate strands skipped, a subset kept,
every strand resampled by arc length to a fixed node count.  All vectorised over the vertices
(no loop per strand or per vertex)."""
from typing import Tuple

import numpy as np

from hair_tracking.core.groom import scalp_order
from hair_tracking.grooms.polylines import Polylines

#: A strand shorter than this fraction of the longest is degenerate (a point, or vertices that
#: all coincide).
DEGENERATE_FRACTION = 1e-6


def segment_lengths(poly: Polylines) -> np.ndarray:
    """Length of each segment (P - 1,) between consecutive vertices of ``poly.points``, 0 where
    the two vertices belong to different strands."""
    d = np.diff(poly.points, axis=0)
    seg = np.sqrt(np.einsum('ij,ij->i', d, d))
    ends = np.cumsum(poly.counts)[:-1] - 1          # last vertex of every strand but the last
    seg[ends[(ends >= 0) & (ends < seg.shape[0])]] = 0.0
    return seg


def strand_lengths(poly: Polylines, seg=None) -> np.ndarray:
    """Arc length of each strand (S,), in the file's units (``seg``: its
    :func:`segment_lengths`, if known)."""
    seg = np.concatenate([segment_lengths(poly) if seg is None else seg, [0.0]])
    out = np.zeros(poly.count)
    has = poly.counts > 0
    out[has] = np.add.reduceat(seg, poly.starts[has])
    return out


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


def resample(poly: Polylines, nodes: int, seg=None) -> np.ndarray:
    """Every strand of ``poly`` (none empty) resampled to ``nodes`` points evenly spaced along
    its arc length, root and tip kept: (S, nodes, 3).  A strand of zero length gives ``nodes``
    copies of its root.  ``seg``: its :func:`segment_lengths`, if known.

    Each target arc length is found among the strand's cumulative vertex arc lengths by one
    sorted search over all strands at once (key: strand index + fraction of its length)."""
    s = poly.count
    starts, counts = poly.starts, poly.counts
    seg = np.concatenate([[0.0], segment_lengths(poly) if seg is None else seg])
    cum = np.cumsum(seg)
    cum -= np.repeat(cum[starts], counts)                 # arc length from the strand's root
    total = cum[starts + counts - 1]
    strand = np.repeat(np.arange(s), counts)
    frac = cum / np.maximum(np.repeat(total, counts), 1e-300)
    key = 2.0 * strand + frac
    u = np.arange(nodes) / (nodes - 1)
    target = (2.0 * np.arange(s)[:, None] + u[None, :]).ravel()
    i = np.searchsorted(key, target, side='right') - 1
    first = np.repeat(starts, nodes)
    last = np.repeat(starts + counts - 2, nodes)          # last segment's first vertex
    i = np.clip(i, first, last)
    want = (np.repeat(total, nodes) * np.tile(u, s))
    span = cum[i + 1] - cum[i]
    t = np.where(span > 0.0, (want - cum[i]) / np.where(span > 0.0, span, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)[:, None]
    p = poly.points
    out = p[i] + t * (p[i + 1] - p[i])
    return out.reshape(s, nodes, 3)
