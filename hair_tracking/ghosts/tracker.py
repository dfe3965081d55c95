"""Ghost strands that follow the simulated guides: the method of Park & Kim.

``GhostTracker`` assigns every ghost strand to a guide (equation (1),
:mod:`hair_tracking.ghosts.correspondence`), precomputes everything static, and then, once per
substep after the guides moved, advances all
ghosts with one fused numba kernel (:func:`hair_tracking.ghosts.kernels.track_groups`):

a. velocity transfer -- each ghost node moves by the displacement of its target point on the guide
   (the point at the node's arc-length fraction);
b. individuality weights -- equations (4)-(5) with ``dt`` explicit
   (:mod:`hair_tracking.ghosts.weights`);
c. offset feedback -- a pull toward ``guide point + Q rest_offset``, ``Q`` the guide segment's
   frame (head rotation composed with the smallest rotation of the rest tangent onto the current
   one), so the offsets turn with the head (unlike TressFX follow hairs);
d. centre-of-mass tracking -- per group and node index the ghosts' centre of mass moves toward the
   centre of mass of their targets (paper Fig. 1), so ghosts never drift;
e. optional spread control (HairControl, Milliez et al. 2018);
f. optional length restoration (one Follow-The-Leader pass, Mueller, Kim & Chentanez 2012);
g. roots (nodes 0 and 1) pinned at ``head.to_world(rest)``;
h. optional collision with the head collider: inside the kernel for the table's head row
   (:class:`hair_tracking.colliders.head.HeadCollider`), node by node after (f) (push out with
   friction, then, with length restoration on, the collision-aware FTL step of the guides,
   :func:`hair_tracking.guides.ftl.restore_node`, so a
   push does not stretch the ghost);
i. with a body (``body.bust``), the contact model's collision stage against the bust's
   capsules after the kernel, as the guide solver runs it
   (:func:`~hair_tracking.colliders.kernels.collide`: friction relative to the body's motion,
   the push-out velocity bound ``body.max_push_speed``; with length restoration on,
   :func:`~hair_tracking.guides.ftl.ftl_restore_shapes`), and the pushed nodes' velocities
   updated by their push.

See ``docs/ghosts.md`` for the reasoning, the two readings of equation (4) and the energy argument.

Ghost order: the user's ghost order is never changed.  Internally ghosts are visited group by
group through ``order`` (ghost indices sorted by guide, stable); group ``g`` is
``order[group_start[g]:group_start[g + 1]]`` and follows guide ``group_guide[g]``.
"""
import math
from typing import Dict, Optional, Tuple

import numba
import numpy as np

from hair_tracking.colliders.head import HeadCollider
from hair_tracking.colliders.kernels import collide
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.core.kernels import runs_parallel
from hair_tracking.core.model import carry_rigidly, HeadPose, StrandSet, strand_part
from hair_tracking.core.point_records import blocks_to_records
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts.correspondence import assign_guides, node_correspondence
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.ghosts.kernels import (block_groups, chunk_count, copy_blocks, GhostModel,
                                          group_blocks, guide_frames, rest_tangents, TMP_ROWS,
                                          track_groups, track_groups_serial, TrackWork)
from hair_tracking.ghosts.weights import elastic_code, tip_weights
from hair_tracking.guides.ftl import ftl_restore_shapes


class GhostTracker:
    """Moves ``ghosts`` (a :class:`StrandSet`) after ``guides``; implements
    :class:`~hair_tracking.ghosts.interface.GhostTracking`.

    The tracker takes ``ghosts.x`` and ``ghosts.v`` (world frame [m], [m/s]) as its start
    state and keeps the state in its kernel's layout (block by block, [node][axis][ghost], see
    :mod:`hair_tracking.ghosts.kernels`) from then on: :meth:`positions` and :meth:`velocities`
    write it out into arrays of the ghosts' shape when they are read after a step (the
    positions alone for :meth:`positions`), :meth:`write_records` reads it straight from the
    blocks, and :meth:`set_state` puts a state in.  So several substeps without a read cost no
    conversion.

    ``collider`` is used only when ``scene.tracking.collide`` is true and it is given: the
    head's row of the collider table (a :class:`~hair_tracking.colliders.head.HeadCollider`,
    with the scene's margin as given).  ``colliders``: the scene's
    :class:`~hair_tracking.colliders.table.ColliderTable` (its bust and slots, stage (i);
    default: one built from ``scene``).

    ``regroup`` (default true): the ghost StrandSet is reordered **once**, at construction, so
    that the ghosts of each guide are contiguous in memory (stable order within a group); its
    arrays are replaced by reordered copies.  The kernel then streams through memory instead of
    jumping between strands.  ``permutation[i]`` is the index, before construction, of the ghost
    now in row ``i`` (identity when the set was already grouped, e.g. when a tracker is rebuilt
    on the same ghosts).  With ``regroup=False`` the rows are left alone and visited through
    ``order``.

    ``parallel``: run the parallel kernel rather than its serial variant (default: by the ghost
    node count, :func:`~hair_tracking.core.kernels.runs_parallel`; the simulator decides
    for the whole scene).
    """

    def __init__(self, ghosts: StrandSet, guides: StrandSet, scene: Scene,
                 collider: Optional[HeadCollider] = None,
                 regroup: bool = True, parallel: Optional[bool] = None,
                 colliders: Optional[ColliderTable] = None):
        tr = scene.tracking
        self.ghosts = ghosts
        self.guides = guides
        self.tracking = tr
        self.collider = collider
        _check_strandset('ghosts', ghosts)
        _check_strandset('guides', guides)
        if guides.count == 0:
            raise ValueError('guides: a ghost tracker needs at least one guide strand')
        # tracking.collide means "collide with the head collider, if the scene has one"
        self.collide = bool(tr.collide and collider is not None)
        if collider is not None and not isinstance(collider, HeadCollider):
            raise ValueError(f'collider: the head row of the collider table (a HeadCollider), '
                             f'got {type(collider).__name__}')
        s_count, n_nodes = ghosts.count, ghosts.nodes
        self.parallel = bool(runs_parallel(s_count * n_nodes) if parallel is None else parallel)

        # -- correspondence (equation (1)) and node correspondence by arc length
        self.guide_of, self.cost = assign_guides(ghosts.rest, guides.rest, tr.candidates)
        seg, t = node_correspondence(ghosts.rest_length, guides.rest_length, self.guide_of)
        self.seg, self.t = seg, t

        # -- groups: ghosts sorted by guide (stable), contiguous
        self.order = np.argsort(self.guide_of, kind='stable').astype(np.int64)
        self.permutation = np.arange(s_count, dtype=np.int64)
        if regroup and np.any(self.order != self.permutation):
            _permute(ghosts, self.order)
            self.permutation = self.order
            self.guide_of = np.ascontiguousarray(self.guide_of[self.order])
            self.cost = np.ascontiguousarray(self.cost[self.order])
            seg = np.ascontiguousarray(seg[self.order])
            t = np.ascontiguousarray(t[self.order])
            self.seg, self.t = seg, t
            self.order = np.arange(s_count, dtype=np.int64)
        sorted_guides = self.guide_of[self.order]
        self.group_guide, first = np.unique(sorted_guides, return_index=True)
        self.group_guide = self.group_guide.astype(np.int64)
        self.group_start = np.append(first, s_count).astype(np.int64)
        n_groups = self.group_guide.size
        group_size = np.diff(self.group_start)

        # -- static per-ghost data, in group order
        o = self.order
        self._gparam = np.ascontiguousarray(seg[o] + t[o])
        g_of = self.guide_of[o][:, None]
        gr = guides.rest
        guide_point_rest = (1.0 - t[o])[..., None] * gr[g_of, seg[o]] + \
            t[o][..., None] * gr[g_of, seg[o] + 1]                      # (S, N, 3) head frame
        ghost_rest = ghosts.rest[o]
        group_of_row = np.repeat(np.arange(n_groups), group_size)
        rest_com = _group_sum(ghost_rest, self.group_start) / \
            np.maximum(group_size, 1)[:, None, None]                     # (K, N, 3)
        dev = ghost_rest - rest_com[group_of_row]
        var0 = _group_sum(np.einsum('snk,snk->sn', dev, dev), self.group_start)
        self._var_target = np.ascontiguousarray(tr.spread_target * var0)
        target_rest = ghost_rest
        if tr.spread > 0.0 and tr.spread_target != 1.0:
            # the offset targets carry the requested spread so (c) does not fight (e)
            target_rest = rest_com[group_of_row] + math.sqrt(tr.spread_target) * dev
            target_rest[:, :2] = ghost_rest[:, :2]
        self._rest_off = np.ascontiguousarray(target_rest - guide_point_rest)   # (S, N, 3)
        # blocks of consecutive groups (the kernel's unit of work and of its per-node layout)
        self.block_group = block_groups(self.group_start)
        self._block_rows = np.ascontiguousarray(self.group_start[self.block_group])
        self._rest_off_blocks = group_blocks(self._rest_off, self._block_rows)
        self._seg_len_blocks = group_blocks(ghosts.rest_length[o], self._block_rows)
        self._root_blocks = group_blocks(ghosts.rest[o][:, :min(2, n_nodes)], self._block_rows)
        w_tip = tip_weights(ghosts.rest_length, tr.tip_weight)[o]      # equation (5)'s w_tip
        # per-node data (guide parameter, w_tip) as a table of distinct rows: ghosts with the
        # same arc-length layout share one row
        table = np.stack([self._gparam, w_tip], axis=-1).reshape(s_count, -1)
        if s_count == 0 or np.array_equal(table, np.broadcast_to(table[0], table.shape)):
            rows, inverse = table[:1], np.zeros(s_count, dtype=np.int64)   # the usual case
        else:
            rows, inverse = np.unique(table, axis=0, return_inverse=True)
        self._node_table = np.ascontiguousarray(rows.reshape(-1, n_nodes, 2))
        self._node_row = np.ascontiguousarray(inverse.reshape(-1).astype(np.int64))
        # the row shared by all ghosts of a group (-1: the group mixes layouts)
        self._group_row = np.full(n_groups, -1, dtype=np.int64)
        for g in range(n_groups):
            r = self._node_row[self.group_start[g]:self.group_start[g + 1]]
            if r.size and np.all(r == r[0]):
                self._group_row[g] = r[0]
        length = ghosts.strand_length[o]
        self._inv_len = np.where(length > 0.0, 1.0 / np.where(length > 0.0, length, 1.0), 0.0)
        self._tan_rest = rest_tangents(gr)
        self._elastic = elastic_code(tr)

        # -- scratch
        n_blocks = self.block_group.size - 1
        chunks = chunk_count(n_blocks, numba.config.NUMBA_NUM_THREADS)
        groups_per_block = int(np.diff(self.block_group).max()) if n_blocks else 1
        self._q_buf = np.empty((chunks, groups_per_block, guides.nodes - 1, 3, 3))
        lanes = int(np.diff(self._block_rows).max()) if n_blocks else 1
        self._buf = np.zeros((chunks, 3 * n_nodes * lanes))
        # the state, in the kernel's layout, and the arrays positions() and velocities() show
        # it in (written out when read after a step)
        self._xb = np.empty(s_count * n_nodes * 3)
        self._vb = np.empty(s_count * n_nodes * 3)
        self._x = np.empty(ghosts.rest.shape)
        self._v = np.empty(ghosts.rest.shape)
        self._synced_x = False        # _x equals the kept positions (no step since)
        self._synced_v = False        # _v equals the kept velocities
        self._tmp = np.zeros((chunks, TMP_ROWS * lanes))
        self._clamped = np.zeros(n_blocks, dtype=np.int64)
        self._contacts = np.zeros(chunks, dtype=np.int64)
        # the head's row runs inside the kernel (h)
        if self.collide:
            self._axes = np.ascontiguousarray(collider.radii + collider.margin)
            self._center = collider.center
            self._friction, self._refine = collider.friction, collider.refine
        else:
            self._axes, self._center = np.ones(3), np.zeros(3)
            self._friction, self._refine = 0.0, 0
        table = colliders if colliders is not None else ColliderTable(scene)
        #: the scene's bust and slot shapes (``None`` without either): stage (i)
        self.body = table.body_for(ghosts)
        self._body_head: Optional[HeadPose] = None      # the head pose of the last step
        self._x_prev = np.empty(ghosts.rest.shape) if self.body is not None else None
        #: the kernel's static data: the fields of
        #: :data:`~hair_tracking.ghosts.kernels.GhostModel` (a plain tuple)
        self.model = tuple(GhostModel(
            ghosts.rest, self._seg_len_blocks, self.order, self.group_start, self.block_group,
            self.group_guide, self._group_row, self._node_table, self._node_row,
            self._rest_off_blocks, self._root_blocks, self._inv_len, self._var_target,
            self._tan_rest))
        #: the kernel's work space and counters: the fields of
        #: :data:`~hair_tracking.ghosts.kernels.TrackWork` (a plain tuple)
        self.work = tuple(TrackWork(self._q_buf, self._buf, self._tmp, self._clamped,
                                    self._contacts))
        self.stats: Dict[str, int] = {
            'ghosts': int(s_count), 'groups': int(n_groups),
            'largest_group': int(group_size.max()) if n_groups else 0,
            'steps': 0, 'clamped': 0, 'contacts': 0, 'parallel': int(self.parallel),
        }
        self.set_state(ghosts.x, ghosts.v)      # the start state

    # ------------------------------------------------------------------ API
    def set_state(self, x: np.ndarray, v: np.ndarray) -> None:
        """Put the ghosts at ``x`` with velocities ``v`` ((S, N, 3) in the ghosts' row order,
        world frame [m], [m/s]); the next step starts from there."""
        shape = self.ghosts.rest.shape
        x, v = np.asarray(x), np.asarray(v)
        if x.shape != shape or v.shape != shape:
            raise ValueError(f'ghost positions and velocities must be shaped {shape}, got '
                             f'{x.shape} and {v.shape}')
        np.copyto(self._x, x)
        np.copyto(self._v, v)
        copy_blocks(self._x, self._v, self.order, self._block_rows, self._xb, self._vb, True,
                    True)
        self._synced_x = self._synced_v = True

    def _write_back(self, with_v: bool = True) -> None:
        """The kept state into ``_x`` (and ``_v`` if ``with_v``), unless they hold it
        already."""
        need_v = with_v and not self._synced_v
        if need_v or not self._synced_x:
            copy_blocks(self._x, self._v, self.order, self._block_rows, self._xb, self._vb,
                        False, need_v)
            self._synced_x = True
            self._synced_v = self._synced_v or need_v

    def positions(self) -> np.ndarray:
        """The ghosts' positions (S, N, 3), world [m], read only: written out of the kernel's
        layout if a step ran since the last read (the positions alone: output needs no
        velocities)."""
        self._write_back(with_v=False)
        view = self._x.view()
        view.flags.writeable = False
        return view

    def velocities(self) -> np.ndarray:
        """The ghosts' velocities (S, N, 3) [m/s], read only (see :meth:`positions`)."""
        self._write_back(with_v=True)
        view = self._v.view()
        view.flags.writeable = False
        return view

    def part_positions(self, part: int, parts: int) -> Tuple[np.ndarray, np.ndarray]:
        """The strands ``S * part // parts .. S * (part + 1) // parts - 1`` and their positions
        (read from :meth:`positions`): ``(strand indices, positions (len, N, 3))``."""
        idx = strand_part(self.ghosts.count, part, parts)
        return idx, self.positions()[idx]

    def write_records(self, words: np.ndarray, stride: int, rot=None, origin=None) -> bool:
        """The ghosts' positions as float32 x y z at the start of ``words``' records (S * N
        of ``stride`` words, ghost ``s``'s node ``j`` at record ``s * N + j``), transformed
        to ``rot (x - origin)`` if given; True when all are finite.  Read straight from the
        kernel's layout, without writing the positions out first."""
        return blocks_to_records(words, stride, self._xb, self.order, self._block_rows,
                                 self.ghosts.rest.shape[1], rot, origin)

    def reset(self, head: HeadPose) -> None:
        """Ghosts in their rest shape carried by ``head``, at rest (out of the bust)."""
        self.set_state(head.to_world(self.ghosts.rest), np.zeros(self.ghosts.rest.shape))
        self._body_head = head
        self._leave_body(head)

    def carry(self, old: HeadPose, new: HeadPose) -> None:
        """The ghosts carried rigidly with the head from ``old`` to ``new``, at rest."""
        self._write_back(with_v=False)
        self._x[...] = carry_rigidly(self._x, old, new)
        self._v[...] = 0.0
        copy_blocks(self._x, self._v, self.order, self._block_rows, self._xb, self._vb, True,
                    True)
        self._synced_v = True
        self._body_head = new
        self._leave_body(new)

    def _leave_body(self, head: HeadPose) -> None:
        """Ghosts placed or carried rigidly with the head, which the bust does not follow,
        moved out of the bust posed at ``head`` as they stand: stage (i) with the bust still
        and no push-out bound, the lengths put back when length restoration is on; at rest
        (as :meth:`~hair_tracking.guides.solver.GuideSolver.leave_body` does for the guides)."""
        if self.body is None:
            return
        self._write_back()
        x = self._x.copy()
        start = x.copy()
        bust = self.body.posed(head, head, 0.0)
        if not collide(x, start, self.ghosts.inv_mass, bust, -1.0, start):
            return
        if self.tracking.length_restore:
            ftl_restore_shapes(x, start, self.ghosts.rest, self.ghosts.rest_length,
                               _f64(head.rotation), bust, np.zeros_like(x), -1.0)
        self.set_state(x, np.zeros_like(x))

    def zero_velocities(self) -> None:
        """The ghosts at rest where they are."""
        self._vb[...] = 0.0
        self._v[...] = 0.0
        self._synced_v = True

    def step(self, motion: TrackStep) -> None:
        """Advance the ghosts by ``motion.dt`` [s] after the guides moved from
        ``motion.guide_x_old`` to ``motion.guide_x`` (both (G, M, 3), world [m]);
        ``motion.head`` is the head pose at the end.

        ``motion.substeps`` > 1 covers that many guide substeps in one tracking step: the
        per-step feedback strengths ``k`` (offset, centre of mass, spread) become
        ``1 - (1 - k)^substeps``, what ``substeps`` separate steps would have applied to a
        constant deviation, so the pull per second does not depend on how often the ghosts are
        tracked."""
        dt, substeps, guide_x_old, gx, head = motion
        if not (dt > 0.0 and math.isfinite(dt)):
            raise ValueError(f'dt must be a finite number > 0 [s], got {dt!r}')
        if guide_x_old is None or guide_x_old.shape != gx.shape or \
                gx.shape != self.guides.rest.shape:
            raise ValueError(f'guide_x_old must be shaped {self.guides.rest.shape} like the '
                             f'guides, got {getattr(guide_x_old, "shape", None)}')
        tr = self.tracking
        if self._x_prev is not None:
            np.copyto(self._x_prev, self.positions())
        # plain tuples in the fields' order of GhostState, GuideMotion and TrackParams
        drive = (_f64(gx), _f64(guide_x_old), _f64(head.rotation), _f64(head.position),
                 1.0 / float(dt))
        params = (self._elastic, tr.tip_weight > 0.0, tr.com_weight, tr.max_weight,
                  _per(tr.offset_strength, substeps), _per(tr.com_strength, substeps),
                  _per(tr.spread, substeps), tr.length_restore, self.collide,
                  self._center, self._axes, self._friction, self._refine)
        kernel = track_groups if self.parallel else track_groups_serial
        kernel(self.model, (self._xb, self._vb), drive, params, self.work)
        self._synced_x = self._synced_v = False
        self.stats['steps'] += 1
        self.stats['clamped'] = int(self._clamped.sum())
        if self.collide:
            self.stats['contacts'] = int(self._contacts.sum())
        if self.body is not None:
            head_contacts = self.stats['contacts'] if self.collide else 0
            self.stats['contacts'] = head_contacts + self._collide_body(dt, head)
        self._body_head = head

    def _collide_body(self, dt: float, head: HeadPose) -> int:
        """Stage (i): the ghosts against the bust posed over the step (``dt`` [s], the head
        from the last step's pose to ``head``), the positions at the step's start
        (``_x_prev``) the friction reference; a pushed node's velocity gains its push less the
        part the push-out bound moved its start by.  Returns the number of nodes pushed."""
        self._write_back()
        x, v = self._x, self._v
        before = self._body_head if self._body_head is not None else head
        bust = self.body.posed(before, head, dt)
        cap = self.body.push_cap(dt)
        placed = x.copy()
        start = self._x_prev.copy()            # moved by the push-out bound
        pushed = int(collide(x, self._x_prev, self.ghosts.inv_mass, bust, cap, start))
        if pushed == 0:
            return 0
        if self.tracking.length_restore:
            ftl_restore_shapes(x, start, self.ghosts.rest, self.ghosts.rest_length,
                               _f64(head.rotation), bust, np.zeros_like(x), cap)
        v += ((x - placed) - (start - self._x_prev)) / dt
        self.set_state(x, v)
        return pushed

    def targets(self, head: HeadPose, guide_x: np.ndarray = None) -> np.ndarray:
        """(S, N, 3) where each ghost node is pulled by the offset feedback (c): its guide point
        plus ``Q`` times its rest offset (world [m], user order; roots: the pinned rest roots).
        ``guide_x`` defaults to the current guides."""
        gx = self.guides.x if guide_x is None else _f64(guide_x)
        frames = guide_frames(gx, self._tan_rest, head.rotation)       # (G, M-1, 3, 3)
        g_of = self.guide_of[self.order][:, None]
        gp = self._gparam
        seg = np.minimum(gp.astype(np.int64), gx.shape[1] - 2)
        t = (gp - seg)[..., None]
        p = (1.0 - t) * gx[g_of, seg] + t * gx[g_of, seg + 1]
        q = p + np.einsum('snab,snb->sna', frames[g_of, seg], self._rest_off)
        out = np.empty_like(q)
        out[self.order] = q
        out[:, :2] = head.to_world(self.ghosts.rest[:, :2])
        return out

    def group_members(self, g: int) -> np.ndarray:
        """Ghost indices of group ``g`` (which follows guide ``group_guide[g]``)."""
        return self.order[self.group_start[g]:self.group_start[g + 1]]


def _per(strength: float, substeps: int) -> float:
    """A per-substep relaxation strength applied over ``substeps`` substeps at once."""
    return strength if substeps <= 1 else 1.0 - (1.0 - strength) ** substeps


def _f64(a):
    return np.ascontiguousarray(a, dtype=np.float64)


def _check_strandset(name, s):
    for field in ('rest', 'x', 'v'):
        a = getattr(s, field)
        if not (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 3 and
                a.shape[2] == 3 and a.flags.c_contiguous):
            raise ValueError(f'{name}.{field} must be a C-contiguous float64 array (S, N, 3)')
    if s.x.shape != s.rest.shape or s.v.shape != s.rest.shape:
        raise ValueError(f'{name}: x, v and rest must have the same shape, got '
                         f'{s.x.shape}, {s.v.shape}, {s.rest.shape}')
    if s.rest.shape[1] < 2:
        raise ValueError(f'{name}: strands need at least 2 nodes, got {s.rest.shape[1]}')
    if s.rest_length.shape != (s.rest.shape[0], s.rest.shape[1] - 1):
        raise ValueError(f'{name}.rest_length must be shaped (S, N-1)')
    if not np.all(np.isfinite(s.rest)):
        raise ValueError(f'{name}.rest contains NaN or infinite coordinates')


def _permute(strands, order):
    """Reorder the strands of a StrandSet (rows ``order``).  The arrays are replaced by reordered
    copies: arrays shared with others (``from_rest`` keeps the caller's rest array) are left
    untouched."""
    for name in ('rest', 'rest_length', 'inv_mass', 'x', 'v'):
        setattr(strands, name, np.ascontiguousarray(getattr(strands, name)[order]))


def _group_sum(a, group_start):
    """Sums of the rows of each (non-empty, contiguous) group."""
    if a.shape[0] == 0:
        return np.zeros((0,) + a.shape[1:])
    return np.add.reduceat(a, group_start[:-1], axis=0)
