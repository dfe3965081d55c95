"""What the trackers without state of their own share -- the blend tracker
(:mod:`hair_tracking.ghosts.blend`) and the turn tracker (:mod:`hair_tracking.ghosts.turn`): the
guides are some of the strands themselves (:func:`choose_guides`; a ratio of 1:1 is full
simulation), every guide is read at the ghosts' node fractions (:func:`node_map`,
:func:`guide_columns`), the ghosts are kept out of the head collider with the guide solver's
margin rule (:meth:`~hair_tracking.colliders.head.HeadCollider.fitted`), and every strand is
placed from the guides and head pose of the last step when the hair is next read
(:class:`StatelessTracker`), once per output frame however many head poses came in between.
"""
from collections import namedtuple
from typing import Dict, Optional, Tuple

import numpy as np
from numba import njit

from hair_tracking.colliders.head import rotation_entries, world_center
from hair_tracking.colliders.kernels import slide_push_strands
from hair_tracking.colliders.pose import frames_at, world_quadric
from hair_tracking.colliders.reference import (reference_level, reference_pose,
                                               reference_slide_push)
from hair_tracking.colliders.shapes import Shape, shape_table
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.core.model import carry_rigidly, HeadPose, StrandSet, strand_part
from hair_tracking.core.point_records import points_to_records, record_target
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.grooms.guides import farthest_points


#: Where a placement kernel writes, a plain tuple in these fields' order (numba types a named
#: tuple by encoding its class and field names on every call): ``out`` (S, N, >= 3) the
#: positions as x y z, or with ``check`` point records (the points that are not finite counted),
#: carried to ``rot (x - origin)`` when ``moved``
#: (:func:`~hair_tracking.core.point_records.record_target`,
#: :func:`~hair_tracking.core.point_records.put_record`).
Placement = namedtuple('Placement', ['out', 'rot', 'origin', 'moved', 'check'])
#: What a placement kernel places the ghosts from (a plain tuple in these fields' order): the
#: guides at the ghosts' node fractions ``gcol`` (G, 3, N), component-major
#: (:func:`guide_columns`), and the head pose ``rot`` (3, 3), ``pos`` (3,).
GuidePose = namedtuple('GuidePose', ['gcol', 'rot', 'pos'])


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


@njit(cache=True, inline='always')
def world_collider(rot, pos, center, axes, out):
    """The collider ellipsoid (``center``, ``axes``: head frame) in the world for the head pose
    ``rot``, ``pos``: ``out[0:3]`` its centre, ``out[3:9]`` the entries Q00 Q11 Q22 Q01 Q02 Q12
    of ``Q = R diag(1 / axes^2) R^T`` (:func:`~hair_tracking.colliders.pose.world_quadric`; a
    point ``x`` is inside when ``(x - c)^T Q (x - c) < 1``)."""
    out[0], out[1], out[2] = world_center(rot, pos, center)
    inv = 1.0 / (axes * axes)
    world_quadric(rotation_entries(rot), (inv[0], inv[1], inv[2]), out, 3)


def reference_contact(p, prev, length, head: HeadPose, axes, center, slide=True):
    """The trackers' head contact for node ``p`` (world) after its predecessor ``prev`` in plain
    numpy, for the tests and for reading: the contact model's statement
    (:func:`~hair_tracking.colliders.reference.reference_slide_push`) for the ellipsoid ``axes``
    around ``center`` (head frame) placed by ``head``; a node outside is returned as it is."""
    local = shape_table([Shape('ellipsoid', center=tuple(center), radii=tuple(axes))])
    frames = frames_at(head.rotation, head.position)
    row = reference_pose(local, *frames, *frames)[0]
    if reference_level(p, row)[0] >= 0.0:                # outside: as it is
        return p
    return reference_slide_push(p, prev, length, row, slide)


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
    """Places ``ghosts`` from the guides of its last step when the hair is read; a subclass
    supplies the placement (:meth:`_place`).  Implements
    :class:`~hair_tracking.ghosts.interface.GhostTracking`.

    ``guides`` must be some of the ghost strands: ``guide_index[i]`` is the ghost strand that
    guide ``i`` is (``ghosts.rest[guide_index] == guides.rest``).  ``collider``, when given and
    ``scene.tracking.collide`` is true, is the head's row of the collider table (a
    :class:`~hair_tracking.colliders.head.HeadCollider`; its margin fitted to the ghosts,
    :meth:`~hair_tracking.colliders.head.HeadCollider.fitted`); ``colliders`` the scene's
    :class:`~hair_tracking.colliders.table.ColliderTable` (default: one built from ``scene``).
    Ghosts carry no velocity of their own (:meth:`velocities` is zero).

    :meth:`step` keeps the guides (read at the ghosts' node fractions) and the head pose; the
    ghosts are placed from them when they are next read: :meth:`positions` (and
    :meth:`part_positions` of all parts, or :meth:`carry`) places every strand once, in float32
    (the precision of the point cloud they are published in, and half the bytes of float64);
    :meth:`write_records` before any such read writes the point records straight from the
    kernel, without the float32 array in between, and leaves the positions to be placed when
    read; :meth:`part_positions` before any such read places the part's strands alone.  So a
    step that nothing reads costs the copy of the guides only.  Positions set by
    :meth:`reset` and :meth:`carry` are kept exactly (float64) until the next step.
    """

    def __init__(self, ghosts: StrandSet, guides: StrandSet, guide_index, scene, collider=None,
                 colliders: Optional[ColliderTable] = None):
        self.ghosts = ghosts
        self.guides = guides
        self.guide_index = np.asarray(guide_index, dtype=np.int64)
        self.permutation = np.arange(ghosts.count, dtype=np.int64)      # the groom's order
        if self.guide_index.shape != (guides.count,) or \
                not np.allclose(ghosts.rest[self.guide_index], guides.rest):
            raise ValueError(f'{type(self).__name__}: the guides must be some of the ghost '
                             'strands (guide_index names them)')
        self.seg, self.t = node_map(ghosts.rest.shape[1], guides.rest.shape[1])
        self._gcol = np.empty((guides.count, 3, ghosts.rest.shape[1]))
        self._rot, self._pos = np.empty((3, 3)), np.empty(3)
        self._pose = (self._gcol, self._rot, self._pos)       # GuidePose of the last step
        self._pending = False         # a step not yet placed into _x32
        self._x32 = ghosts.x.astype(np.float32)
        self._x32_target = (self._x32, np.eye(3), np.zeros(3), False, False)      # Placement
        self._x64 = None              # the positions set by reset or carry, until a step
        self._stepped = False         # the positions are placed from the last step
        self._v = np.zeros(ghosts.rest.shape)
        self._v.flags.writeable = False
        self.collide = bool(scene.tracking.collide and collider is not None)
        table = colliders if colliders is not None else ColliderTable(scene)
        head = collider.fitted(ghosts.rest, ghosts.inv_mass, ghosts.rest_length) \
            if self.collide else None
        #: the ellipsoid the ghosts are kept out of, head frame: its centre and its radii plus
        #: the margin fitted to the ghosts (a stand-in without a collider)
        if head is not None:
            self.center, self.axes = head.center, head.axes
        else:
            self.center, self.axes = np.zeros(3), np.ones(3)
        #: the scene's bust and slot colliders (``None`` without either), the head's row
        #: first: every placement is followed by their contact pass
        #: (:func:`~hair_tracking.colliders.kernels.slide_push_strands`)
        self.body = table.body_for(ghosts, head.row() if head is not None else None)
        self._head = HeadPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.eye(3))
        self._rest_length = np.ascontiguousarray(ghosts.rest_length, dtype=np.float64)
        self.stats: Dict[str, int] = {'ghosts': int(ghosts.count), 'steps': 0, 'evaluations': 0,
                                      'contacts': 0, 'parallel': 1}

    def step(self, motion: TrackStep) -> None:
        """Keep the guides ``motion.guide_x`` (read at the ghosts' node fractions) and the head
        pose ``motion.head``: every ghost is placed from them when it is next read."""
        guide_columns(motion.guide_x, self.seg, self.t, self._gcol)
        np.copyto(self._rot, motion.head.rotation)
        np.copyto(self._pos, motion.head.position)
        self._head = motion.head
        self._pending = True
        self._x64 = None
        self._stepped = True
        self.stats['steps'] += 1

    def _evaluate(self) -> None:
        """Place every ghost from the last step into ``_x32`` if not done yet."""
        if not self._pending:
            return
        self._pending = False
        self._placed_into(self._x32_target)
        if self.body is not None:
            self.stats['contacts'] += int(slide_push_strands(
                self._x32, self._rest_length, self.body.posed(self._head, self._head, 0.0), 2,
                self.body.lead))

    def _placed_into(self, target) -> bool:
        contacts, finite = self._place(target)
        self.stats['contacts'] = int(contacts)
        self.stats['evaluations'] += 1
        return bool(finite)

    def _place(self, target) -> Tuple[int, bool]:
        """Every ghost from the last step (``_pose``) as float32 x y z into ``target`` (the
        fields of :data:`Placement`: ``_x32`` as it is, or point records); returns the number
        of head contacts and whether every coordinate written is finite (true without
        ``check``)."""
        raise NotImplementedError

    def _set(self, x: np.ndarray, head: HeadPose) -> None:
        """Positions ``x`` (S, N, 3) float64 from outside a step, placed with the head pose
        ``head``, kept exactly; with a bust, moved out of it by the placement's contact pass
        (the bust does not follow the head's tilt: hair carried with the head may hang
        through it)."""
        self._pending = False
        self._stepped = False
        self._x64 = x
        self._x32[...] = x
        if self.body is not None and slide_push_strands(
                self._x32, self._rest_length, self.body.posed(head, head, 0.0), 2,
                self.body.lead):
            self._x64 = None

    @property
    def from_step(self) -> bool:
        """Whether the positions are (or will be) placed from the guides and head pose of the
        last step alone, not set by :meth:`reset` or :meth:`carry` since: what a process given
        the same guides and head pose places (a ghost shard, ``hair_sim_ghosts``)."""
        return self._stepped

    def reset(self, head: HeadPose) -> None:
        """Rest shape carried by ``head``."""
        self._set(head.to_world(self.ghosts.rest), head)

    def carry(self, old: HeadPose, new: HeadPose) -> None:
        """The ghosts now (placed from the last step first if not done yet) carried rigidly
        with the head from ``old`` to ``new``."""
        self._evaluate()
        x = self._x64 if self._x64 is not None else self._x32.astype(np.float64)
        self._set(carry_rigidly(x, old, new), new)

    def zero_velocities(self) -> None:
        """Nothing to do: the ghosts carry no velocity of their own."""

    def positions(self) -> np.ndarray:
        """The ghost positions (S, N, 3) float32, world frame [m], placed from the last step
        first if not done yet (read only)."""
        self._evaluate()
        view = self._x32.view()
        view.flags.writeable = False
        return view

    def velocities(self) -> np.ndarray:
        """Zero (S, N, 3): the ghosts carry no velocity of their own."""
        return self._v

    def part_positions(self, part: int, parts: int) -> Tuple[np.ndarray, np.ndarray]:
        """The strands of part ``part`` of ``parts`` (about ``S / parts`` strands; the parts
        together are every strand once) and their positions (float32, world frame): placed
        alone from the last step when nothing has read the hair since (:meth:`_place_part`), so
        a check of a few strands does not cost a whole evaluation; else read from
        :meth:`positions`.  Returns ``(strand indices, positions (len, N, 3))``."""
        if self._pending and self.body is None:
            idx = self._place_part(part, parts)
            return idx, self._x32[idx]
        idx = strand_part(self.ghosts.count, part, parts)
        return idx, self.positions()[idx]

    def _place_part(self, part: int, parts: int) -> np.ndarray:
        """Place the strands of part ``part`` of ``parts`` from the last step into their rows
        of ``_x32`` (the other rows are left as they are: the step stays pending) and return
        their indices."""
        raise NotImplementedError

    def _place_rows(self, rows: slice, target) -> Tuple[int, bool]:
        """Place the strands ``rows`` (a contiguous slice) from the last step alone into
        ``target`` (the fields of :data:`Placement`, ``out`` holding those rows only), each
        strand bit for bit as a whole placement places it; returns as :meth:`_place`."""
        raise NotImplementedError

    def rows_positions(self, rows: slice) -> np.ndarray:
        """The strands ``rows`` (a contiguous slice; the blend tracker's from a multiple of
        :data:`~hair_tracking.ghosts.blend.STRAND_BLOCK`) placed from the last step alone
        (:meth:`_place_rows`), with the bust's contact pass: their float32 positions (len, N,
        3), world [m], a view of the tracker's array valid until the next step (the other
        strands are left as they are)."""
        x = self._x32[rows]
        self._place_rows(rows, (x,) + self._x32_target[1:])
        if self.body is not None:
            slide_push_strands(x, self._rest_length[rows],
                               self.body.posed(self._head, self._head, 0.0), 2, self.body.lead)
        return x

    def write_rows(self, rows: slice, words, stride, rot=None, origin=None) -> bool:
        """float32 x y z of the nodes of the strands ``rows`` (as :meth:`rows_positions`)
        into point records (as :meth:`write_records`), straight from the kernel without a
        bust; returns whether every coordinate is finite."""
        if self.body is not None:
            return points_to_records(words, stride, self.rows_positions(rows), rot, origin)
        s, n = rows.stop - rows.start, self.ghosts.rest.shape[1]
        return bool(self._place_rows(rows, record_target(words, stride, s, n, rot, origin) +
                                     (True,))[1])

    def write_records(self, words, stride, rot=None, origin=None) -> bool:
        """float32 x y z of every ghost node into point records (as
        :func:`~hair_tracking.core.point_records.points_to_records`).  After a step that nothing
        has read yet the kernel writes the records itself, and the positions stay to be placed
        when read."""
        if self._pending and self.body is None:
            s, n = self.ghosts.rest.shape[:2]
            return self._placed_into(record_target(words, stride, s, n, rot, origin) + (True,))
        return points_to_records(words, stride, self.positions(), rot, origin)
