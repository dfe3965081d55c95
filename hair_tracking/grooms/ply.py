"""Polyline PLY files: a ``vertex`` element (``x``, ``y``, ``z``) and a ``strand`` element
with each strand's segment count (``nsegs``), as hairutil writes them and ``plyfile`` reads
them.

PLY (Turk 1994, "The PLY polygon file format"): a text header -- ``ply``, ``format ascii |
binary_little_endian | binary_big_endian 1.0``, ``element NAME COUNT`` lines each followed by its
``property TYPE NAME`` lines, ``end_header`` -- then the elements in the order declared, one row
per item.  Rows of scalar properties have a fixed size, so each element is one numpy structured
array (binary) or one block of numbers (ascii).  A ``property list`` makes rows of varying size:
allowed only in elements after the vertices and strands (e.g. hairutil's ``edge`` or a mesh's
faces), which are not read.  A strand element may give vertex counts instead (``nverts``,
``vertex_count``); without any, every vertex is one strand's, which is an error.
"""
from typing import Dict, List, Tuple

import numpy as np

from hair_tracking.grooms.polylines import (check_finite, GroomFileError, need, Polylines,
                                            read_bytes)

FORMAT = 'polyline PLY'
TYPES = {'char': 'i1', 'int8': 'i1', 'uchar': 'u1', 'uint8': 'u1', 'short': 'i2',
         'int16': 'i2', 'ushort': 'u2', 'uint16': 'u2', 'int': 'i4', 'int32': 'i4',
         'uint': 'u4', 'uint32': 'u4', 'float': 'f4', 'float32': 'f4', 'double': 'f8',
         'float64': 'f8'}
ENCODINGS = {'ascii': '', 'binary_little_endian': '<', 'binary_big_endian': '>'}
#: Strand-element properties holding segment counts (vertices - 1) ...
SEGMENT_NAMES = ('nsegs', 'segments', 'nsegments', 'segment_count')
#: ... or vertex counts.
VERTEX_NAMES = ('nverts', 'vertices', 'nvertices', 'vertex_count')


def _header(path: str, data: bytes) -> Tuple[str, List[Tuple[str, int, list]], int, int]:
    """(encoding, [(element, count, [(property, type or None for a list)])], byte where the
    body starts, header lines)."""
    if not data.startswith(b'ply'):
        raise GroomFileError(path, 'byte 0', 'the magic "ply"', repr(data[:3]))
    end = data.find(b'end_header')
    if end < 0:
        raise GroomFileError(path, 'byte 0', 'a header closed by end_header',
                             'the end of the file')
    body = data.find(b'\n', end)
    body = len(data) if body < 0 else body + 1
    try:
        lines = data[:body].decode('ascii').splitlines()
    except UnicodeDecodeError:
        raise GroomFileError(path, 'the header', 'ASCII text', 'other bytes') from None
    encoding, elements = None, []
    offset = 0
    for line in lines:
        words = line.split()
        where = f'byte {offset}'
        offset += len(line) + 1
        if not words or words[0] in ('ply', 'comment', 'obj_info', 'end_header'):
            continue
        if words[0] == 'format':
            if len(words) < 2 or words[1] not in ENCODINGS:
                raise GroomFileError(path, where, 'format ascii, binary_little_endian or '
                                     'binary_big_endian', line.strip())
            encoding = words[1]
        elif words[0] == 'element' and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == 'property' and elements and len(words) == 3 and words[1] in TYPES:
            elements[-1][2].append((words[2], TYPES[words[1]]))
        elif words[0] == 'property' and elements and len(words) == 5 and words[1] == 'list':
            elements[-1][2].append((words[4], None))
        else:
            raise GroomFileError(path, where, 'a PLY header line (format, element, property, '
                                 'comment)', repr(line.strip()[:40]))
    if encoding is None:
        raise GroomFileError(path, 'the header', 'a format line', 'none')
    return encoding, elements, body, len(lines)


def read_ply(path: str) -> Polylines:
    """The strands of a polyline PLY file (see the module docstring)."""
    data = read_bytes(path)
    encoding, elements, pos, header_lines = _header(path, data)
    names = [e[0] for e in elements]
    for wanted in ('vertex', 'strand'):
        if wanted not in names:
            raise GroomFileError(path, 'the header', f"an element '{wanted}'",
                                 f'elements {names}')
    last = max(names.index('vertex'), names.index('strand'))
    order = ENCODINGS[encoding]
    tables: Dict[str, np.ndarray] = {}
    where_vertex = None             # byte of vertex i (binary) ...
    vertex_line = 0                 # ... or the line of vertex 0 (ascii)
    if order:
        for name, count, props in elements[:last + 1]:
            if any(t is None for _, t in props):
                raise GroomFileError(path, f'byte {pos}', f"element '{name}' of scalar "
                                     'properties before the vertices and strands',
                                     'a list property')
            dtype = np.dtype([(p, order + t) for p, t in props])
            need(path, len(data), pos, dtype.itemsize * count, f"{count} rows of element "
                 f"'{name}'")
            tables[name] = np.frombuffer(data, dtype, count=count, offset=pos)
            if name == 'vertex':
                start, size = pos, dtype.itemsize
                where_vertex = lambda i: start + size * i            # noqa: E731
            pos += dtype.itemsize * count
    else:
        tokens = data[pos:].split()
        taken, line = 0, header_lines
        for name, count, props in elements[:last + 1]:
            if any(t is None for _, t in props):
                raise GroomFileError(path, f'line {line + 1}', f"element '{name}' of scalar "
                                     'properties before the vertices and strands',
                                     'a list property')
            n = count * len(props)
            if taken + n > len(tokens):
                raise GroomFileError(path, f'line {line + 1}', f"{count} rows of element "
                                     f"'{name}'", 'the end of the file')
            try:
                block = np.array(tokens[taken:taken + n], dtype=np.float64)
            except ValueError:
                raise GroomFileError(path, f'line {line + 1}', f"numbers in element '{name}'",
                                     'other text') from None
            tables[name] = np.rec.fromarrays(block.reshape(count, len(props)).T,
                                             names=[p for p, _ in props]) if count else \
                np.zeros(0, dtype=[(p, 'f8') for p, _ in props])
            if name == 'vertex':
                vertex_line = line + 1
            taken += n
            line += count
    vertex, strand = tables['vertex'], tables['strand']
    fields = vertex.dtype.names or ()
    if not {'x', 'y', 'z'} <= set(fields):
        raise GroomFileError(path, 'the header', "vertex properties x, y and z",
                             f'{list(fields)}')
    seg = [p for p in SEGMENT_NAMES if p in (strand.dtype.names or ())]
    ver = [p for p in VERTEX_NAMES if p in (strand.dtype.names or ())]
    if seg:
        counts = np.asarray(strand[seg[0]]).astype(np.int64) + 1
    elif ver:
        counts = np.asarray(strand[ver[0]]).astype(np.int64)
    else:
        raise GroomFileError(path, 'the header', "a strand property nsegs (segments per "
                             "strand) or nverts", f'{list(strand.dtype.names or ())}')
    if len(counts) == 0:
        raise GroomFileError(path, 'the header', 'at least one strand', '0')
    if (counts < 0).any() or int(counts.sum()) != len(vertex):
        raise GroomFileError(path, "element 'strand'", f'counts that make the {len(vertex)} '
                             'vertices', f'{int(counts.sum())}')
    xyz = np.stack([np.asarray(vertex[c], dtype=np.float64) for c in 'xyz'], axis=1)
    if where_vertex is not None:
        check_finite(path, xyz, where_vertex)
    else:
        bad = ~np.isfinite(xyz).all(axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise GroomFileError(path, f'line {vertex_line + i} (vertex {i})',
                                 'a finite vertex', f'{xyz[i].tolist()}')
    return Polylines(xyz, counts, FORMAT)
