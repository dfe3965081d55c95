"""Groom files out: strands as ``points`` (P, 3) and per-strand vertex ``counts`` (S,), written in
the layouts the readers of :mod:`hair_tracking.grooms.formats` take.

=========  ======================================================================================
``.hair``  Cem Yuksel's layout (:mod:`~hair_tracking.grooms.cyhair`): the 128-byte header with the
           segments and points arrays (u16 segments: at most 65536 vertices a strand)
``.data``  USC-HairSalon's count-prefixed strands (:mod:`~hair_tracking.grooms.counted`)
``.ply``   binary little-endian polyline PLY, ``vertex`` (x y z float) and ``strand`` (``nsegs``
           int) elements (:mod:`~hair_tracking.grooms.ply`)
``.npz``   ``points``, ``counts`` and the units and up axis when known
           (:mod:`~hair_tracking.grooms.npz`)
``.usd*``  a USD stage with one linear ``BasisCurves`` prim ``/groom/hair``, ``metersPerUnit`` and
           ``upAxis`` set when known (usd-core; :mod:`~hair_tracking.grooms.usd`)
=========  ======================================================================================

Only ``.npz`` and USD carry units and an up axis; the other layouts have no place for them.
Points are written as float32, as every one of these layouts stores them.
"""
import os
import struct
from typing import Optional

import numpy as np

from hair_tracking.grooms.polylines import GroomFileError

#: Information text of a ``.hair`` header written here (88 bytes at most).
HAIR_INFO = b'hair_tracking'


def _checked(points, counts):
    p = np.ascontiguousarray(points, dtype='<f4').reshape(-1, 3)
    c = np.asarray(counts, dtype=np.int64).reshape(-1)
    if (c < 0).any() or int(c.sum()) != p.shape[0]:
        raise ValueError(f'vertex counts summing to the {p.shape[0]} points, got '
                         f'{int(c.sum())}')
    return p, c


def write_hair(path: str, points, counts, **_) -> None:
    """Cem Yuksel's ``.hair``: header, u16 segment counts, f32 points."""
    p, c = _checked(points, counts)
    if c.size and (c.min() < 1 or c.max() > 65536):
        raise GroomFileError(path, '', 'strands of 1 to 65536 vertices (u16 segment counts)',
                             f'{int(c.min())} to {int(c.max())}')
    head = struct.pack('<4sIIIIff3f88s', b'HAIR', c.size, p.shape[0], 1 | 2, 0, 1.0, 0.0,
                       0.0, 0.0, 0.0, HAIR_INFO)
    with open(path, 'wb') as f:
        f.write(head)
        f.write((c - 1).astype('<u2').tobytes())
        f.write(p.tobytes())


def write_data(path: str, points, counts, **_) -> None:
    """USC-HairSalon ``.data``: int32 strand count, then per strand its int32 vertex count and
    its f32 x y z."""
    p, c = _checked(points, counts)
    starts = np.concatenate([[0], np.cumsum(c)])
    with open(path, 'wb') as f:
        f.write(struct.pack('<i', c.size))
        for s in range(c.size):
            f.write(struct.pack('<i', int(c[s])))
            f.write(p[starts[s]:starts[s + 1]].tobytes())


def write_ply(path: str, points, counts, **_) -> None:
    """Binary little-endian polyline PLY: vertex x y z (float), strand nsegs (int)."""
    p, c = _checked(points, counts)
    head = ('ply\nformat binary_little_endian 1.0\ncomment written by hair_tracking\n'
            f'element vertex {p.shape[0]}\nproperty float x\nproperty float y\n'
            f'property float z\nelement strand {c.size}\nproperty int nsegs\nend_header\n')
    with open(path, 'wb') as f:
        f.write(head.encode('ascii'))
        f.write(p.tobytes())
        f.write((c - 1).astype('<i4').tobytes())


def write_npz(path: str, points, counts, meters_per_unit: Optional[float] = None,
              up_axis: Optional[str] = None) -> None:
    """``points``, ``counts``, and the units and up axis when given
    (:func:`hair_tracking.grooms.npz.write_npz`)."""
    from hair_tracking.grooms.npz import write_npz as write
    p, c = _checked(points, counts)
    write(path, p, c, meters_per_unit, up_axis)


def write_usd(path: str, points, counts, meters_per_unit: Optional[float] = None,
              up_axis: Optional[str] = None) -> None:
    """A USD stage of one linear BasisCurves prim (:func:`hair_tracking.grooms.usd.write_usd`)."""
    from hair_tracking.grooms.usd import write_usd as write
    p, c = _checked(points, counts)
    write(path, p, c, meters_per_unit, up_axis)


WRITERS = {'.hair': write_hair, '.data': write_data, '.ply': write_ply, '.npz': write_npz,
           '.usd': write_usd, '.usda': write_usd, '.usdc': write_usd}


def write_strands(path: str, points, counts, meters_per_unit: Optional[float] = None,
                  up_axis: Optional[str] = None) -> None:
    """The strands in the layout ``path``'s extension names (:data:`WRITERS`); GroomFileError for
    another extension."""
    ext = os.path.splitext(str(path))[1].lower()
    writer = WRITERS.get(ext)
    if writer is None:
        raise GroomFileError(str(path), 'its name', f'one of the extensions '
                             f'{", ".join(WRITERS)}', repr(ext) if ext else 'none')
    writer(str(path), points, counts, meters_per_unit=meters_per_unit, up_axis=up_axis)
