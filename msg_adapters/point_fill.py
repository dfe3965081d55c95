"""One pass that writes strands into the point records of a PointCloud2's data.

numpy needs a strided float64 -> float32 copy per field plus a separate finiteness scan; this
loop reads each coordinate once and writes each record once (``scripts/bench_msgs.py`` times
both).  Compiled with numba (``cache=True``: loaded from disk after the first run).
"""
import sys

import numpy as np
from numba import njit

#: The largest finite float64: ``abs(v) <= _MAX`` is false exactly for NaN and +-Inf.
_MAX = sys.float_info.max


@njit(cache=True, inline='always')
def _put_point(words, o, x, p, sid):
    """x y z and the strand id of point ``p`` into the record at word ``o``; True if a
    coordinate is not finite."""
    a = x[3 * p]
    b = x[3 * p + 1]
    c = x[3 * p + 2]
    words[o] = a
    words[o + 1] = b
    words[o + 2] = c
    words[o + 3] = sid
    return not (abs(a) <= _MAX and abs(b) <= _MAX and abs(c) <= _MAX)


@njit(cache=True, nogil=True)
def _fill_records(words, x, rgb, ids, n_points, per_point_rgb):
    """``words`` (S * N * 4|5,) float32, records of 4 words (x y z strand) without colours and
    of 5 (... rgb) with; ``x`` (S * N * 3,) float64; ``rgb`` (S,) or with ``per_point_rgb``
    (S * N,) float32 packed colours (or empty: none); ``ids`` (S,) the uint32 strand ids
    *viewed as float32*.  Returns True when every coordinate is finite.

    Ids and colours are bit patterns: they are copied as float32 words, which moves their bits
    unchanged (no arithmetic touches them).  One float32 output array, a finiteness test
    without a floating-point dependency chain, flat arrays and a constant record size (numba
    reads the strides of a reshaped view at run time) keep the loop memory-bound."""
    bad = 0
    with_rgb = rgb.shape[0] > 0
    for s in range(ids.shape[0]):
        sid = ids[s]
        p0 = s * n_points
        # one loop per layout with the record size a constant: a branch, or the size as a
        # variable, inside the point loop halved its speed
        if not with_rgb:
            for j in range(n_points):
                bad += _put_point(words, (p0 + j) * 4, x, p0 + j, sid)
        elif per_point_rgb:
            for j in range(n_points):
                p = p0 + j
                bad += _put_point(words, p * 5, x, p, sid)
                words[p * 5 + 4] = rgb[p]
        else:
            col = rgb[s]
            for j in range(n_points):
                p = p0 + j
                bad += _put_point(words, p * 5, x, p, sid)
                words[p * 5 + 4] = col
    return bad == 0


def fill_records(words, x, rgb, ids):
    """Write points into ``words``, the (S, N, 4|5) little-endian float32 view of a cloud's
    data; ``x`` (S, N, 3) float64 C-contiguous, ``rgb`` (S, 1|N) packed float32 or None,
    ``ids`` (S,) uint32.  Returns ``is_dense`` (every coordinate finite).  Falls back to numpy
    for memory numba cannot take as float32 (not 4-byte aligned, or big-endian) and for
    records wider than the cloud's own."""
    n_strands, n_points = words.shape[:2]
    if rgb is not None and rgb.shape != (n_strands, 1) and rgb.shape != (n_strands, n_points):
        raise ValueError(f'rgb must be shaped ({n_strands}, 1 or {n_points}), got {rgb.shape}')
    stride = words.shape[2]
    if rgb is not None and stride != 5:
        raise ValueError(f'records with rgb are 5 words (x y z strand rgb), got {stride}')
    if not (words.flags.aligned and words.flags.c_contiguous and
            words.dtype == np.dtype('<f4') and x.dtype == np.dtype('<f8') and
            x.flags.c_contiguous) or (rgb is None and stride != 4):
        return _fill_numpy(words, x, rgb, ids)      # any alignment, any record size
    if rgb is None:
        rgb = np.empty(0, dtype=np.float32)
        per_point = False
    else:
        per_point = rgb.shape[1] == n_points and n_points > 1
        rgb = np.ascontiguousarray(rgb if per_point else rgb[:, :1], dtype=np.float32)
    ids = np.ascontiguousarray(ids, dtype='<u4').view('<f4')
    return bool(_fill_records(words.reshape(-1), _read_only(x), _read_only(rgb),
                              _read_only(ids), n_points, per_point))


def _read_only(a):
    """A flat read-only view of ``a``: numba compiles one specialisation per argument type and
    read-only is part of the type, so the inputs always go in read-only (the node's frames are
    read-only views, its cached colours too, warm-up data is not: a second specialisation
    compiled in the middle of the first published frame, 1.5 s with an empty cache)."""
    v = a.reshape(-1)
    v.flags.writeable = False
    return v


def _fill_numpy(words, x, rgb, ids):
    """:func:`fill_records` with numpy only (any alignment)."""
    words[..., :3] = x
    words[..., 3:4].view('<u4')[..., 0] = ids[:, None]
    if rgb is not None:
        words[..., 4] = rgb
    return bool(np.isfinite(x).all())
