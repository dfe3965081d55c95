"""Strand positions written as float32 x y z into fixed-size records, in one compiled pass.

An output format such as a PointCloud2 stores each point as a record of ``stride`` 4-byte
words whose first three are x y z (float32); the other words (a strand index, a colour) are
the caller's and left untouched.  The functions here write the positions of S strands x N
points, record ``s * N + j`` for point ``j`` of strand ``s``, optionally carried by a rigid
transform ``y = rot (x - origin)`` (world -> head frame: ``rot`` = R^T, ``origin`` = the head
position, as :meth:`hair_tracking.core.model.HeadPose.to_head`), and report whether every
coordinate written is finite (a cloud's ``is_dense``).

:func:`blocks_to_records` reads the paper tracker's own layout (block by block,
[node][axis][ghost], see :mod:`hair_tracking.ghosts.kernels`) directly, without a write-back
into ``(S, N, 3)`` first; :func:`points_to_records` takes ``(S, N, 3)`` arrays (the guides, or
ghosts placed already).  The stateless trackers' kernels write records themselves, point by
point with :func:`put_record` (arguments checked by :func:`record_target`).  No ROS here.
"""
import numpy as np
from numba import njit, prange


#: The largest finite float32, as float64: a coordinate outside +-this is not finite once
#: written as float32 (it rounds to +-inf), and NaN fails every comparison.
_MAX32 = float(np.finfo(np.float32).max)


@njit(cache=True, inline='always')
def _put(words, w, x0, x1, x2, rot, origin, moved):
    """Write one point (transformed if ``moved``) at word ``w``; 1 if a coordinate is not a
    finite float32, else 0."""
    if moved:
        d0, d1, d2 = x0 - origin[0], x1 - origin[1], x2 - origin[2]
        y0 = rot[0, 0] * d0 + rot[0, 1] * d1 + rot[0, 2] * d2
        y1 = rot[1, 0] * d0 + rot[1, 1] * d1 + rot[1, 2] * d2
        y2 = rot[2, 0] * d0 + rot[2, 1] * d1 + rot[2, 2] * d2
    else:
        y0, y1, y2 = x0, x1, x2
    words[w] = y0
    words[w + 1] = y1
    words[w + 2] = y2
    return 0 if (abs(y0) <= _MAX32) & (abs(y1) <= _MAX32) & (abs(y2) <= _MAX32) else 1


@njit(cache=True, inline='always')
def put_record(records, s, j, x0, x1, x2, rot, origin, moved):
    """:func:`_put` into the record of point ``j`` of strand ``s`` of ``records`` (S, N,
    stride) (:func:`record_target`)."""
    return _put(records[s, j], 0, x0, x1, x2, rot, origin, moved)


@njit(cache=True, nogil=True, parallel=True)
def _blocks_to_records(words, stride, xb, order, block_rows, n_nodes, rot, origin, moved):
    bad = 0
    for g in prange(block_rows.shape[0] - 1):
        k0 = block_rows[g]
        n = block_rows[g + 1] - k0
        base = k0 * n_nodes * 3
        for kk in range(n):
            w = order[k0 + kk] * n_nodes * stride
            i = base + kk
            for _ in range(n_nodes):
                bad += _put(words, w, xb[i], xb[i + n], xb[i + 2 * n], rot, origin, moved)
                w += stride
                i += 3 * n
    return bad == 0


@njit(cache=True, nogil=True, parallel=True)
def _points_to_records(words, stride, x, n_strands, n_nodes, rot, origin, moved):
    bad = 0
    for s in prange(n_strands):
        w = s * n_nodes * stride
        i = s * n_nodes * 3
        for _ in range(n_nodes):
            bad += _put(words, w, x[i], x[i + 1], x[i + 2], rot, origin, moved)
            w += stride
            i += 3
    return bad == 0


def _check_words(words: np.ndarray, stride: int, points: int) -> np.ndarray:
    if not (isinstance(words, np.ndarray) and words.dtype == np.float32 and words.ndim == 1
            and words.flags.c_contiguous and words.flags.writeable):
        raise TypeError('words must be a writable contiguous 1-d float32 array')
    if stride < 3 or words.size != stride * points:
        raise ValueError(f'words must hold {points} records of stride >= 3 words, got '
                         f'{words.size} words with stride {stride}')
    return words


def _transform(rot, origin):
    """-> (rot, origin, moved) as fresh C-contiguous float64 arrays: numba compiles one
    specialisation per argument type, and read-only or transposed inputs are other types."""
    if rot is None and origin is None:
        return np.eye(3), np.zeros(3), False
    rot = np.eye(3) if rot is None else np.array(rot, dtype=np.float64, order='C')
    origin = np.zeros(3) if origin is None else np.array(origin, dtype=np.float64, order='C')
    if rot.shape != (3, 3) or origin.shape != (3,):
        raise ValueError(f'rot must be (3, 3) and origin (3,), got {rot.shape} and {origin.shape}')
    return rot, origin, True


def record_target(words: np.ndarray, stride: int, strands: int, nodes: int, rot=None,
                  origin=None):
    """The checked output arguments of a kernel that writes the records of ``strands`` x
    ``nodes`` points with :func:`put_record`: ``(records (strands, nodes, stride) float32 view
    of words, rot, origin, moved)``, ``rot`` and ``origin`` as :func:`points_to_records` takes
    them."""
    words = _check_words(words, int(stride), int(strands) * int(nodes))
    rot, origin, moved = _transform(rot, origin)
    return words.reshape(int(strands), int(nodes), int(stride)), rot, origin, moved


def points_to_records(words: np.ndarray, stride: int, x: np.ndarray, rot=None,
                      origin=None) -> bool:
    """``x`` (S, N, 3) -> float32 x y z at the start of ``words``' records (``stride`` words
    each, S * N of them), as ``rot (x - origin)`` when either is given.  Returns True when every
    coordinate written is finite."""
    if not (isinstance(x, np.ndarray) and x.dtype == np.float32 and x.flags.c_contiguous):
        x = np.ascontiguousarray(x, dtype=np.float64)       # float32 positions as they are
    if x.ndim != 3 or x.shape[2] != 3:
        raise ValueError(f'x must be shaped (S, N, 3), got {x.shape}')
    s, n = x.shape[:2]
    words = _check_words(words, int(stride), s * n)
    rot, origin, moved = _transform(rot, origin)
    flat = x.reshape(-1)
    flat.flags.writeable = False     # always read-only: one specialisation a float type
    return bool(_points_to_records(words, np.int64(stride), flat, np.int64(s), np.int64(n),
                                   rot, origin, moved))


def blocks_to_records(words: np.ndarray, stride: int, xb: np.ndarray, order: np.ndarray,
                      block_rows: np.ndarray, n_nodes: int, rot=None, origin=None) -> bool:
    """The ghost tracker's positions ``xb`` (its block layout; ``order`` and ``block_rows`` as
    in :func:`hair_tracking.ghosts.kernels.copy_blocks`) -> float32 x y z at the start of
    the records of ghost ``order[k]``; see :func:`points_to_records`."""
    s = order.shape[0]
    words = _check_words(words, int(stride), s * int(n_nodes))
    if xb.shape != (s * int(n_nodes) * 3,):
        raise ValueError(f'xb must hold {s} x {n_nodes} x 3 values, got {xb.shape}')
    rot, origin, moved = _transform(rot, origin)
    return bool(_blocks_to_records(words, np.int64(stride), xb, order, block_rows,
                                   np.int64(n_nodes), rot, origin, moved))
