"""HairSimulator: the one object the node, the bag tools and the evaluation drive.

``push_pose(t, p, q)`` feeds the head track, ``advance_to(t)`` steps a fixed-dt accumulator up to
time ``t`` (integer nanoseconds, so the same inputs give bit-identical outputs), ``frame()``
returns the strands.  The pipeline is assembled from the scene: without a collider no collision
stage exists, without ghosts no tracker exists, without a curve no curve is evaluated, without
``groom.detail_nodes`` no detail is kept.

Time handling
* Each substep samples the head at its own time (interpolated by :class:`HeadTrack`), moves the
  guides, then lets the ghosts follow.
* At most ``solver.max_substeps`` substeps run per call.  When more are due (a stalled caller, a
  long gap) the remaining ones are *dropped*: the capped substeps still sweep the head through the
  whole interval, so the hair arrives with the head instead of lagging behind or being left inside
  it.
* Time going backwards or a teleport carries the hair rigidly to the new head pose with zero
  velocity (no whip); an explicit :meth:`reset` puts the hair back in its rest shape and lets it
  settle.
* Ghosts are tracked after every guide substep, or - with ``tracking.every_substep: false`` or
  while ``track_once_per_call`` is set (the live node's load shedding) - once per
  ``advance_to`` call (one head pose) over all its substeps, 2-4x cheaper.
* The ghost tracker keeps the ghosts' state
  (:class:`~hair_tracking.ghosts.interface.GhostTracking`); :meth:`frame`,
  :meth:`record_writer`, :meth:`max_stretch`, :meth:`penetration` and :meth:`audit` ask it for
  the ghosts.  The blend and turn trackers place the ghosts there, from their last step, and
  only then: once per output frame however many head poses came in between.
* The guide solver takes the substeps of a pose (or of a whole settle) in one call
  (:meth:`~hair_tracking.guides.solver.GuideSolver.advance`), up to the first that needs
  splitting: a substep in which a hair node would move too far is split into equal shorter
  substeps, the head interpolated between its two poses (the split rule,
  :mod:`hair_tracking.guides.split`, which the solver applies after every substep of a run), so
  the hair is that of the substeps taken one by one; ``counters.extra['split_substeps']``
  counts the extra substeps.

Public loop (what the node, the crowd and the tools drive): the simulator built from a
:class:`~hair_tracking.core.scene.Scene`, :meth:`HairSimulator.push_pose`,
:meth:`~HairSimulator.advance_to` (or one substep: :meth:`~HairSimulator.step`),
:meth:`~HairSimulator.frame`, :meth:`~HairSimulator.reset`, :meth:`~HairSimulator.settle`;
and, for a driver that schedules the guide substeps itself (the crowd,
:mod:`hair_tracking.people.crowd`), :meth:`~HairSimulator.begin_tracking`,
:meth:`~HairSimulator.run_substeps` and :meth:`~HairSimulator.finish_tracking`, the three parts
of one :meth:`~HairSimulator.advance_to`, with :attr:`~HairSimulator.split_rule`,
:attr:`~HairSimulator.speed` and :meth:`~HairSimulator.note_split` for guides it advances in a
batch.
"""
import dataclasses
from dataclasses import dataclass, field
import math
import time
from typing import Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np

from hair_tracking.core import curves
from hair_tracking.core.groom import Groom
from hair_tracking.core.head_track import HeadTrack, IDENTITY, PoseResult
from hair_tracking.core.metrics import max_stretch
from hair_tracking.core.model import carry_rigidly, HeadPose, StrandSet
from hair_tracking.core.point_records import points_to_records
from hair_tracking.core.scene import GUIDES_AMONG_STRANDS, Scene
from hair_tracking.core.settle import settle as settle_until_still
from hair_tracking.ghosts.blend import BlendTracker
from hair_tracking.ghosts.detail import Detail
from hair_tracking.ghosts.interface import GhostTracking, TrackStep
from hair_tracking.ghosts.stateless import choose_guides
from hair_tracking.ghosts.turn import TurnTracker
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.grooms.build import build_groom
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.core.kernels import runs_parallel
from hair_tracking.guides.solver import make_solver
from hair_tracking.guides.split import run_split, split_heads, SplitRule


@dataclass
class Frame:
    """The hair at one instant (world frame unless ``head_frame`` was asked for)."""

    t_ns: int
    head: HeadPose
    guides: np.ndarray                 # (G, Ng, 3)
    ghosts: Optional[np.ndarray]       # (S, Ns, 3) or None when the scene has no ghosts
    curves: Optional[np.ndarray] = None  # (S, P, 3) the groom's detail or smoothed strands

    @property
    def strands(self) -> np.ndarray:
        """What is shown as hair: the ghosts' detail (``groom.detail_nodes``) or smoothed
        curves (``output.curve``), else ghosts, else the guides themselves."""
        if self.curves is not None:
            return self.curves
        return self.ghosts if self.ghosts is not None else self.guides


class Parallelism(NamedTuple):
    """Which variant of their kernels the guide and the ghost stages run: the parallel one
    (True) or the serial one (:func:`~hair_tracking.core.kernels.runs_parallel`)."""

    guides: bool
    ghosts: bool


def parallelism(scene: Scene, groom: Optional[Groom] = None) -> Parallelism:
    """The kernel variants of ``scene``'s stages, from the node counts of its guides and
    ghosts (:func:`~hair_tracking.core.kernels.runs_parallel`): the strand counts of
    ``groom``, the scene's groom already built, when given; else of the procedural groom the
    scene describes, or of the imported one (``groom.file``, read for its strand counts)."""
    g = scene.groom
    if groom is None and g.file:
        groom = build_groom(g)
    if groom is not None:
        (guides, guide_nodes), (ghosts, ghost_nodes) = groom.guide_rest.shape[:2], \
            groom.ghost_rest.shape[:2]
    else:
        guides, ghosts = g.guides, g.guides * g.ghosts_per_guide
        guide_nodes, ghost_nodes = g.guide_nodes, g.ghost_nodes
    among = scene.tracking.mode in GUIDES_AMONG_STRANDS and ghosts > 0
    return Parallelism(runs_parallel(guides * (ghost_nodes if among else guide_nodes)),
                       runs_parallel(ghosts * ghost_nodes))


@dataclass
class Counters:
    substeps: int = 0
    substeps_dropped: int = 0
    resets: int = 0
    last_advance_ms: float = 0.0
    last_track_ms: float = 0.0       # ghost tracking inside the last advance_to
    last_substeps: int = 0
    extra: Dict[str, int] = field(default_factory=dict)


class HairSimulator:
    """Guides + ghosts driven by a head-pose stream, assembled from a :class:`Scene`."""

    def __init__(self, scene: Scene, clock: Callable[[], float] = time.perf_counter,
                 parallel: Optional[Parallelism] = None, groom: Optional[Groom] = None,
                 settled: bool = True):
        """``clock()`` [s] times the work reported in :attr:`counters` (a test injects one);
        ``parallel`` the kernel variants of the stages (default: :func:`parallelism` of the
        scene; :func:`warm_up` runs a tiny scene through the variants of a large one);
        ``groom`` the scene's groom when already built (one hair per person shares it), or
        strands of the caller's own (the evaluation's methods); ``settled``: false leaves the
        hair in its rest shape, not settled, for a driver that settles it its own way
        (:meth:`rest_at`)."""
        scene.validate()
        self.scene = scene
        self.clock = clock
        self._parallel = parallel
        self.track = HeadTrack(scene.head_track)
        self.counters = Counters()
        self.time_ns: Optional[int] = None
        #: Track the ghosts once per advance_to call even when the scene says every substep
        #: (load shedding, set by the live node when it falls behind; see load_shedding.py).
        self.track_once_per_call = False
        #: Place the blend and turn trackers' ghosts from the guides rounded to float32, as a
        #: ghost shard receives them (hair_tracking_msgs/GuideState): set by the node that
        #: publishes the guides' state, so its own ghosts are the shards' to the bit.
        self.guides_as_float32 = False
        self._build(groom=groom, settle=settled)

    # ------------------------------------------------------------- assembly
    def _build(self, head: HeadPose = IDENTITY, groom: Optional[Groom] = None,
               settle: bool = True) -> None:
        """Assemble every stage from the scene (``groom``: the scene's groom, if already
        built), the hair in its rest shape at ``head`` (:meth:`rest_at`)."""
        scene = self.scene
        if groom is None:
            groom = build_groom(scene.groom)
        #: Where the strands came from (an imported groom's report; '' for the procedural one).
        self.groom_note = groom.note
        #: the kernel variants of the guide and ghost stages (:class:`Parallelism`)
        self.parallel = self._parallel if self._parallel is not None else \
            parallelism(scene, groom)
        self.guide_index = None
        if self._stateless(scene) and groom.ghost_rest.shape[0] > 0:
            # the guides are some of the strands themselves (1:1 is full simulation); an
            # imported groom has chosen them by root and shape
            self.guide_index = groom.guide_index if groom.guide_index is not None else \
                choose_guides(groom.ghost_rest[:, 0], scene.groom.guides)
            self.guides = StrandSet.from_rest(groom.ghost_rest[self.guide_index])
        else:
            self.guides = StrandSet.from_rest(groom.guide_rest)
        #: the scene's colliders, one table (its frames set once for every strand set)
        self.colliders = ColliderTable(scene)
        self.guide_solver = make_solver(self.guides, scene, self.parallel.guides, self.colliders)
        self.ghosts = None             # the ghost strands' rest data (state: the tracker's)
        self.ghost_tracker: Optional[GhostTracking] = None
        if groom.ghost_rest.shape[0] > 0:
            self.ghosts = StrandSet.from_rest(groom.ghost_rest)
            self.ghost_tracker = self._make_tracker(scene)
        #: the groom's shape between the ghosts' nodes (``groom.detail_nodes``), or None
        self.detail = None
        if self.ghosts is not None and scene.groom.detail_nodes:
            fine = groom.detail_rest
            self.detail = Detail(self.ghosts.rest, None if fine is None else
                                 fine[self.ghost_tracker.permutation], scene.groom.detail_nodes)
        self._x_old = np.empty_like(self.guides.x)
        self._ghost_guide_x = np.empty_like(self.guides.x)   # guides at the last ghost step
        # farthest any hair node can be from the head origin [m]: root distance + strand length
        reach = [np.linalg.norm(self.guides.rest[:, 0], axis=1) + self.guides.strand_length]
        if self.ghosts is not None:
            reach.append(np.linalg.norm(self.ghosts.rest[:, 0], axis=1) +
                         self.ghosts.strand_length)
        self._reach = float(max(r.max() for r in reach))
        #: the split rule (:class:`~hair_tracking.guides.split.SplitRule`) of this hair
        self.split_rule = self._split_rule(scene)
        #: the largest node speed of the last guide substep [m/s] (the split rule's estimate;
        #: a driver that advances the guides in a batch sets it after each run)
        self.speed = 0.0
        self.dt_ns = max(1, int(round(scene.solver.dt * 1e9)))
        self.rest_at(head, settle)

    def update_scene(self, scene: Scene) -> bool:
        """Adopt a changed scene; returns True when the hair had to be rebuilt.

        A changed groom (strand counts, nodes, lengths, seed, file ...) rebuilds the hair in its
        rest shape at the current head pose; anything else keeps the hair where it is.  A groom
        file that cannot be read raises
        :class:`~hair_tracking.grooms.polylines.GroomFileError` and changes nothing.
        """
        scene.validate()
        if dataclasses.replace(scene, gravity=self.scene.gravity) == self.scene:
            self.set_gravity(scene.gravity)          # gravity alone: a per-step input
            return False
        rebuild = scene.groom != self.scene.groom or \
            scene.tracking.mode != self.scene.tracking.mode
        groom = build_groom(scene.groom) if rebuild else None
        old, self.scene = self.scene, scene
        self.track.spec = scene.head_track
        if rebuild:
            self._build(self.head, groom)
            return True
        table = self._table(scene, old)
        new_table, self.colliders = table is not self.colliders, table
        self.guide_solver = make_solver(self.guides, scene, self.parallel.guides, self.colliders)
        if self.ghosts is not None:
            if scene.tracking != old.tracking or new_table:
                # the new tracker starts where the old one leaves the ghosts
                np.copyto(self.ghosts.x, self.ghost_tracker.positions())
                np.copyto(self.ghosts.v, self.ghost_tracker.velocities())
                self.ghost_tracker = self._make_tracker(scene)
        self.dt_ns = max(1, int(round(scene.solver.dt * 1e9)))
        self.split_rule = self._split_rule(scene)
        return False

    def _table(self, scene: Scene, old: Scene) -> ColliderTable:
        """The collider table of ``scene`` replacing ``old``'s: the same table while the
        scene's colliders are unchanged, else a new one that keeps the frames' poses received
        so far."""
        if scene.collider == old.collider and scene.body == old.body and \
                scene.colliders == old.colliders:
            return self.colliders
        table = ColliderTable(scene)
        table.keep_frames(self.colliders)
        return table

    def set_gravity(self, gravity) -> None:
        """Gravity [m/s^2] (3,) in the fixed frame of the head poses from the next substep on,
        an input of each step like the head pose (``gravity_frame``: the node turns the scene's
        gravity into the pose frame whenever that frame moves): the solver and the split rule
        take it, nothing is rebuilt.  ValueError for anything but three finite numbers (the
        hair is left as it was)."""
        g = np.asarray(gravity, dtype=np.float64)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f'gravity must be three finite numbers [m/s^2], got {gravity!r}')
        self.scene = dataclasses.replace(self.scene, gravity=tuple(float(v) for v in g))
        self.guide_solver.set_gravity(g)
        self.split_rule = self._split_rule(self.scene)

    def _split_rule(self, scene: Scene) -> SplitRule:
        return SplitRule(scene.solver.max_displacement, float(np.linalg.norm(scene.gravity)),
                         self._reach)

    @staticmethod
    def _stateless(scene: Scene) -> bool:
        """Whether the scene's ghost tracker takes its guides among the strands (blend, turn)
        and places every strand once per read, without state."""
        return scene.tracking.mode in GUIDES_AMONG_STRANDS

    def _make_tracker(self, scene: Scene) -> GhostTracking:
        """The scene's ghost tracker, started from ``self.ghosts.x`` and ``.v``."""
        collider = self.colliders.head if scene.tracking.collide else None
        if scene.tracking.mode == 'turn':
            return TurnTracker(self.ghosts, self.guides, self.guide_index, scene, collider,
                               colliders=self.colliders)
        if self._stateless(scene):
            return BlendTracker(self.ghosts, self.guides, self.guide_index, scene, collider,
                                k=scene.tracking.blend_guides, colliders=self.colliders)
        return GhostTracker(self.ghosts, self.guides, scene, collider,
                            parallel=self.parallel.ghosts, colliders=self.colliders)

    # ---------------------------------------------------------------- input
    def push_pose(self, t_ns: int, position, quaternion) -> PoseResult:
        """Feed one head pose.  Rejected poses change nothing (see :class:`HeadTrack`)."""
        result = self.track.push(t_ns, position, quaternion)
        if result is PoseResult.REJECTED:
            return result
        if self.time_ns is None or result.is_reset:
            new_head = self.track.latest()
            self._carry_rigidly(self.head, new_head)
            self.head = new_head
            if self.time_ns is None or result is PoseResult.RESET_BACKWARDS:
                self.time_ns = int(t_ns)
            if result.is_reset:
                self.counters.resets += 1
        return result

    def advance_to(self, t_ns: int) -> int:
        """Step the fixed-dt accumulator up to ``t_ns``; returns the substeps run."""
        if self.time_ns is None or t_ns <= self.time_ns:
            self.counters.last_substeps = 0
            return 0
        start = self.clock()
        times, self.time_ns, dropped = substep_times(self.time_ns, t_ns, self.dt_ns,
                                                     self.scene.solver.max_substeps)
        self.counters.substeps_dropped += dropped
        self.counters.last_track_ms = 0.0
        self.advance_poses([self.track.sample(t) for t in times])
        self.counters.substeps += len(times)
        self.counters.last_substeps = len(times)
        self.counters.last_advance_ms = (self.clock() - start) * 1e3
        return len(times)

    def advance_poses(self, heads: List[HeadPose]) -> None:
        """One substep (``solver.dt``) a pose of ``heads``, from the current head on, the
        ghosts tracked as the scene says; the head is then ``heads[-1]``.  What
        :meth:`advance_to` runs with the poses it samples from the head track, for a driver
        that has the poses itself (the evaluation's methods); the simulator's time and head
        track are not touched."""
        dt = self.scene.solver.dt
        self.begin_tracking()
        if heads:
            self.run_substeps(dt, self.head, heads)
            self.head = heads[-1]
        self.finish_tracking(dt * len(heads), len(heads))

    def set_body_frame(self, rotation, position) -> None:
        """The pose of the scene's ``body.frame`` (rotation (3, 3), origin (3,)) in the fixed
        frame of the head poses: the bust rides on it from the next substep on (kept until the
        next call; without one the bust rides on the neck frame of the head pose)."""
        self.colliders.set_body_frame(rotation, position)

    def set_collider_frame(self, name: str, rotation, position) -> None:
        """The pose of the TF frame ``name`` that a collider slot (``colliders.<slot>.frame``)
        rides on, in the fixed frame of the head poses: its colliders ride on it from the next
        substep on (kept until the next call; before the first one they are off)."""
        self.colliders.set_tf_frame(name, rotation, position)

    def collider_frames(self) -> Tuple[str, ...]:
        """The TF frames the scene's collider slots ride on (``body.frame`` not included)."""
        return self.colliders.tf_frames()

    def colliders_waiting(self) -> List[str]:
        """The slot colliders that are off until their TF frame first arrives."""
        return self.colliders.waiting()

    def reset(self) -> None:
        """Rest shape at the current head pose, settled; the head track is kept."""
        self.rest_at(self.head)
        self.counters.resets += 1

    def rest_at(self, head: HeadPose, settle: bool = True) -> None:
        """The hair in its rest shape carried by ``head`` (out of the body's bust), at rest,
        the head now there; then :meth:`settle` unless ``settle`` is false (a driver that
        settles the hair its own way).  The simulator's time and head track are kept."""
        self.head = head
        self.guide_solver.reset(head)
        self.guide_solver.leave_body(head)
        if self.ghost_tracker is not None:
            self.ghost_tracker.reset(head)
        self.speed = 0.0
        if settle:
            self.settle()

    def settle(self) -> float:
        """Let the hair come to rest where it is, the head still at its current pose:
        ``solver.settle_time``, then, with ``solver.settle_speed``, on until no node moves
        faster than that (:func:`hair_tracking.core.settle.settle`), the ghosts tracked as the
        scene says; the simulator's time and head track are kept.  The velocities are then zero
        (FTL's stored velocities do not vanish at rest, :mod:`hair_tracking.guides.ftl`:
        zeroing them sets still FTL hair moving by a few millimetres, which settles again).
        Returns the time simulated [s], also kept as ``settled_s``."""
        head = self.head
        once, self.track_once_per_call = self.track_once_per_call, False   # the scene's rest
        sv = self.scene.solver
        try:
            self.settled_s = settle_until_still(
                lambda steps: self.advance_poses([head] * steps), self._settling_nodes, sv.dt,
                sv.settle_time, sv.settle_speed)
        finally:
            self.track_once_per_call = once
        self.zero_velocities()
        return self.settled_s

    def zero_velocities(self) -> None:
        """The hair at rest where it is: the guides' and the ghosts' velocities zero."""
        self.guides.v[...] = 0.0
        if self.ghost_tracker is not None:
            self.ghost_tracker.zero_velocities()
        self.speed = 0.0

    def step(self) -> int:
        """One substep (``solver.dt``) on from the simulator's time, the head sampled from its
        track as :meth:`advance_to` samples it; returns the substeps run (0 before the first
        pose)."""
        if self.time_ns is None:
            return 0
        return self.advance_to(self.time_ns + self.dt_ns)

    # -------------------------------------------------------------- substeps
    def run_substeps(self, dt: float, head_prev: HeadPose, heads: List[HeadPose]) -> None:
        """The guide substeps ``dt`` from ``head_prev`` through ``heads`` under the split rule
        (:func:`~hair_tracking.guides.split.run_split`), the ghosts tracked after each when
        :attr:`tracks_every_substep`: the guide solver takes them in one call up to the first
        that needs splitting (it applies the rule after every substep:
        :meth:`~hair_tracking.guides.solver.GuideSolver.advance`'s ``stop``), so exactly as if
        they were taken one by one.  Between :meth:`begin_tracking` and
        :meth:`finish_tracking`."""
        every = self.tracks_every_substep
        rule = self.split_rule
        rigid = rule.rigid_run(head_prev, heads)

        def prev(k):
            return heads[k - 1] if k else head_prev

        def run(k):
            if every:
                self._substep(dt, prev(k), heads[k], 1)
                return 1
            steps = self.guide_solver.advance(dt, prev(k), heads[k:], measure=True,
                                              stop=rule.stop(dt, rigid[k:]))
            self.speed = math.sqrt(steps[-1]) / dt
            return len(steps)

        run_split(len(heads), lambda k: rule.parts(dt, rigid[k], self.speed),
                  lambda k, parts: self._substep(dt, prev(k), heads[k], parts), run)

    def note_split(self, parts: int) -> None:
        """Count a substep split into ``parts`` parts (``counters.extra['split_substeps']``)."""
        self.counters.extra['split_substeps'] = \
            self.counters.extra.get('split_substeps', 0) + parts - 1

    # --------------------------------------------------------------- output
    def frame(self, head_frame: bool = False, copy: bool = True) -> Frame:
        """The hair now; with ``copy`` false the arrays may be read-only views of the state."""
        g = self.guides.x
        s = self._ghost_positions()
        if head_frame:
            g = self.head.to_head(g)
            s = self.head.to_head(s) if s is not None else None
        elif copy:
            g = g.copy()
            s = s.astype(np.float64) if s is not None else None
        out = self.scene.output
        smooth = None
        if self.detail is not None:
            smooth = self.detail.carry(s, np.eye(3) if head_frame else self.head.rotation)
        elif out.curve != 'none':
            src = s if s is not None else g
            smooth = curves.resample(src, out.points_per_strand, out.curve)
        return Frame(t_ns=self.time_ns or 0, head=self.head, guides=g, ghosts=s, curves=smooth)

    def strand_positions(self) -> np.ndarray:
        """The simulated strands a :meth:`frame` is made of (the ghosts, or the guides without
        ghosts; before any output curve) as they are now, world frame [m], without making a
        frame: a view of the state, valid until the next step (read only for the ghosts).  The
        ghosts come in the tracker's order (``ghost_tracker.permutation`` where the paper
        tracker grouped them)."""
        s = self._ghost_positions()
        return self.guides.x if s is None else s

    def strand_count(self, guides: bool = False) -> int:
        """How many strands a :meth:`frame` shows (``frame.strands``; ``frame.guides`` with
        ``guides``), without making the frame."""
        if guides or self.ghosts is None:
            return self.guides.count
        return self.ghosts.count

    def record_writer(self, guides: bool = False, head_frame: bool = False,
                      rows: Optional[np.ndarray] = None):
        """``(S, N, write)`` for an output format with one record per point: the shape of the
        strands a :meth:`frame` shows (``frame.strands``; ``frame.guides`` with ``guides``)
        and ``write(words, stride) -> bool``, which puts their positions now as float32 x y z
        at the start of ``words``' S * N records of ``stride`` float32 words (strand ``s``'s
        point ``j`` at record ``s * N + j``; in the head frame with ``head_frame``) and says
        whether all are finite (:mod:`~hair_tracking.core.point_records`).  The ghosts are read
        straight from the tracker's layout, without the write-back a frame makes.  ``rows``:
        those strands only (an index array; S is then its length)."""
        rot = origin = None
        if head_frame:
            rot, origin = self.head.rotation.T, self.head.position
        tracker = self.ghost_tracker
        if rows is None and not guides and tracker is not None and self.detail is None and \
                self.scene.output.curve == 'none':
            s, n = self.ghosts.rest.shape[:2]
            return s, n, lambda words, stride: tracker.write_records(words, stride, rot, origin)
        # the guides as a frame holds them, without the frame's write-back of the ghosts
        if guides:
            x = self.guides.x
        elif self.detail is not None:               # the detail of those strands alone
            x = self.detail.carry(self._ghost_positions(), self.head.rotation, rows)
            rows = None
        else:
            x = self.frame(copy=False).strands
        if rows is not None:
            x = x[rows]
        return x.shape[0], x.shape[1], \
            lambda words, stride: points_to_records(words, stride, x, rot, origin)

    def max_stretch(self) -> float:
        """max |l/l0 - 1| over guide and ghost segments (0 = exact lengths; NaN when a segment
        has a NaN length)."""
        m = max_stretch(self.guides.x, self.guides.rest_length)
        if self.ghosts is not None:
            m = _worst(m, max_stretch(self._ghost_positions(), self.ghosts.rest_length))
        return m

    def penetration(self) -> float:
        """Deepest hair node inside the head collider or the body's bust [m]; 0 without
        either."""
        d = self._depth(self.guides.x, self.guides.inv_mass, self.parallel.guides)
        if self.ghosts is not None:
            d = max(d, self._depth(self._ghost_positions(), None, self.parallel.ghosts))
        return d

    def _depth(self, x, inv_mass, parallel) -> float:
        """Deepest node of ``x`` inside the head collider (all nodes) or the bust (the free
        nodes when ``inv_mass`` is given)."""
        head = self.colliders.head
        d = 0.0 if head is None else head.penetration(x, self.head, parallel=parallel)
        return max(d, self.colliders.body_depth(x, self.head, inv_mass))

    def audit(self, part: int = 0, parts: int = 1) -> Tuple[float, float, np.ndarray]:
        """:meth:`max_stretch` and :meth:`penetration` over the guides and part ``part`` of
        ``parts`` of the ghost strands (:func:`~hair_tracking.core.model.strand_part`; a
        stateless tracker places those strands alone from its last step, so checking 1 / parts
        of the hair costs about 1 / parts of a whole check).  Returns ``(stretch, depth [m],
        the ghost strands checked)``; ``parts`` = 1 is the whole hair."""
        stretch = max_stretch(self.guides.x, self.guides.rest_length)
        depth = self._depth(self.guides.x, self.guides.inv_mass, self.parallel.guides)
        if self.ghost_tracker is None:
            return stretch, depth, np.zeros(0, dtype=np.int64)
        idx, x = self.ghost_tracker.part_positions(part, parts)
        stretch = _worst(stretch, max_stretch(x, self.ghosts.rest_length[idx]))
        if idx.size:
            depth = max(depth, self._depth(x, None, self.parallel.ghosts))
        return stretch, depth, idx

    # ------------------------------------------------------------ internals
    def _ghost_positions(self) -> Optional[np.ndarray]:
        """The ghost positions now, from the tracker (which places them here if it defers
        placing to the read: the blend and turn trackers), or None without ghosts."""
        if self.ghost_tracker is None:
            return None
        return self.ghost_tracker.positions()

    def _substep(self, dt: float, head_prev: HeadPose, head: HeadPose, parts: int) -> None:
        """One substep split into ``parts`` parts (the split rule's, at least one)."""
        if parts == 1:
            self._step(dt, head_prev, (head,))
            return
        self.note_split(parts)
        self._step(dt / parts, head_prev, split_heads(head_prev, head, parts))

    def _step(self, dt: float, head_prev: HeadPose, heads) -> None:
        """Substeps ``dt`` through ``heads`` (the parts of one split substep, or one), each
        followed by the ghosts when they are tracked every substep."""
        if not self.tracks_every_substep:
            steps = self.guide_solver.advance(dt, head_prev, heads, measure=True)
        else:
            for head in heads:
                np.copyto(self._x_old, self.guides.x)
                steps = self.guide_solver.advance(dt, head_prev, (head,), measure=True)
                start = self.clock()
                self.ghost_tracker.step(TrackStep(dt, 1, self._x_old, self.guides.x, head))
                self.counters.last_track_ms += (self.clock() - start) * 1e3
                head_prev = head
        self.speed = math.sqrt(steps[-1]) / dt

    # Ghost tracking schedule.  With ``tracking.every_substep: false`` the ghosts are tracked
    # once per advance_to() call (one head pose), over all the guide substeps of that call, with
    # the per-substep feedback strengths compounded (GhostTracker.step's ``substeps``): at
    # 240 Hz substeps and a 60 Hz pose stream, 4x fewer tracking steps (see docs/ghosts.md for
    # its stability on long strands).
    def _every_substep(self) -> bool:
        return self.scene.tracking.every_substep and not self.track_once_per_call \
            and not self._stateless(self.scene)

    @property
    def tracks_every_substep(self) -> bool:
        """Whether the ghosts are tracked after every guide substep (by :meth:`run_substeps`)
        rather than once a pose (by :meth:`finish_tracking`)."""
        return self.ghost_tracker is not None and self._every_substep()

    def begin_tracking(self) -> None:
        """Start a pose's ghost tracking: keep the guides where the paper's once-per-call
        tracking step starts from (the blend and turn trackers place the ghosts from the guides
        at the end alone).  Before the pose's :meth:`run_substeps`."""
        if self.ghost_tracker is not None and not self._every_substep() and \
                not self._stateless(self.scene):
            np.copyto(self._ghost_guide_x, self.guides.x)

    def finish_tracking(self, dt: float, substeps: int) -> None:
        """End a pose's ghost tracking: ``substeps`` guide substeps over ``dt`` [s] were taken
        since :meth:`begin_tracking`; the ghosts tracked once over all of them (nothing when
        they were tracked every substep)."""
        if self.ghost_tracker is None or self._every_substep() or substeps == 0:
            return
        start = self.clock()
        start_x = None if self._stateless(self.scene) else self._ghost_guide_x
        guide_x = self.guides.x
        if self.guides_as_float32 and start_x is None:
            guide_x = guide_x.astype(np.float32).astype(np.float64)
        self.ghost_tracker.step(TrackStep(dt, substeps, start_x, guide_x, self.head))
        self.counters.last_track_ms += (self.clock() - start) * 1e3

    def _settling_nodes(self):
        """The positions that settle: the guides, and the paper tracker's ghosts (the blend and
        turn trackers place theirs from the guides)."""
        out = [self.guides.x]
        if self.ghost_tracker is not None and not self._stateless(self.scene):
            out.append(self.ghost_tracker.positions())
        return out

    def _carry_rigidly(self, old: HeadPose, new: HeadPose) -> None:
        """Move all hair with the head from ``old`` to ``new``, at rest (no whip), and out of
        the body's bust, which does not move with the head."""
        self.guides.x[...] = carry_rigidly(self.guides.x, old, new)
        self.guide_solver.leave_body(new)
        self.guides.v[...] = 0.0
        if self.ghost_tracker is not None:
            self.ghost_tracker.carry(old, new)
        self.speed = 0.0


def substep_times(time_ns: int, t_ns: int, dt_ns: int, cap: int):
    """``(times, new time, dropped)``: the ends of the substeps that take the fixed-dt
    accumulator at ``time_ns`` towards ``t_ns`` [ns], at most ``cap`` of them (more due: ``cap``
    substeps spread over the whole interval, the rest dropped, the accumulator at ``t_ns``)."""
    due = (int(t_ns) - time_ns) // dt_ns
    if due > cap:
        span = int(t_ns) - time_ns
        return [time_ns + (span * (k + 1)) // cap for k in range(cap)], int(t_ns), int(due - cap)
    return [time_ns + dt_ns * (k + 1) for k in range(due)], time_ns + dt_ns * int(due), 0


def _worst(a: float, b: float) -> float:
    """The larger of two checks' values, NaN if either is NaN (``max`` keeps its first
    argument when the other is NaN, which would hide broken hair)."""
    return math.nan if math.isnan(a) or math.isnan(b) else max(a, b)


def warm_up(scene: Scene, parallel: Optional[Parallelism] = None) -> HairSimulator:
    """Compile (or load from numba's on-disk cache) every kernel ``scene`` uses.

    Runs a tiny copy of the scene (same solver, collider, tracking and output options and
    node counts, at most two guides with two ghosts each, a procedural groom: an imported one
    is read for its strand counts only) through a moving, turning head and the stretch and
    penetration checks, so the first real steps are not late: every stage through the variant,
    serial or parallel, that the full scene will run (:func:`parallelism` of ``scene``, handed
    to the tiny copy; ``parallel``: those of a simulator of ``scene`` already built, so an
    imported groom is not read again), and only that one.  Returns the tiny simulator (callers
    may warm their own output code on its frames).
    """
    g = scene.groom
    small = scene.with_changes(groom__guides=min(g.guides, 2),
                               groom__ghosts_per_guide=min(g.ghosts_per_guide, 2),
                               groom__file='', solver__settle_time=0.0)
    sim = HairSimulator(small, parallel=parallel if parallel is not None else
                        parallelism(scene))
    dt_ns = max(1, int(round(small.solver.dt * 1e9)))
    sim.push_pose(1, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    sim.push_pose(1 + 4 * dt_ns, [0.01, 0.0, 0.0], [0.0, 0.0, 0.0871557, 0.9961947])
    sim.advance_to(1 + 4 * dt_ns)
    sim.max_stretch()
    sim.penetration()
    sim.frame()                     # the output curves and the groom's detail, if asked for
    return sim
