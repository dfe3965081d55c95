"""What the trackers without state of their own share -- the blend tracker
(:mod:`hair_tracking.ghosts.blend`) and the turn tracker (:mod:`hair_tracking.ghosts.turn`): the
guides are some of the strands themselves (:func:`choose_guides`; a ratio of 1:1 is full
simulation), every guide is read at the ghosts' node fractions (:func:`node_map`,
:func:`guide_columns`), the ghosts are kept out of the head collider with the guide solver's
margin rule (:func:`collider_axes`), and every strand is placed from the guides and head pose
of the last step when the hair is next read (:class:`StatelessTracker`), once per output frame
however many head poses came in between.
"""
from typing import Dict, Optional, Tuple

import numpy as np
from numba import njit

from hair_tracking.core.model import HeadPose, StrandSet, strand_part
from hair_tracking.core.point_records import points_to_records, record_target
from hair_tracking.grooms.guides import farthest_points
from hair_tracking.guides.collision import outside_distance, world_center


def choose_guides(roots: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` strands spread evenly over the scalp: farthest-point sampling of the
    root positions (S, 3) (:func:`~hair_tracking.grooms.guides.farthest_points`), starting from
    the root nearest their centroid; deterministic.  Sorted ascending."""
    return farthest_points(roots, count)


def node_map(ghost_nodes: int, guide_nodes: int) -> Tuple[np.ndarray, np.ndarray]:
    """Guide segment and parameter of each ghost node index at its arc-length fraction
    ``j / (N - 1)`` (the groom spaces nodes evenly along each strand): ``(seg (N,) int64,
    t (N,) float64)``; equal node counts map node to node exactly."""
    f = np.arange(ghost_nodes) / max(1, ghost_nodes - 1) * (guide_nodes - 1)
    seg = np.minimum(np.floor(f).astype(np.int64), guide_nodes - 2)
    t = f - seg
    t[np.abs(t) < 1e-12] = 0.0
    return seg, t


def collider_axes(ghosts: StrandSet, collider) -> Tuple[np.ndarray, np.ndarray]:
    """``(centre, axes)`` of the ellipsoid the ghosts are kept out of (head frame): the head
    collider's radii plus its margin, the margin capped as the guide solver caps it: by the rest
    clearance of any free node and half the shortest segment, so no ghost is pushed out of its
    own rest shape."""
    clearance = outside_distance(ghosts.rest[:, 2:] - collider.center, collider.radii)
    margin = min(collider.margin, float(clearance.min()), 0.5 * float(ghosts.rest_length.min()))
    return (np.ascontiguousarray(collider.center, dtype=np.float64),
            np.ascontiguousarray(collider.radii + max(0.0, margin), dtype=np.float64))


@njit(cache=True, inline='always')
def ellipsoid_form(dx, dy, dz, q0, q1, q2, q3, q4, q5):
    """``d^T Q d`` with ``Q``'s entries Q00 Q11 Q22 Q01 Q02 Q12 as scalars (in a vector loop they
    stay in registers)."""
    return q0 * dx * dx + q1 * dy * dy + q2 * dz * dz + \
        2.0 * (q3 * dx * dy + q4 * dx * dz + q5 * dy * dz)


@njit(cache=True, inline='always')
def world_collider(rot, pos, center, axes, out):
    """The collider ellipsoid (``center``, ``axes``: head frame) in the world for the head pose
    ``rot``, ``pos``: ``out[0:3]`` its centre, ``out[3:9]`` the entries Q00 Q11 Q22 Q01 Q02 Q12
    of ``Q = R diag(1 / axes^2) R^T`` (a point ``x`` is inside when ``(x - c)^T Q (x - c) <
    1``)."""
    out[0], out[1], out[2] = world_center(rot, pos, center)
    inv = 1.0 / (axes * axes)
    for i, (a, b) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
        out[3 + i] = rot[a, 0] * rot[b, 0] * inv[0] + rot[a, 1] * rot[b, 1] * inv[1] + \
            rot[a, 2] * rot[b, 2] * inv[2]


def reference_contact(p, prev, length, head: HeadPose, axes, center, slide=True):
    """Plain-numpy statement of the trackers' head contact for node ``p`` (world) after its
    predecessor ``prev``: inside the ellipsoid ``axes`` around ``center`` (head frame), it is
    placed at ``length`` from ``prev`` along its step with the inward part (along the normal at
    ``prev``) removed (``slide``), then moved radially onto the surface if still inside; a node
    outside is returned as it is.  For the tests and for reading."""
    rot, pos = head.rotation, head.position
    qm = rot @ np.diag(1.0 / np.asarray(axes, dtype=np.float64) ** 2) @ rot.T
    cw = rot @ np.asarray(center, dtype=np.float64) + pos
    if (p - cw) @ qm @ (p - cw) >= 1.0:
        return p
    if slide:                                  # slide along the surface, not into it
        n = qm @ (prev - cw)
        n /= np.linalg.norm(n)
        d = p - prev
        d = d - min(0.0, float(d @ n)) * n
        p = prev + d * (length / np.linalg.norm(d))
    e = float((p - cw) @ qm @ (p - cw))
    if 0.0 < e < 1.0:                          # still inside: radially onto the surface
        p = cw + (p - cw) / np.sqrt(e)
    return p


def at_fractions(points: np.ndarray, seg: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Strands ``points`` (G, M, 3) read at the node fractions of :func:`node_map` (step 1);
    equal node counts give ``points`` itself."""
    if seg.shape[0] == points.shape[1] and not t[:-1].any():
        return points
    a = points[:, seg]
    return a + t[None, :, None] * (points[:, seg + 1] - a)


@njit(cache=True)
def guide_columns(gx, seg, t, out):
    """Kernel, step 1: ``out`` (G, 3, N) every guide ``gx`` (G, M, 3) read at the ghosts' node
    fractions (``seg``, ``t`` from :func:`node_map`), component-major, so a ghost's blend runs
    along its nodes; a node fraction on a guide node copies it exactly."""
    for g in range(gx.shape[0]):
        guide_column(gx, seg, t, out, g)


@njit(cache=True, inline='always')
def guide_column(gx, seg, t, out, g):
    """:func:`guide_columns` for guide ``g``."""
    for j in range(seg.shape[0]):
        a, u = seg[j], t[j]
        for i in range(3):
            if u == 0.0:
                out[g, i, j] = gx[g, a, i]
            elif u == 1.0:
                out[g, i, j] = gx[g, a + 1, i]
            else:
                out[g, i, j] = gx[g, a, i] + u * (gx[g, a + 1, i] - gx[g, a, i])


class StatelessTracker:
    """Places ``ghosts`` from ``guides`` when they are read; a subclass supplies the placement
    (:meth:`_place`).

    ``guides`` must be some of the ghost strands: ``guide_index[i]`` is the ghost strand that
    guide ``i`` is (``ghosts.rest[guide_index] == guides.rest``).  ``collider``, when given and
    ``scene.tracking.collide`` is true, is the head collider (a
    :class:`~hair_tracking.guides.collision.Collider`).  Ghosts carry no velocity of their
    own (``ghosts.v`` stays zero).

    The ghost positions are placed in float32 (:meth:`positions`, world frame): the precision
    of the point cloud they are published in, and half the bytes of float64.  ``ghosts.x``
    (float64) receives them when it is read or assigned; what is assigned there is taken back on
    the next read.  An output that is written before anything reads the positions
    (:meth:`write_records`: a point cloud) receives the ghosts straight from the kernel, without
    the float32 copy in between; a later read places them again from the same step.
    """

    def __init__(self, ghosts: StrandSet, guides: StrandSet, guide_index, scene, collider=None):
        self.ghosts = ghosts
        self.guides = guides
        self.guide_index = np.asarray(guide_index, dtype=np.int64)
        if self.guide_index.shape != (guides.count,) or \
                not np.allclose(ghosts.rest[self.guide_index], guides.rest):
            raise ValueError(f'{type(self).__name__}: the guides must be some of the ghost '
                             'strands (guide_index names them)')
        self.seg, self.t = node_map(ghosts.rest.shape[1], guides.rest.shape[1])
        self._gcol = np.empty((guides.count, 3, ghosts.rest.shape[1]))
        self._rot, self._pos = np.empty((3, 3)), np.empty(3)
        self._pending = False         # a step not yet placed into _x32 (see step and release)
        self._x32 = ghosts.x.astype(np.float32)
        self._x32_out = (self._x32, np.eye(3), np.zeros(3), False, False)
        self._in_x32 = True           # whether _x32 (else ghosts._x) holds the positions
        ghosts.hold(self)             # so a write to ghosts.x before the first step is seen
        self.collide = bool(scene.tracking.collide and collider is not None)
        if self.collide:
            self._center, self._axes = collider_axes(ghosts, collider)
        else:
            self._center, self._axes = np.zeros(3), np.ones(3)
        self.stats: Dict[str, int] = {'ghosts': int(ghosts.count), 'steps': 0, 'evaluations': 0,
                                      'contacts': 0, 'parallel': 1}

    def step(self, dt: float, guide_x_old: Optional[np.ndarray], head: HeadPose,
             substeps: int = 1) -> None:
        """Take the guides now (read at the ghosts' node fractions) and the head pose ``head``;
        every ghost is placed from them when its positions are next read (``ghosts.x``,
        :meth:`positions`) or written (:meth:`write_records`), so a step that no read follows
        costs this copy only.  Nothing is integrated (``dt``, ``guide_x_old`` and
        ``substeps`` are accepted for the simulator's interface and not needed)."""
        guide_columns(self.guides.x, self.seg, self.t, self._gcol)
        np.copyto(self._rot, head.rotation)
        np.copyto(self._pos, head.position)
        self._pending = True
        self.ghosts.hold(self)
        self.stats['steps'] += 1

    def release(self) -> None:
        """Hand the positions to ``ghosts.x``, placing the ghosts from the last :meth:`step`
        first if not done yet (called by :class:`~hair_tracking.core.model.StrandSet` when
        ``ghosts.x`` or ``ghosts.v`` is read or assigned)."""
        self._evaluate()
        if self._in_x32:
            np.copyto(self.ghosts._x, self._x32)
            self._in_x32 = False

    def _evaluate(self) -> None:
        if not self._pending:
            return
        self._pending = False
        self._placed_into(*self._x32_out)
        self._in_x32 = True

    def _placed_into(self, out, rot, origin, moved, check) -> bool:
        contacts, finite = self._place(out, rot, origin, moved, check)
        self.stats['contacts'] = int(contacts)
        self.stats['evaluations'] += 1
        return bool(finite)

    def _place(self, out, rot, origin, moved, check) -> Tuple[int, bool]:
        """Every ghost from ``_gcol``, ``_rot``, ``_pos`` as float32 x y z into ``out`` (S, N,
        >= 3): ``_x32`` as it is, or with ``check`` records carried by ``rot``, ``origin`` when
        ``moved`` (:func:`~hair_tracking.core.point_records.record_target`); returns the number
        of head contacts and whether every coordinate written is finite (true without
        ``check``)."""
        raise NotImplementedError

    def reset(self, head: HeadPose) -> None:
        """Rest shape carried by ``head``."""
        self._pending = False
        self.ghosts.place_at(head)

    def positions(self) -> np.ndarray:
        """The ghost positions (S, N, 3) float32, world frame [m] (the live array: read
        only)."""
        self._evaluate()
        if not self._in_x32:
            np.copyto(self._x32, self.ghosts._x)
            self._in_x32 = True
        return self._x32

    def part_positions(self, part: int, parts: int) -> Tuple[np.ndarray, np.ndarray]:
        """The strands of part ``part`` of ``parts`` (about ``S / parts`` strands; the parts
        together are every strand once) and their positions (float32, world frame): placed
        alone from the last step when nothing has read the hair since (:meth:`_place_part`), so
        a check of a few strands does not cost a whole evaluation; else read from
        :meth:`positions`.  Returns ``(strand indices, positions (len, N, 3))``."""
        if self._pending:
            idx = self._place_part(part, parts)
            return idx, self._x32[idx]
        idx = strand_part(self.ghosts.count, part, parts)
        return idx, self.positions()[idx]

    def _place_part(self, part: int, parts: int) -> np.ndarray:
        """Place the strands of part ``part`` of ``parts`` from the last step into their rows
        of ``_x32`` (the other rows are left as they are: the step stays pending) and return
        their indices."""
        raise NotImplementedError

    def write_records(self, words, stride, rot=None, origin=None) -> bool:
        """float32 x y z of every ghost node into point records (as
        :func:`~hair_tracking.core.point_records.points_to_records`).  After a step that nothing
        has read yet the kernel writes the records itself, and the positions stay to be placed
        when read."""
        if self._pending:
            s, n = self.ghosts.rest.shape[:2]
            return self._placed_into(*record_target(words, stride, s, n, rot, origin), True)
        return points_to_records(words, stride, self.positions(), rot, origin)
