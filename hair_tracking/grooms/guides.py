"""Guides chosen among the strands: farthest-point sampling.

Farthest-point sampling (Gonzalez 1985, "Clustering to minimize the maximum intercluster
distance", a 2-approximation of the k-centre problem; Eldar, Lindenbaum, Porat & Zeevi 1997,
"The farthest point strategy for progressive image sampling") picks, one after another, the
point farthest from every point picked so far, so every point ends near a pick.  Over the roots
alone (:func:`~hair_tracking.ghosts.stateless.choose_guides`, the procedural groom, whose strands
all share one shape) the guides cover the scalp; over :func:`shape_features` (an imported groom:
fringes, curls and ponytails side by side on the scalp) they cover the scalp and the shapes:
every strand then has a guide both near its root and of a similar shape.
"""
import numpy as np
from numba import njit

#: Fractions of the arc length at which a strand's shape is sampled (:func:`shape_features`).
SHAPE_SAMPLES = (1.0 / 3.0, 2.0 / 3.0, 1.0)


def farthest_points(features: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` rows of ``features`` (S, D) by farthest-point sampling (squared
    Euclidean distances summed over the columns in order), starting from the row nearest their
    mean; ties go to the lower index; deterministic.  Sorted ascending."""
    features = np.ascontiguousarray(features, dtype=np.float64)
    s = features.shape[0]
    if not 1 <= count <= s:
        raise ValueError(f'guides: need 1..{s} guides among {s} strands, got {count}')
    if count == s:
        return np.arange(s)
    first = int(np.argmin(np.sum((features - features.mean(axis=0)) ** 2, axis=1)))
    out = np.empty(count, dtype=np.int64)
    _farthest(features, first, out)
    return np.sort(out)


@njit(cache=True)
def _farthest(features, first, out):
    """Kernel of :func:`farthest_points`: ``out`` the picks, ``out[0] = first``."""
    s, d = features.shape
    dist = np.empty(s)
    pick = first
    for c in range(out.shape[0]):
        out[c] = pick
        best, far = 0, -1.0
        for i in range(s):
            acc = 0.0
            for k in range(d):
                t = features[i, k] - features[pick, k]
                acc += t * t
            if c == 0 or acc < dist[i]:
                dist[i] = acc
            if dist[i] > far:
                best, far = i, dist[i]
        pick = best


def shape_features(rest: np.ndarray) -> np.ndarray:
    """Per strand of ``rest`` (S, N, 3; nodes evenly spaced along each strand) its root and
    its nodes at :data:`SHAPE_SAMPLES` relative to the root, the latter scaled so that the
    roots and the shapes weigh alike (equal total variance): (S, 3 + 3 * len(SHAPE_SAMPLES))."""
    n = rest.shape[1]
    roots = rest[:, 0]
    cols = [int(round(f * (n - 1))) for f in SHAPE_SAMPLES]
    shape = (rest[:, cols] - roots[:, None]).reshape(rest.shape[0], -1)
    var_roots = float(np.sum(np.var(roots, axis=0)))
    var_shape = float(np.sum(np.var(shape, axis=0)))
    weight = np.sqrt(var_roots / var_shape) if var_shape > 0.0 and var_roots > 0.0 else 1.0
    return np.concatenate([roots, weight * shape], axis=1)


def choose_guides_by_shape(rest: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` strands of ``rest`` (S, N, 3) covering the scalp and the shapes:
    :func:`farthest_points` over :func:`shape_features`.  Sorted ascending."""
    return farthest_points(shape_features(rest), count)
