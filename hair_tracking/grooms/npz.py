"""Strands in a numpy ``.npz`` archive (what ``hair_sim_groom convert`` writes).

Either ``strands`` (S, N, 3): every strand with N vertices, or ``points`` (P, 3) with ``counts``
(S,): the vertices of all strands one after the other and each strand's vertex count.
Optional ``meters_per_unit`` (a number) and ``up_axis`` (``'y'``, ``'-x'``, ...) say the units and
axes, as a USD stage does; without them they are guessed like any file's.
"""
import os
import zipfile

import numpy as np

from hair_tracking.grooms.fit import UP_AXES
from hair_tracking.grooms.polylines import GroomFileError, Polylines, strand_of

FORMAT = 'NPZ'


#: The arrays of an archive may hold at most this many bytes more than the file ...
NPZ_SLACK_BYTES = 64 << 20
#: ... plus this many times the file's size (what compression may gain on strands).
NPZ_MAX_RATIO = 20


def _check_members(path: str) -> None:
    """Every array's header against what its member holds, and the members' sizes against the
    file's, before numpy allocates an array of the declared shape (it does so before reading
    the data): GroomFileError naming the array."""
    size = os.path.getsize(path)
    with zipfile.ZipFile(path) as zf:
        total = 0
        for info in zf.infolist():
            total += info.file_size
            if total > NPZ_SLACK_BYTES + NPZ_MAX_RATIO * size:
                raise GroomFileError(path, f'member {info.filename!r}', f'arrays of at most '
                                     f'{NPZ_MAX_RATIO}x the file\'s {size} bytes',
                                     f'{total} bytes declared')
            if not info.filename.endswith('.npy'):
                continue
            with zf.open(info) as f:
                version = np.lib.format.read_magic(f)
                read = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                    np.lib.format.read_array_header_2_0
                shape, _, dtype = read(f)
                start = f.tell()
            nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
            if start + nbytes != info.file_size:
                raise GroomFileError(path, f'array {info.filename[:-4]!r}', f'a shape that '
                                     f'fits its {info.file_size - start} bytes',
                                     f'{dtype} {shape}')


def read_npz(path: str) -> Polylines:
    """The strands of an ``.npz`` file (see the module docstring)."""
    try:
        _check_members(path)
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except GroomFileError:
        raise
    except FileNotFoundError:
        raise GroomFileError(path, '', '', 'file not found') from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise GroomFileError(path, 'byte 0', 'a numpy .npz archive', str(e).split('\n')[0]) \
            from None
    if 'strands' in arrays:
        s = arrays['strands']
        if s.ndim != 3 or s.shape[2] != 3 or s.dtype.kind not in 'fiu':
            raise GroomFileError(path, "array 'strands'", 'numbers of shape (S, N, 3)',
                                 f'{s.dtype} {s.shape}')
        points = s.reshape(-1, 3).astype(np.float64)
        counts = np.full(s.shape[0], s.shape[1], dtype=np.int64)
    elif 'points' in arrays and 'counts' in arrays:
        p, c = arrays['points'], arrays['counts']
        if p.ndim != 2 or p.shape[1] != 3 or p.dtype.kind not in 'fiu':
            raise GroomFileError(path, "array 'points'", 'numbers of shape (P, 3)',
                                 f'{p.dtype} {p.shape}')
        if c.ndim != 1 or c.dtype.kind not in 'iu' or (c < 0).any() or \
                int(c.sum()) != p.shape[0]:
            raise GroomFileError(path, "array 'counts'", f'vertex counts >= 0 summing to the '
                                 f'{p.shape[0]} points', f'{c.dtype} {c.shape}, sum '
                                 f'{int(c.sum()) if c.dtype.kind in "iu" else "?"}')
        points, counts = p.astype(np.float64), c.astype(np.int64)
    else:
        raise GroomFileError(path, 'arrays', "'strands' (S, N, 3), or 'points' (P, 3) with "
                             "'counts' (S,)", f'{sorted(arrays)}')
    if counts.shape[0] == 0:
        raise GroomFileError(path, "array 'counts'" if 'counts' in arrays else
                             "array 'strands'", 'at least one strand', '0')
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise GroomFileError(path, f'vertex {i} (strand {strand_of(counts, i)})',
                             'a finite vertex', f'{points[i].tolist()}')
    mpu = arrays.get('meters_per_unit')
    up = arrays.get('up_axis')
    if mpu is not None and not (mpu.shape == () and mpu.dtype.kind == 'f' and
                                np.isfinite(mpu) and mpu > 0):
        raise GroomFileError(path, "array 'meters_per_unit'", 'a positive number',
                             f'{mpu!r}')
    if up is not None and str(up) not in UP_AXES:
        raise GroomFileError(path, "array 'up_axis'", f'one of {", ".join(UP_AXES)}',
                             f'{up!r}')
    return Polylines(points, counts, FORMAT,
                     meters_per_unit=None if mpu is None else float(mpu),
                     up_axis=None if up is None else str(up))


def write_npz(path: str, points: np.ndarray, counts: np.ndarray, meters_per_unit=None,
              up_axis=None) -> None:
    """Write strands as ``points`` and ``counts`` (float32 and int32; see the module
    docstring), with the units and up axis when given."""
    extra = {}
    if meters_per_unit is not None:
        extra['meters_per_unit'] = np.float64(meters_per_unit)
    if up_axis is not None:
        extra['up_axis'] = np.str_(up_axis)
    with open(path, 'wb') as f:
        np.savez_compressed(f, points=np.asarray(points, dtype=np.float32),
                            counts=np.asarray(counts, dtype=np.int32), **extra)
