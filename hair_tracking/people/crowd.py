"""Crowd: one hair per person, every person's guides advanced in one compiled call.

Each person is a :class:`~hair_tracking.simulator.HairSimulator` of the same scene, sharing one
built groom: its head track, its ghost tracker, its counters and its outputs are its own.  What
is batched is the guide solver, the stage that steps every substep: the people's guides live
side by side in arrays shaped ``(places, G, N, 3)`` (a person's ``guides.x`` and ``.v`` are views
of its place, :class:`~hair_tracking.guides.solver.HeadBatch`), and one call of
:func:`~hair_tracking.guides.ftl.ftl_advance` (the kernel of one person's guides too, a run
of one head) advances all of them, each through its own head poses (its roots and its head
collider placed by its own head).

Time: the crowd has one fixed-dt accumulator (:func:`~hair_tracking.simulator.substep_times`),
advanced to the newest stamp of any person (:meth:`Crowd.advance_to`); each person's head is
sampled from its own track at the crowd's substep times (held at its newest pose until the next
one arrives).  The split rule of the single head (a substep in which a node would move too far
is split, :mod:`hair_tracking.guides.split`) is applied with the largest estimate over the
people: a substep split for one person is split for all (the others' heads interpolated the
same way).  A solver that batches heads (:meth:`~hair_tracking.guides.solver.GuideSolver.
head_batch`: FTL without the body's bust) is batched; the others and the paper tracker's
every-substep ghost tracking take one solver call per person
(:meth:`~hair_tracking.simulator.HairSimulator.run_substeps`, the single-head code path).

A person added gets fresh hair: the rest shape settled (``solver.settle_time``) and carried to
the first pose, at rest (no jump); a person removed frees the place for the next.
"""
import math
import time
from typing import Callable, Dict, List, Optional

import numpy as np

from hair_tracking.core.head_track import PoseResult
from hair_tracking.core.scene import Scene
from hair_tracking.grooms.build import build_groom
from hair_tracking.core.kernels import runs_parallel
from hair_tracking.guides.split import run_split, split_heads
from hair_tracking.simulator import HairSimulator, substep_times


class CrowdFull(RuntimeError):
    """Every place of the crowd is taken."""


class Crowd:
    """People's hair in one scene (see the module docstring).

    ``places``: most people at once; ``clock()`` [s] times the work (a test injects one).
    ``parallel``: the batched kernel's variant (default: by the node count of all places,
    :func:`~hair_tracking.core.kernels.runs_parallel`).
    """

    def __init__(self, scene: Scene, places: int, clock: Callable[[], float] = time.perf_counter,
                 parallel: Optional[bool] = None):
        scene.validate()
        self.scene = scene
        self.clock = clock
        self.groom = build_groom(scene.groom)
        self._make = lambda: HairSimulator(scene, clock=clock, groom=self.groom)
        first = self._make()
        g = first.guides
        self._free: List[int] = list(range(places - 1, -1, -1))
        self.parallel = runs_parallel(places * g.count * g.nodes) if parallel is None \
            else bool(parallel)
        #: the people's guides side by side, advanced in one call (None where the solver
        #: takes one call a person: :meth:`~hair_tracking.guides.solver.GuideSolver.head_batch`)
        self.batch = first.guide_solver.head_batch(places)
        #: whether the guides of all people advance in one call
        self.batched = self.batch is not None
        #: where the people's guides live, side by side: (places, G, N, 3) positions and
        #: velocities (a person's ``guides.x`` and ``.v`` are views of its place)
        self.x, self.v = (self.batch.x, self.batch.v) if self.batched else \
            (np.zeros((places,) + g.x.shape), np.zeros((places,) + g.x.shape))
        self.people: Dict[str, HairSimulator] = {}
        self._place: Dict[str, int] = {}
        self.time_ns: Optional[int] = None
        self.dt_ns = first.dt_ns
        self.substeps = 0
        self.substeps_dropped = 0

    @property
    def places(self) -> int:
        return self.x.shape[0]

    # ---------------------------------------------------------------- people
    def add(self, key: str, t_ns: int, position, quaternion) -> PoseResult:
        """A new person ``key`` at its first pose: fresh hair, settled and carried there at
        rest.  Raises :class:`CrowdFull` when every place is taken, ``KeyError`` when ``key``
        is there already.  A rejected pose adds nobody."""
        if key in self.people:
            raise KeyError(f'{key} is in the crowd already')
        if not self._free:
            raise CrowdFull(f'all {self.places} places are taken')
        sim = self._make()
        result = sim.push_pose(int(t_ns), position, quaternion)
        if result is PoseResult.REJECTED:
            return result
        place = self._free.pop()
        g = sim.guides
        np.copyto(self.x[place], g.x)
        np.copyto(self.v[place], g.v)
        g.x, g.v = self.x[place], self.v[place]
        self.people[key] = sim
        self._place[key] = place
        if self.time_ns is None:
            self.time_ns = int(t_ns)
        sim.time_ns = self.time_ns
        return result

    def remove(self, key: str) -> None:
        """Person ``key`` and their hair gone (nothing if absent); the place is free."""
        if self.people.pop(key, None) is not None:
            self._free.append(self._place.pop(key))
        if not self.people:
            self.time_ns = None

    def push_pose(self, key: str, t_ns: int, position, quaternion) -> PoseResult:
        """Person ``key``'s next head pose (:meth:`HairSimulator.push_pose`).  A pose older than
        the person's last takes the crowd's clock back to it: every other person's head is held
        where it is from then on."""
        sim = self.people[key]
        result = sim.push_pose(int(t_ns), position, quaternion)
        if result is PoseResult.RESET_BACKWARDS:
            self.time_ns = int(t_ns)
            for other in self.people.values():
                other.time_ns = self.time_ns
                if other is not sim:
                    head = other.track.latest()
                    other.track.clear()
                    other.track.push(self.time_ns, head.position, head.quaternion)
        return result

    # ---------------------------------------------------------------- stepping
    def advance_to(self, t_ns: int) -> int:
        """Step every person's hair up to ``t_ns``; returns the substeps run."""
        if self.time_ns is None or t_ns <= self.time_ns:
            return 0
        keys = list(self.people)
        sims = [self.people[k] for k in keys]
        slots = np.array([self._place[k] for k in keys], dtype=np.int64)
        times, self.time_ns, dropped = substep_times(self.time_ns, t_ns, self.dt_ns,
                                                     self.scene.solver.max_substeps)
        self.substeps_dropped += dropped
        dt = self.scene.solver.dt
        heads = []
        for sim in sims:
            start = sim.clock()
            sim.counters.last_track_ms = 0.0
            sim.begin_tracking()
            heads.append([sim.track.sample(t) for t in times])
            sim.counters.last_advance_ms = (sim.clock() - start) * 1e3
        if times:
            self._run(dt, sims, slots, heads)
        for sim, h in zip(sims, heads):
            start = sim.clock()
            if h:
                sim.head = h[-1]
            sim.time_ns = self.time_ns
            sim.finish_tracking(dt * len(times), len(times))
            c = sim.counters
            c.substeps += len(times)
            c.last_substeps = len(times)
            c.substeps_dropped += dropped
            c.last_advance_ms += (sim.clock() - start) * 1e3
        self.substeps += len(times)
        return len(times)

    def _run(self, dt: float, sims: List[HairSimulator], slots: np.ndarray, heads) -> None:
        """Every person's guides through their ``heads`` (substeps ``dt``): one batched call a
        run of substeps; a substep that any person's split rule splits, split for all."""
        if not self.batched or any(s.tracks_every_substep for s in sims):
            for sim, h in zip(sims, heads):
                sim.run_substeps(dt, sim.head, h)
            return
        rule = sims[0].split_rule
        rigid = np.array([s.split_rule.rigid_run(s.head, h) for s, h in zip(sims, heads)])

        def prev(k):
            return [h[k - 1] for h in heads] if k else [s.head for s in sims]

        def split(k, parts):
            run = [split_heads(p, h[k], parts) for p, h in zip(prev(k), heads)]
            steps, _ = self.batch.advance(dt / parts, slots, prev(k), run, None, self.parallel)
            for s in sims:
                s.note_split(parts)
            for i, s in enumerate(sims):
                s.speed = math.sqrt(steps[i, parts - 1]) * parts / dt

        def run(k):
            steps, done = self.batch.advance(dt, slots, prev(k), [h[k:] for h in heads],
                                             rule.stop(dt, rigid[:, k:]), self.parallel)
            for i, s in enumerate(sims):
                s.speed = math.sqrt(steps[i, done - 1]) / dt
            return done

        run_split(len(heads[0]),
                  lambda k: max(s.split_rule.parts(dt, rigid[i, k], s.speed)
                                for i, s in enumerate(sims)), split, run)


def warm_up(scene: Scene, parallel: bool) -> None:
    """Compile (or load from numba's on-disk cache) the batched kernel's ``parallel`` variant
    for ``scene``'s stages: two people of a tiny copy of the scene, a few substeps."""
    g = scene.groom
    small = scene.with_changes(groom__guides=min(g.guides, 2),
                               groom__ghosts_per_guide=min(g.ghosts_per_guide, 2),
                               groom__file='', solver__settle_time=0.0)
    crowd = Crowd(small, 2, parallel=parallel)
    dt_ns = crowd.dt_ns
    for i, key in enumerate(('a', 'b')):
        crowd.add(key, 1, [0.3 * i, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
        crowd.push_pose(key, 1 + 4 * dt_ns, [0.3 * i + 0.01, 0.0, 0.0],
                        [0.0, 0.0, 0.0871557, 0.9961947])
    crowd.advance_to(1 + 4 * dt_ns)
