"""A groom's shape between its ghosts' nodes: each strand kept at a finer resolution and carried
by its moving ghost.

The ghosts are tracked at ``groom.ghost_nodes`` nodes, so a curl finer than their spacing is
not in them.  With ``groom.detail_nodes`` D > 0 every strand is also kept at D points (an
imported strand resampled from the file by arc length, ``Groom.detail_rest``), stored as
offsets from its ghost's rest polyline, and the output shows those D points moved with the
ghost: the coarse strand carries the fine one, as in the multiresolution hair of Kim & Neumann
2002 ("Interactive multiresolution hair modeling and editing", SIGGRAPH), where a strand's
detail is an offset in its parent curve's local frames, and as shipping hair decouples the
simulated and the rendered resolution.

Rest (:class:`Detail`): point ``j`` sits at node parameter ``u_j = j (N - 1) / (D - 1)`` of its
ghost (both are samples of one polyline spaced evenly by arc length, so the parameters match),
on segment ``k = min(floor(u_j), N - 2)`` at ``t = u_j - k``; its offset is ``o_j = P_j - ((1 -
t) r_k + t r_k+1)`` (head frame).

Now (:func:`carry_kernel`): every ghost segment's turn ``M_k = T(R a_k -> b_k) R``, the turn
tracker's (:func:`~hair_tracking.ghosts.kernels.segment_frame_into`; ``a_k`` and ``b_k`` the
segment's unit direction at rest, head frame, and now, ``R`` the head's rotation); a node's
turn the mean of its two segments' (the end nodes: their one segment's); the point at ``(1 - t)
x_k + t x_k+1 + ((1 - t) N_k + t N_k+1) o_j``.  A strand carried rigidly with the head carries
its detail exactly; the points are continuous across the nodes.  The offsets are within a
segment of the ghost, and the points are not collided themselves: they stay outside the head as
far as the ghost's nodes, which keep the collider's margin, allow.
"""
from typing import Optional, Tuple

import numpy as np
from numba import njit, prange

from hair_tracking.core.kernels import FASTMATH
from hair_tracking.ghosts.kernels import rest_tangents, segment_frame_into

#: Work items of :func:`carry_kernel`'s parallel loop (each with its own turn scratch).
CHUNKS = 64


def stencil(nodes: int, points: int) -> Tuple[np.ndarray, np.ndarray]:
    """For ``points`` points spread evenly over a strand of ``nodes`` nodes by node parameter:
    each point's segment (int64) and its place along it (0..1)."""
    u = np.arange(points) * ((nodes - 1) / (points - 1))
    seg = np.minimum(np.floor(u).astype(np.int64), nodes - 2)
    return seg, u - seg


def on_segments(rest: np.ndarray, seg: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """The points of :func:`stencil` on the polylines ``rest`` (S, N, 3): (S, D, 3)."""
    t = frac[None, :, None]
    return (1.0 - t) * rest[:, seg] + t * rest[:, seg + 1]


class Detail:
    """The detail of the ghost strands ``ghost_rest`` (S, N, 3, head frame [m]): ``fine_rest``
    (S, D, 3) the same strands at D points; None: the strands have no finer shape than their
    nodes, and ``points`` points lie on their segments."""

    def __init__(self, ghost_rest: np.ndarray, fine_rest: Optional[np.ndarray] = None,
                 points: int = 0):
        rest = np.asarray(ghost_rest, dtype=np.float64)
        if fine_rest is not None:
            points = fine_rest.shape[1]
        if points < 2:
            raise ValueError(f'groom.detail_nodes: at least 2 points a strand, got {points}')
        self.seg, self.frac = stencil(rest.shape[1], points)
        if fine_rest is None:
            self.offsets = np.zeros((rest.shape[0], points, 3), dtype=np.float32)
        else:
            self.offsets = (np.asarray(fine_rest, dtype=np.float64)
                            - on_segments(rest, self.seg, self.frac)).astype(np.float32)
        self.tan_rest = rest_tangents(rest)

    @property
    def points(self) -> int:
        """Points per strand (D)."""
        return self.seg.shape[0]

    def carry(self, x: np.ndarray, rotation: np.ndarray,
              rows: Optional[np.ndarray] = None) -> np.ndarray:
        """The detail of the ghosts at ``x`` (S, N, 3) now, the head turned by ``rotation``
        (3, 3; the identity for ``x`` in the head frame): (S, D, 3) float64 in ``x``'s frame;
        ``rows``: those strands only."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        rows = np.arange(x.shape[0], dtype=np.int64) if rows is None else \
            np.ascontiguousarray(rows, dtype=np.int64)
        out = np.empty((rows.shape[0], self.points, 3))
        carry_kernel(x, rows, self.tan_rest, self.offsets, self.seg, self.frac,
                     np.ascontiguousarray(rotation, dtype=np.float64), out)
        return out


@njit(cache=True, parallel=True, fastmath=FASTMATH, error_model='numpy')
def carry_kernel(x, rows, tan_rest, offsets, seg, frac, rot, out):
    """``out[r]`` (D, 3) the detail points of strand ``rows[r]`` of ``x`` (S, N, 3) (see the
    module docstring); ``tan_rest`` (S, N - 1, 3) the unit rest directions (zero rows for
    degenerate segments), ``offsets`` (S, D, 3), ``seg`` and ``frac`` (D,) the
    :func:`stencil`."""
    count = rows.shape[0]
    n_seg = x.shape[1] - 1
    chunks = min(count, CHUNKS)
    for c in prange(chunks):
        turn = np.empty((1, n_seg, 3, 3))
        for r in range(c * count // chunks, (c + 1) * count // chunks):
            s = rows[r]
            for k in range(n_seg):
                segment_frame_into(x, tan_rest, s, k, rot, turn, 0)
            for j in range(seg.shape[0]):
                k = seg[j]
                t = frac[j]
                before = k - 1 if k > 0 else k
                after = k + 1 if k + 1 < n_seg else k
                wa, wb, wc = 0.5 * (1.0 - t), 0.5, 0.5 * t
                ox, oy, oz = offsets[s, j, 0], offsets[s, j, 1], offsets[s, j, 2]
                for a in range(3):
                    m0 = wa * turn[0, before, a, 0] + wb * turn[0, k, a, 0] + \
                        wc * turn[0, after, a, 0]
                    m1 = wa * turn[0, before, a, 1] + wb * turn[0, k, a, 1] + \
                        wc * turn[0, after, a, 1]
                    m2 = wa * turn[0, before, a, 2] + wb * turn[0, k, a, 2] + \
                        wc * turn[0, after, a, 2]
                    out[r, j, a] = (1.0 - t) * x[s, k, a] + t * x[s, k + 1, a] + \
                        m0 * ox + m1 * oy + m2 * oz
