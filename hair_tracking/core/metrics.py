"""Figures of merit of strand arrays (numpy, and one compiled pass for the per-frame stretch
check).

Stretch is ``max |l / l0 - 1|`` over segments (the metric of research.md, section A); errors of an
approximation against a reference are normalised by strand length, as in the reduced-hair
literature (Chai et al. 2014).
"""
import numpy as np
from numba import njit


def max_stretch(x: np.ndarray, rest_length: np.ndarray) -> float:
    """Largest relative length error ``|l / l0 - 1|`` of any segment of ``x`` (S, N, 3) whose
    rest length ``l0`` (S, N-1) is positive; 0 when there is none or the lengths are exact, NaN
    when a measured segment has a NaN length (a check must not hide broken hair).

    One compiled pass without temporaries: it runs on every published frame (and for the node's
    diagnostics), where a numpy expression would make five arrays the size of the hair.  float32
    positions (the stateless trackers') are read as they are, not converted."""
    x = np.asarray(x)
    if x.dtype != np.float32:
        x = np.asarray(x, dtype=np.float64)
    rest_length = np.asarray(rest_length, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3 or rest_length.shape != (x.shape[0], x.shape[1] - 1):
        raise ValueError(f'max_stretch: x must be (S, N, 3) and rest_length (S, N-1), got '
                         f'{x.shape} and {rest_length.shape}')
    return float(_max_stretch(x, rest_length))


@njit(cache=True, error_model='numpy')
def _max_stretch(x, rest_length):
    worst = 0.0
    for s in range(x.shape[0]):
        for i in range(x.shape[1] - 1):
            l0 = rest_length[s, i]
            if not l0 > 0.0:
                continue
            d0 = x[s, i + 1, 0] - x[s, i, 0]
            d1 = x[s, i + 1, 1] - x[s, i, 1]
            d2 = x[s, i + 1, 2] - x[s, i, 2]
            r = abs(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / l0 - 1.0)
            if r != r:          # NaN: broken hair, reported as such
                return r
            worst = max(worst, r)
    return worst


def position_error(x: np.ndarray, ref: np.ndarray, strand_length: np.ndarray):
    """(rms, max) node distance to the reference divided by each strand's length."""
    d = np.linalg.norm(x - ref, axis=2) / strand_length[:, None]
    return float(np.sqrt(np.mean(d * d))), float(d.max())


def tip_error(x: np.ndarray, ref: np.ndarray, strand_length: np.ndarray) -> float:
    """Mean tip distance to the reference divided by strand length."""
    return float(np.mean(np.linalg.norm(x[:, -1] - ref[:, -1], axis=1) / strand_length))


def hair_layer(x: np.ndarray, center, radii, cap_deg: float = 60.0):
    """How thick the hair lies on the head: the 10-90 % spread of the distances [m] of the
    nodes ``x`` (..., 3, head frame) within ``cap_deg`` of the top from the ellipsoid
    ``center``, ``radii`` (along each node's ray from the centre), and their median.  Returns
    ``(spread, median, nodes counted)``."""
    q = np.asarray(x, dtype=np.float64).reshape(-1, 3) - np.asarray(center, dtype=np.float64)
    dist = np.linalg.norm(q, axis=1)
    rel = np.linalg.norm(q / np.asarray(radii, dtype=np.float64), axis=1)
    top = (dist > 0.0) & (q[:, 2] > np.cos(np.radians(cap_deg)) * dist)
    d = ((rel - 1.0) * dist / np.maximum(rel, 1e-300))[top]
    if d.size == 0:
        return 0.0, 0.0, 0
    return float(np.percentile(d, 90) - np.percentile(d, 10)), float(np.median(d)), int(d.size)
