"""The individuality weights of ghost tracking: equations (4) and (5) of Park & Kim.

A ghost node copies the displacement of its target point on the guide and adds a weighted copy of
it (equation (5) with the time step made explicit, see ``docs/ghosts.md``)::

    pos* = pos + v dt (W* + w_tip + w_com),   W* + w_tip + w_com clamped to max_weight

* ``W*`` (equation (4)), the *elastic weight*, from the angle between the node's previous velocity
  ``v0`` and its current velocity ``v`` (unit vectors): ``W* = 0.5 (v . v0) + 0.5`` in mode
  ``'kept'`` (the equation as printed: largest while the velocity keeps its direction) or
  ``W* = 0.5 - 0.5 (v . v0)`` in mode ``'changed'`` (largest where the velocity turns, as the
  paper's text says).  Where a direction is undefined (a zero vector) ``v . v0`` is taken as 0,
  so ``W* = 0.5`` in both modes.
* ``w_tip`` grows linearly with the node's arc-length fraction along its ghost strand, from 0 at
  the root to ``tracking.tip_weight`` at the tip.
* ``w_com`` grows with the node's distance from the centre of mass of its ghost group (same node
  index), divided by the ghost's length so it is dimensionless: ``com_weight * |x - c| / L``.

The numba functions here are small scalar helpers inlined into the fused tracking kernel
(:mod:`hair_tracking.ghosts.kernels`); the array helpers run once at construction.
All weights are dimensionless.
"""
import math

from numba import njit
import numpy as np

#: Codes of ``tracking.elastic_mode`` passed to the kernels (0: the elastic weight is off).
ELASTIC_OFF = 0
ELASTIC_KEPT = 1
ELASTIC_CHANGED = 2


def elastic_code(tracking) -> int:
    """Kernel code of the elastic weight from a ``TrackingSpec``."""
    if not tracking.elastic_weight:
        return ELASTIC_OFF
    if tracking.elastic_mode == 'kept':
        return ELASTIC_KEPT
    if tracking.elastic_mode == 'changed':
        return ELASTIC_CHANGED
    raise ValueError(f'tracking.elastic_mode: {tracking.elastic_mode!r} is not one of '
                     'kept, changed')


@njit(cache=True, inline='always')
def direction_cos(vx, vy, vz, v0x, v0y, v0z):
    """Cosine of the angle between ``v`` and ``v0``, in [-1, 1]; 0 where a direction is undefined
    (``|v|^2 |v0|^2 <= 1e-300``, i.e. speeds below about 1e-75 m/s) or the input is not finite.
    Branch-free, so that loops calling it vectorise."""
    nn = (vx * vx + vy * vy + vz * vz) * (v0x * v0x + v0y * v0y + v0z * v0z)
    ok = nn > 1e-300
    cos = (vx * v0x + vy * v0y + vz * v0z) / math.sqrt(nn if ok else 1.0)
    # comparisons, not min/max: numba's builtins compile to a switch that stops LLVM from
    # vectorising the calling loop (a NaN passes both tests and is caught below)
    cos = -1.0 if cos < -1.0 else cos
    cos = 1.0 if cos > 1.0 else cos
    return cos if ok and cos == cos else 0.0


@njit(cache=True, inline='always')
def elastic_weight(vx, vy, vz, v0x, v0y, v0z, mode):
    """W* of equation (4) from the current (v) and previous (v0) velocity of one node.

    Only the directions matter, so ``v`` may be given as a displacement.  Returns a value in
    [0, 1]; 0 when ``mode`` is :data:`ELASTIC_OFF`.  Directions are undefined (``cos`` taken as
    0, see :func:`direction_cos`) for speeds below about 1e-75 m/s.
    """
    if mode == ELASTIC_OFF:
        return 0.0
    return 0.5 + elastic_sign(mode) * direction_cos(vx, vy, vz, v0x, v0y, v0z)


@njit(cache=True, inline='always')
def elastic_sign(mode):
    """``s`` of ``W* = 0.5 + s cos`` for an elastic mode that is on: 0.5 for
    :data:`ELASTIC_KEPT` (the equation as printed), -0.5 for :data:`ELASTIC_CHANGED`."""
    return 0.5 if mode == ELASTIC_KEPT else -0.5


@njit(cache=True, inline='always')
def com_weight(distance, inv_length, weight_per_length):
    """w_com = weight_per_length * distance / strand length (distance [m], inv_length [1/m])."""
    return weight_per_length * distance * inv_length


@njit(cache=True, inline='always')
def weighted_position(x0, x1, x2, d0, d1, d2, w_elastic, w_tip, w_com, max_weight):
    """Equation (5) for one node, with the velocity transfer it weights: the node at ``x`` moves
    by its guide point's displacement ``d = v dt`` plus the weighted copy of it,

        pos* = x + d (1 + W),   W = W* + (w_tip + w_com) clamped to [0, max_weight]

    (the paper's ``pos`` is the transferred position ``x + d``; ``dt`` is the implied time step
    that turns the velocity into a displacement).  ``w_elastic`` is W* of equation (4)
    (:func:`elastic_weight`), ``w_tip`` from :func:`tip_weights`, ``w_com`` from
    :func:`com_weight`.  Returns ``(pos*_x, pos*_y, pos*_z, clamped)``, ``clamped`` 1 when the
    weight sum exceeded ``max_weight``."""
    w = w_elastic + (w_tip + w_com)
    clamped = 1 if w > max_weight else 0
    w = 1.0 + clamp_weight(w, max_weight)
    return x0 + d0 * w, x1 + d1 * w, x2 + d2 * w, clamped


@njit(cache=True, inline='always')
def clamp_weight(total, max_weight):
    """The weight sum W* + w_tip + w_com limited to [0, max_weight] (energy safety)."""
    if total > max_weight:
        return max_weight
    if total < 0.0:
        return 0.0
    return total


def arc_fractions(rest_length: np.ndarray) -> np.ndarray:
    """(S, N-1) rest segment lengths -> (S, N) arc-length fraction of every node, 0 root, 1 tip.

    A strand of zero length gets evenly spaced fractions ``j / (N - 1)``.
    """
    rest_length = np.asarray(rest_length, dtype=np.float64)
    if rest_length.ndim != 2 or rest_length.shape[1] < 1:
        raise ValueError(f'rest_length must be shaped (S, N-1) with N >= 2, got '
                         f'{rest_length.shape}')
    s, m = rest_length.shape
    cum = np.zeros((s, m + 1))
    np.cumsum(rest_length, axis=1, out=cum[:, 1:])
    total = cum[:, -1:]
    even = np.broadcast_to(np.linspace(0.0, 1.0, m + 1), cum.shape)
    with np.errstate(divide='ignore', invalid='ignore'):
        frac = np.where(total > 0.0, cum / np.where(total > 0.0, total, 1.0), even)
    frac[:, -1] = 1.0
    return np.ascontiguousarray(frac)


def tip_weights(rest_length: np.ndarray, tip_weight: float) -> np.ndarray:
    """(S, N) w_tip of equation (5): ``tip_weight`` times the node's arc-length fraction (0 at
    the root, ``tip_weight`` at the tip).  The fractions are rounded to 12 decimals, so that
    strands with the same layout get bit-equal weights (the tracker shares one row of its node
    table between them)."""
    if not (tip_weight >= 0.0 and np.isfinite(tip_weight)):
        raise ValueError(f'tracking.tip_weight must be a finite number >= 0, got {tip_weight!r}')
    return float(tip_weight) * np.round(arc_fractions(rest_length), 12)
