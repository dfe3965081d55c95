"""Cem Yuksel's ``.hair`` files (cyHairFile.h, MIT licence; www.cemyuksel.com/research/
hairmodels).

Layout, little-endian: a 128-byte header -- ``"HAIR"``, u32 hair count, u32 point count, u32
bit flags of the arrays present (1 segments, 2 points, 4 thickness, 8 transparency, 16 colours),
u32 default segments, f32 default thickness, f32 default transparency, f32[3] default colour,
char[88] information -- then the arrays in that order: u16 segments per strand (vertices - 1;
absent: every strand has the default), f32 x y z per point, f32 thickness per point, f32
transparency per point, f32 r g b per point.  Only the segments and the points are used.
"""
import numpy as np

from hair_tracking.grooms.polylines import (check_finite, GroomFileError, need, Polylines,
                                            read_bytes)

MAGIC = b'HAIR'
HEADER = np.dtype([('magic', 'S4'), ('hairs', '<u4'), ('points', '<u4'), ('arrays', '<u4'),
                   ('d_segments', '<u4'), ('d_thickness', '<f4'), ('d_transparency', '<f4'),
                   ('d_color', '<f4', 3), ('info', 'S88')])
SEGMENTS_BIT, POINTS_BIT, THICKNESS_BIT, TRANSPARENCY_BIT, COLORS_BIT = 1, 2, 4, 8, 16
FORMAT = "Cem Yuksel's .hair"


def read_hair(path: str) -> Polylines:
    """The strands of a ``.hair`` file (GroomFileError naming the byte where it goes wrong)."""
    data = read_bytes(path)
    size = len(data)
    need(path, size, 0, HEADER.itemsize, 'the 128-byte header')
    h = np.frombuffer(data, HEADER, count=1)[0]
    if bytes(h['magic']) != MAGIC:
        raise GroomFileError(path, 'byte 0', 'the magic "HAIR"', repr(bytes(h['magic'])))
    hairs, points, arrays = int(h['hairs']), int(h['points']), int(h['arrays'])
    if not arrays & POINTS_BIT:
        raise GroomFileError(path, 'byte 12', 'array flags with the points bit (2)',
                             f'flags {arrays}')
    pos = HEADER.itemsize
    if arrays & SEGMENTS_BIT:
        need(path, size, pos, 2 * hairs, f'{hairs} u16 segment counts')
        counts = np.frombuffer(data, '<u2', count=hairs, offset=pos).astype(np.int64) + 1
        pos += 2 * hairs
        where = f'byte {HEADER.itemsize}'
    else:
        # checked before anything of the declared sizes is allocated
        per_strand = int(h['d_segments']) + 1
        if hairs * per_strand != points:
            raise GroomFileError(path, 'byte 16', f'a default segment count that makes the '
                                 f'header\'s {points} points', f'{hairs * per_strand} points')
        need(path, size, pos, 12 * points, f'{points} f32 x y z points')
        counts = np.full(hairs, per_strand, dtype=np.int64)
        where = 'byte 16'
    if int(counts.sum()) != points:
        raise GroomFileError(path, where, f'segment counts that make the header\'s {points} '
                             'points', f'{int(counts.sum())} points')
    need(path, size, pos, 12 * points, f'{points} f32 x y z points')
    xyz = np.frombuffer(data, '<f4', count=3 * points, offset=pos).reshape(points, 3)
    start = pos
    check_finite(path, xyz, lambda i: start + 12 * i)
    pos += 12 * points
    for bit, per_point, what in ((THICKNESS_BIT, 4, 'thickness'),
                                 (TRANSPARENCY_BIT, 4, 'transparency'),
                                 (COLORS_BIT, 12, 'colour')):
        if arrays & bit:
            need(path, size, pos, per_point * points, f'the {what} array')
            pos += per_point * points
    if pos != size:
        raise GroomFileError(path, f'byte {pos}', 'the end of the file',
                             f'{size - pos} more bytes')
    if hairs == 0:
        raise GroomFileError(path, 'byte 4', 'at least one strand', '0')
    return Polylines(xyz.astype(np.float64), counts, FORMAT)
