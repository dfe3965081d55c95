"""Validation of the numpy inputs shared by the message builders: strands and colours.

Strands are ``(S, N, 3)`` arrays of points [m] (S strands of N points each, in the frame the
message will name). Colours are RGBA (or RGB, alpha 1) in [0, 1], either per strand ``(S, 3|4)``
or per point ``(S, N, 3|4)``.
"""
import numpy as np


def _first_bad(mask):
    return tuple(int(i) for i in np.argwhere(mask)[0])


def as_strands(strands, *, name='strands', min_points=1, finite=True):
    """``strands`` as a C-contiguous little-endian float64 ``(S, N, 3)`` array.

    ValueError when the shape is wrong, there are fewer than ``min_points`` points per strand,
    or (with ``finite``) a coordinate is NaN/Inf — a NaN point is a caller bug, not data.
    """
    a = np.asarray(strands)
    if a.dtype.kind not in 'fiu':
        raise ValueError(f'{name} must be a real numeric array, got dtype {a.dtype}')
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f'{name} must be shaped (S, N, 3), got {a.shape}')
    if a.shape[1] < min_points:
        raise ValueError(f'{name} needs at least {min_points} points per strand, '
                         f'got shape {a.shape}')
    a = np.ascontiguousarray(a, dtype='<f8')
    if finite and not np.isfinite(a).all():
        idx = _first_bad(~np.isfinite(a))
        raise ValueError(f'{name}{list(idx)} is {a[idx]}: points must be finite '
                         f'(NaN/Inf points are a caller bug)')
    return a


def as_color(color, *, name='color'):
    """One RGBA colour as a tuple of 4 Python floats, each rounded to float32 (ColorRGBA)."""
    c = np.asarray(color, dtype=np.float64)
    if c.shape not in ((3,), (4,)):
        raise ValueError(f'{name} must be RGB or RGBA (3 or 4 numbers), got shape {c.shape}')
    if not (np.isfinite(c).all() and (c >= 0.0).all() and (c <= 1.0).all()):
        raise ValueError(f'{name} components must be finite and in [0, 1], got {c.tolist()}')
    if c.shape == (3,):
        c = np.append(c, 1.0)
    return tuple(float(v) for v in c.astype(np.float32))


def as_colors(colors, n_strands, n_points, *, name='colors'):
    """Per-strand or per-point colours as float32 ``(S, 1, 4)`` or ``(S, N, 4)``; None passes.

    Accepted shapes: ``(S, 3)``, ``(S, 4)`` (one colour per strand) and ``(S, N, 3)``,
    ``(S, N, 4)`` (one per point); RGB gets alpha 1. Components must be finite and in [0, 1].
    """
    if colors is None:
        return None
    c = np.asarray(colors)
    if c.dtype.kind not in 'fiu':
        raise ValueError(f'{name} must be a real numeric array, got dtype {c.dtype}')
    per_strand = c.ndim == 2 and c.shape[0] == n_strands and c.shape[1] in (3, 4)
    if not (per_strand or c.ndim == 3 and c.shape[:2] == (n_strands, n_points)
            and c.shape[2] in (3, 4)):
        raise ValueError(f'{name} must be shaped (S, 3|4) or (S, N, 3|4) with S={n_strands}, '
                         f'N={n_points}; got {c.shape}')
    if per_strand:
        c = c[:, None, :]
    out = np.ones(c.shape[:2] + (4,), dtype='<f4')
    out[..., :c.shape[2]] = c
    if out.size and not (out.min() >= 0.0 and out.max() <= 1.0):     # NaN fails both
        bad = ~((c >= 0.0) & (c <= 1.0))
        idx = _first_bad(bad[:, 0] if per_strand else bad)
        value = c[(idx[0], 0, idx[1]) if per_strand else idx]
        raise ValueError(f'{name}{list(idx)} is {value}: colour components must be in [0, 1]')
    return out
