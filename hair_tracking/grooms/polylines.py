"""Strands as a file holds them, and the error a file that cannot be read gives.

:class:`Polylines` is a ragged set of strands: every vertex of every strand in one ``(P, 3)``
array, strand after strand, and the vertex count of each strand.  The readers
(:mod:`~hair_tracking.grooms.formats`) return one; nothing is resampled, converted or moved yet
(:mod:`~hair_tracking.grooms.build` does that).

A file that cannot be read raises :class:`GroomFileError`, whose message is one line: the file,
where in it (a byte offset, an array, a line), what was expected there and what was found.
"""
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np


class GroomFileError(ValueError):
    """A groom file that cannot be read; the message names the file, the place in it and what
    was expected (one line)."""

    def __init__(self, path: str, where: str, expected: str, found: str = ''):
        text = f'{path}: {where}: ' if where else f'{path}: '
        text += f'expected {expected}' if expected else ''
        if found:
            text += f', found {found}' if expected else found
        super().__init__(text)
        self.path = path


@dataclass
class Polylines:
    """Strands as read: ``points`` (P, 3) float64 in the file's units and axes, strand after
    strand; ``counts`` (S,) int64 the vertices of each strand (they sum to P); ``format`` the
    file format in words; ``meters_per_unit`` and ``up_axis`` when the file says them (USD)."""

    points: np.ndarray
    counts: np.ndarray
    format: str
    meters_per_unit: Optional[float] = None
    up_axis: Optional[str] = None

    @property
    def count(self) -> int:
        return int(self.counts.shape[0])

    @property
    def starts(self) -> np.ndarray:
        """Index of each strand's first vertex in ``points`` (S,)."""
        out = np.zeros(self.counts.shape[0], dtype=np.int64)
        np.cumsum(self.counts[:-1], out=out[1:])
        return out

    def select(self, strands: np.ndarray) -> 'Polylines':
        """The strands ``strands`` (indices, in that order) alone."""
        strands = np.asarray(strands, dtype=np.int64)
        counts = self.counts[strands]
        starts = self.starts[strands]
        index = np.repeat(starts - np.concatenate(([0], np.cumsum(counts)[:-1])), counts) + \
            np.arange(int(counts.sum()))
        return Polylines(self.points[index], counts, self.format, self.meters_per_unit,
                         self.up_axis)


def check_finite(path: str, points: np.ndarray, byte_of) -> None:
    """GroomFileError at the first vertex of ``points`` (P, 3) with a NaN or infinite
    coordinate; ``byte_of(i)`` is the byte offset of vertex ``i`` in the file."""
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise GroomFileError(path, f'byte {byte_of(i)} (vertex {i})', 'a finite vertex',
                             f'{points[i].tolist()}')


def bounding_box(points: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The smallest and largest coordinates of ``points`` (P, 3), a column at a time (a
    reduction along the long axis: an order faster than ``min(axis=0)`` on millions of
    points)."""
    return (np.array([points[:, i].min() for i in range(3)]),
            np.array([points[:, i].max() for i in range(3)]))


def strand_of(counts: np.ndarray, vertex: int) -> int:
    """The strand that vertex ``vertex`` belongs to."""
    return int(np.searchsorted(np.cumsum(counts), vertex, side='right'))


def need(path: str, size: int, start: int, nbytes: int, what: str) -> None:
    """GroomFileError unless ``nbytes`` bytes of ``what`` from byte ``start`` fit in a file of
    ``size`` bytes."""
    if start + nbytes > size:
        raise GroomFileError(path, f'byte {start}', f'{what} ({nbytes} bytes)',
                             f'the end of the file at byte {size}')


def read_bytes(path: str) -> bytes:
    """The whole file (GroomFileError when it cannot be read)."""
    try:
        with open(path, 'rb') as f:
            return f.read()
    except FileNotFoundError:
        raise GroomFileError(path, '', '', 'file not found') from None
    except IsADirectoryError:
        raise GroomFileError(path, '', 'a file', 'a directory') from None
    except OSError as e:
        raise GroomFileError(path, '', '', f'cannot read: {e.strerror or e}') from None
