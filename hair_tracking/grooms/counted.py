"""Files of count-prefixed strands, little-endian, no header: USC-HairSalon / Hair20k ``.data``
and CT2Hair ``.bin``.

Layout: int32 strand count, then per strand an int32 vertex count and that many points of
``k`` float32: x y z for ``.data`` (``k`` = 3; a strand of one vertex is an empty root), x y z,
tangent x y z and a label for ``.bin`` (``k`` = 7; only x y z are used).

Where each strand starts depends on every count before it, so the counts are found by one walk
over the strands (a step per strand, not per vertex); the points are then taken out of the file
in one compiled gather.
"""
from numba import njit
import numpy as np

from hair_tracking.grooms.polylines import (check_finite, GroomFileError, need, Polylines,
                                            read_bytes, strand_of)

DATA = 'USC-HairSalon .data'
CT2HAIR = 'CT2Hair .bin'


def read_data(path: str) -> Polylines:
    """The strands of a USC-HairSalon / Hair20k ``.data`` file."""
    return read_counted(path, 3, DATA)


def read_ct2hair(path: str) -> Polylines:
    """The strands of a CT2Hair ``.bin`` file."""
    return read_counted(path, 7, CT2HAIR)


def read_counted(path: str, k: int, fmt: str) -> Polylines:
    """Count-prefixed strands of ``k`` float32 a point (see the module docstring)."""
    data = read_bytes(path)
    size = len(data)
    need(path, size, 0, 4, 'the int32 strand count')
    n_words = size // 4
    words = np.frombuffer(data, '<i4', count=n_words)
    strands = int(words[0])
    if strands <= 0:
        raise GroomFileError(path, 'byte 0', 'a strand count of at least 1', str(strands))
    if 1 + strands > n_words:
        raise GroomFileError(path, 'byte 0', f'a strand count the file can hold (at most '
                             f'{n_words - 1})', str(strands))
    heads = np.empty(strands, dtype=np.int64)      # word index of each strand's count
    pos = 1
    for s in range(strands):
        if pos >= n_words:
            raise GroomFileError(path, f'byte {4 * pos} (strand {s})',
                                 f'the int32 vertex count of strand {s} of {strands}',
                                 f'the end of the file at byte {size}')
        n = int(words[pos])
        if n < 0:
            raise GroomFileError(path, f'byte {4 * pos} (strand {s})',
                                 'a vertex count >= 0', str(n))
        if pos + 1 + k * n > n_words:
            raise GroomFileError(path, f'byte {4 * pos + 4} (strand {s})',
                                 f'{n} vertices of {4 * k} bytes',
                                 f'the end of the file at byte {size}')
        heads[s] = pos
        pos += 1 + k * n
    counts = words[heads].astype(np.int64)
    end = 4 * pos
    if end != size:
        raise GroomFileError(path, f'byte {end}', f'the end of the file after {strands} '
                             'strands', f'{size - end} more bytes')
    floats = np.frombuffer(data, '<f4', count=pos)
    xyz = np.empty((int(counts.sum()), 3))
    _gather(floats, heads, counts, k, xyz)     # a signalling NaN in the file: checked below
    # vertex i sits after the counts of its strand and those before it
    check_finite(path, xyz, lambda i: 4 * (1 + strand_of(counts, i) + 1 + k * i))
    return Polylines(xyz, counts, fmt)


@njit(cache=True)
def _gather(floats, heads, counts, k, out):
    """x y z (float64) of every vertex into ``out`` (P, 3): strand ``s``'s ``counts[s]``
    points of ``k`` floats follow its count at word ``heads[s]``."""
    v = 0
    for s in range(heads.shape[0]):
        w = heads[s] + 1
        for _ in range(counts[s]):
            out[v, 0] = floats[w]
            out[v, 1] = floats[w + 1]
            out[v, 2] = floats[w + 2]
            v += 1
            w += k
