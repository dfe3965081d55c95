"""HairSimulator: the one object the node, the bag tools and the evaluation drive.

``push_pose(t, p, q)`` feeds the head track, ``advance_to(t)`` steps a fixed-dt accumulator up to
time ``t`` (integer nanoseconds, so the same inputs give bit-identical outputs), ``frame()``
returns the strands.  The pipeline is assembled from the scene: without a collider no collision
stage exists, without ghosts no tracker exists, without a curve no curve is evaluated.

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
"""
from dataclasses import dataclass, field
import time
from typing import Dict, Optional

import numpy as np

from . import curves
from .collision import make_collider
from .ghosts import GhostTracker
from .groom import make_groom
from .guides import GuideSolver
from .head_track import HeadTrack, IDENTITY, PoseResult
from .metrics import max_stretch
from .model import HeadPose, StrandSet
from .scene import Scene


@dataclass
class Frame:
    """The hair at one instant (world frame unless ``head_frame`` was asked for)."""

    t_ns: int
    head: HeadPose
    guides: np.ndarray                 # (G, Ng, 3)
    ghosts: Optional[np.ndarray]       # (S, Ns, 3) or None when the scene has no ghosts
    curves: Optional[np.ndarray] = None  # (S, P, 3) smoothed output strands, if asked for

    @property
    def strands(self) -> np.ndarray:
        """What is shown as hair: smoothed curves, else ghosts, else the guides themselves."""
        if self.curves is not None:
            return self.curves
        return self.ghosts if self.ghosts is not None else self.guides


@dataclass
class Counters:
    substeps: int = 0
    substeps_dropped: int = 0
    resets: int = 0
    last_advance_ms: float = 0.0
    last_substeps: int = 0
    extra: Dict[str, int] = field(default_factory=dict)


class HairSimulator:
    """Guides + ghosts driven by a head-pose stream, assembled from a :class:`Scene`."""

    def __init__(self, scene: Scene):
        scene.validate()
        self.scene = scene
        self.track = HeadTrack(scene.head_track)
        self.counters = Counters()
        self.time_ns: Optional[int] = None
        self._build()

    # ------------------------------------------------------------- assembly
    def _build(self, head: HeadPose = IDENTITY) -> None:
        scene = self.scene
        groom = make_groom(scene.groom)
        self.guides = StrandSet.from_rest(groom.guide_rest)
        self.collider = make_collider(scene.collider)
        self.guide_solver = GuideSolver(self.guides, scene)
        self.ghosts = None
        self.ghost_tracker = None
        if groom.ghost_rest.shape[0] > 0:
            self.ghosts = StrandSet.from_rest(groom.ghost_rest)
            self.ghost_tracker = GhostTracker(
                self.ghosts, self.guides, scene,
                self.collider if scene.tracking.collide else None)
        self._x_old = np.empty_like(self.guides.x)
        self.dt_ns = max(1, int(round(scene.solver.dt * 1e9)))
        self.head = head
        self._rest_at(head)

    def update_scene(self, scene: Scene) -> bool:
        """Adopt a changed scene; returns True when the hair had to be rebuilt.

        A changed groom (strand counts, nodes, lengths, seed ...) rebuilds the hair in its rest
        shape at the current head pose; anything else keeps the hair where it is.
        """
        scene.validate()
        old, self.scene = self.scene, scene
        self.track.spec = scene.head_track
        if scene.groom != old.groom:
            self._build(self.head)
            return True
        self.collider = make_collider(scene.collider)
        self.guide_solver = GuideSolver(self.guides, scene)
        if self.ghosts is not None:
            if scene.tracking != old.tracking or scene.collider != old.collider:
                self.ghost_tracker = GhostTracker(
                    self.ghosts, self.guides, scene,
                    self.collider if scene.tracking.collide else None, keep_state=True)
        self.dt_ns = max(1, int(round(scene.solver.dt * 1e9)))
        return False

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
        start = time.perf_counter()
        due = (int(t_ns) - self.time_ns) // self.dt_ns
        cap = self.scene.solver.max_substeps
        if due > cap:
            span = int(t_ns) - self.time_ns
            times = [self.time_ns + (span * (k + 1)) // cap for k in range(cap)]
            self.counters.substeps_dropped += int(due - cap)
            self.time_ns = int(t_ns)
        else:
            times = [self.time_ns + self.dt_ns * (k + 1) for k in range(due)]
            self.time_ns += self.dt_ns * int(due)
        dt = self.scene.solver.dt
        for t in times:
            head = self.track.sample(t)
            self._substep(dt, self.head, head)
            self.head = head
        self.counters.substeps += len(times)
        self.counters.last_substeps = len(times)
        self.counters.last_advance_ms = (time.perf_counter() - start) * 1e3
        return len(times)

    def reset(self) -> None:
        """Rest shape at the current head pose, settled; the head track is kept."""
        self._rest_at(self.head)
        self.counters.resets += 1

    # --------------------------------------------------------------- output
    def frame(self, head_frame: bool = False, copy: bool = True) -> Frame:
        g = self.guides.x
        s = self.ghosts.x if self.ghosts is not None else None
        if head_frame:
            g = self.head.to_head(g)
            s = self.head.to_head(s) if s is not None else None
        elif copy:
            g = g.copy()
            s = s.copy() if s is not None else None
        out = self.scene.output
        smooth = None
        if out.curve != 'none':
            src = s if s is not None else g
            smooth = curves.resample(src, out.points_per_strand, out.curve)
        return Frame(t_ns=self.time_ns or 0, head=self.head, guides=g, ghosts=s, curves=smooth)

    def max_stretch(self) -> float:
        """max |l/l0 - 1| over guide and ghost segments (0 = exact lengths)."""
        m = max_stretch(self.guides.x, self.guides.rest_length)
        if self.ghosts is not None:
            m = max(m, max_stretch(self.ghosts.x, self.ghosts.rest_length))
        return m

    def penetration(self) -> float:
        """Deepest hair node inside the head collider [m]; 0 without a collider."""
        if self.collider is None:
            return 0.0
        d = self.collider.penetration(self.guides.x, self.head)
        if self.ghosts is not None:
            d = max(d, self.collider.penetration(self.ghosts.x, self.head))
        return d

    # ------------------------------------------------------------ internals
    def _substep(self, dt: float, head_prev: HeadPose, head: HeadPose) -> None:
        np.copyto(self._x_old, self.guides.x)
        self.guide_solver.step(dt, head_prev, head)
        if self.ghost_tracker is not None:
            self.ghost_tracker.step(dt, self._x_old, head)

    def _rest_at(self, head: HeadPose) -> None:
        self.guide_solver.reset(head)
        if self.ghost_tracker is not None:
            self.ghost_tracker.reset(head)
        for _ in range(int(round(self.scene.solver.settle_time / self.scene.solver.dt))):
            self._substep(self.scene.solver.dt, head, head)
        for strands in (self.guides, self.ghosts):
            if strands is not None:
                strands.v[...] = 0.0

    def _carry_rigidly(self, old: HeadPose, new: HeadPose) -> None:
        """Move all hair with the head from ``old`` to ``new``, at rest (no whip)."""
        rot = new.rotation @ old.rotation.T
        for strands in (self.guides, self.ghosts):
            if strands is not None:
                strands.x[...] = (strands.x - old.position) @ rot.T + new.position
                strands.v[...] = 0.0
