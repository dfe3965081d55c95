"""The methods compared by the accuracy evaluation, behind one small interface.

Every method produces the positions of the *same* ghost strands (the workload's ``ghost_rest``,
head frame) node for node, so its output can be compared with the reference:

* :class:`FullSim` -- every ghost strand simulated as a guide by
  :class:`~hair_tracking.guides.solver.GuideSolver` (PBD, XPBD or FTL at the scene's settings).
  With a fine step, many iterations and XPBD at compliance 0 this is the reference.
* :class:`GhostTracking` -- the method of the package (Park & Kim): ``S / ratio`` guides made by
  :func:`~hair_tracking.core.groom.make_groom` (as :class:`~hair_tracking.simulator.HairSimulator`
  makes them) simulated by :class:`~hair_tracking.guides.solver.GuideSolver`, the ghosts moved by
  :class:`~hair_tracking.ghosts.tracker.GhostTracker` each substep
  (or once per output frame over all its substeps with ``tracking.every_substep: false``, as the
  simulator does once per pose).
* :class:`BlendTracking` -- the blend tracker: guides chosen among the strands, every strand the
  skinned blend of its nearest guides once per output frame.
* :class:`TurnTracking` -- the turn tracker: as the blend, every strand's segments turned as its
  nearest guide's segments turned.
* :class:`RigidOffset` -- the game-engine "follow hair" baseline: a ghost node is its guide's
  point at the same arc-length fraction plus the node's rest offset from that point rotated with
  the head (AMD TressFX follow hairs use an unrotated offset; rotating it with the head is the
  fair variant).  Only evaluated when a frame is output.
* :class:`PyPBD` -- the peer library: Jan Bender's PositionBasedDynamics (PyPI ``pypbd``)
  simulating every ghost strand with the same particles and constraints as the package's PBD
  solver (distance constraints of stiffness 1 between neighbours, second-neighbour distance
  constraints of stiffness ``solver.bend_stiffness``; Müller et al. 2007).  pypbd's gravity is
  fixed at ``(0, -9.81, 0)``, so it simulates in a frame with y up (:data:`PYPBD_FROM_WORLD`);
  it has no head collider and no velocity damping here, and its roots are placed through one
  Python call per root node per substep (that time goes to :attr:`Method.excluded_seconds` and
  is kept out of its timing: it measures the binding, not the library).

The interface: ``reset(head)`` puts the hair in its rest shape at ``head``, at rest;
``step(dt, head_prev, head)`` advances one substep of ``dt`` seconds while the head moves from
``head_prev`` to ``head``; ``advance(dt, head_prev, heads)`` advances one substep a pose of
``heads`` (a frame's substeps; the guide solver's one compiled call,
:meth:`~hair_tracking.guides.solver.GuideSolver.advance`, where the method allows it: the
same engineering for every method); ``output(head)`` returns the ghost positions (S, N, 3),
world frame [m], at the end of the frame (a view that stays valid until the next ``step``);
``zero_velocities()`` puts the hair at rest where it is.
"""
from dataclasses import dataclass, field, replace
from typing import Dict

import numpy as np

from hair_tracking.core.groom import make_groom
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts.blend import BlendTracker
from hair_tracking.ghosts.stateless import choose_guides
from hair_tracking.ghosts.turn import TurnTracker
from hair_tracking.ghosts.correspondence import assign_guides, node_correspondence
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.guides.solver import make_solver

#: Ghosts per guide of the fixed grouping used for the spread metric (the default groom's ratio
#: is 1:8; 1:16 groups are large enough for a meaningful variance).
SPREAD_GROUP = 16

#: World (z up) -> pypbd frame (y up, gravity -y): ``p_pbd = PYPBD_FROM_WORLD @ p_world``.
PYPBD_FROM_WORLD = np.array([[1.0, 0.0, 0.0],
                             [0.0, 0.0, 1.0],
                             [0.0, -1.0, 0.0]])


@dataclass
class Workload:
    """What every method simulates: the base scene and the ghost strands (head frame)."""

    scene: Scene
    ghost_rest: np.ndarray            # (S, N, 3) head frame [m]
    groups: np.ndarray                # (S,) fixed group of each ghost (spread metric)
    rest_length: np.ndarray = field(init=False)
    strand_length: np.ndarray = field(init=False)
    inv_mass: np.ndarray = field(init=False)

    def __post_init__(self):
        s = StrandSet.from_rest(self.ghost_rest)
        self.ghost_rest = s.rest
        self.rest_length = s.rest_length
        self.strand_length = s.strand_length
        self.inv_mass = s.inv_mass

    @property
    def count(self) -> int:
        return self.ghost_rest.shape[0]

    def guide_rest(self, ratio: int) -> np.ndarray:
        """Rest shapes (G, M, 3) of ``count // ratio`` guides grown by the groom generator on the
        same scalp, with the scene's lengths and node count (as the simulator grows them)."""
        if ratio < 1 or self.count // ratio < 1:
            raise ValueError(f'ratio: 1:{ratio} leaves no guide for {self.count} ghosts')
        spec = replace(self.scene.groom, guides=self.count // ratio, ghosts_per_guide=0)
        return make_groom(spec).guide_rest


def make_workload(scene: Scene, ghosts: int) -> Workload:
    """The ghost strands of ``scene``'s groom with ``ghosts`` strands in all (rounded down to a
    multiple of 16), and their fixed grouping: each ghost belongs to the guide of a 1:16 groom
    that equation (1) assigns it to."""
    if ghosts < SPREAD_GROUP:
        raise ValueError(f'ghosts: need at least {SPREAD_GROUP} ghost strands, got {ghosts}')
    k = ghosts // SPREAD_GROUP
    spec = replace(scene.groom, guides=k, ghosts_per_guide=SPREAD_GROUP)
    groom = make_groom(spec)
    groups, _ = assign_guides(groom.ghost_rest, groom.guide_rest, scene.tracking.candidates)
    return Workload(scene, groom.ghost_rest, np.asarray(groups, dtype=np.int64))


class Method:
    """Base class; see the module docstring for the interface."""

    family = 'method'

    def __init__(self, name: str, workload: Workload, scene: Scene, knobs: Dict):
        self.name = name
        self.workload = workload
        self.scene = scene
        self.knobs = dict(knobs)
        self.dt = float(scene.solver.dt)
        self.note = ''
        #: seconds spent in work that is not the method's own (kept out of its timing)
        self.excluded_seconds = 0.0

    def reset(self, head: HeadPose) -> None:
        raise NotImplementedError

    def step(self, dt: float, head_prev: HeadPose, head: HeadPose) -> None:
        raise NotImplementedError

    def advance(self, dt: float, head_prev: HeadPose, heads) -> None:
        """One :meth:`step` a pose of ``heads``, the first from ``head_prev``."""
        for head in heads:
            self.step(dt, head_prev, head)
            head_prev = head

    def output(self, head: HeadPose) -> np.ndarray:
        raise NotImplementedError

    def zero_velocities(self) -> None:
        """The hair at rest where it is (a method that keeps no velocities has nothing to
        do)."""

    def close(self) -> None:
        """Release external resources (pypbd)."""


class _Solved(Method):
    """A method whose strands the scene's guide solver ``self.solver`` advances."""

    def reset(self, head):
        self.solver.reset(head)

    def step(self, dt, head_prev, head):
        self.solver.step(dt, head_prev, head)

    def advance(self, dt, head_prev, heads):
        self.solver.advance(dt, head_prev, heads)


class FullSim(_Solved):
    """All ghost strands simulated as guides (the reference at high fidelity)."""

    family = 'full'

    def __init__(self, name, workload, scene, knobs=None):
        super().__init__(name, workload, scene, knobs or {})
        self.strands = StrandSet.from_rest(workload.ghost_rest)
        self.solver = make_solver(self.strands, scene)

    def output(self, head):
        return self.strands.x

    def zero_velocities(self):
        self.strands.v[...] = 0.0


class _GuidedMethod(_Solved):
    """Shared: guides grown at a ratio and simulated by the scene's solver."""

    def __init__(self, name, workload, scene, ratio, knobs):
        super().__init__(name, workload, scene, knobs)
        self.ratio = int(ratio)
        self.guides = StrandSet.from_rest(workload.guide_rest(self.ratio))
        self.solver = make_solver(self.guides, scene)


class GhostTracking(_GuidedMethod):
    """Guides simulated, ghosts tracked by :class:`~hair_tracking.ghosts.tracker.GhostTracker`
    (the package)."""

    family = 'ghost'

    def __init__(self, name, workload, scene, ratio, knobs=None):
        super().__init__(name, workload, scene, ratio, knobs or {})
        self.ghosts = StrandSet.from_rest(workload.ghost_rest)
        table = self.solver.colliders
        collider = table.head if scene.tracking.collide else None
        self.tracker = GhostTracker(self.ghosts, self.guides, scene, collider, colliders=table)
        self._x_old = np.empty_like(self.guides.x)
        self.every_substep = bool(getattr(scene.tracking, 'every_substep', True))
        self._pending = 0
        # the tracker may store the ghosts grouped by guide: row i is the user's ghost perm[i]
        perm = getattr(self.tracker, 'permutation', None)
        self._perm = None
        if perm is not None and np.any(np.asarray(perm) != np.arange(len(perm))):
            self._perm = np.asarray(perm, dtype=np.int64)
            self._out = np.empty_like(workload.ghost_rest)

    def reset(self, head):
        self.solver.reset(head)
        self.tracker.reset(head)
        self._pending = 0
        np.copyto(self._x_old, self.guides.x)

    def step(self, dt, head_prev, head):
        if self.every_substep:
            np.copyto(self._x_old, self.guides.x)
            self.solver.step(dt, head_prev, head)
            self.tracker.step(TrackStep(dt, 1, self._x_old, self.guides.x, head))
        else:           # tracked once per output frame, over all its substeps (simulator's way)
            self.solver.step(dt, head_prev, head)
            self._pending += 1

    def advance(self, dt, head_prev, heads):
        if self.every_substep:          # a step a pose, the ghosts tracked in each
            Method.advance(self, dt, head_prev, heads)
        else:
            self.solver.advance(dt, head_prev, heads)
            self._pending += len(heads)

    def output(self, head):
        if self._pending:
            self.tracker.step(TrackStep(self._pending * self.dt, self._pending, self._x_old,
                                        self.guides.x, head))
            self._pending = 0
            np.copyto(self._x_old, self.guides.x)
        if self._perm is None:
            return self.tracker.positions()
        self._out[self._perm] = self.tracker.positions()
        return self._out

    def zero_velocities(self):
        self.tracker.zero_velocities()


class BlendTracking(_Solved):
    """Guides chosen among the strands (``S / ratio`` of them, :func:`choose_guides`) simulated
    by the scene's solver; every strand blended from its ``k`` nearest guides once per output
    frame (:class:`~hair_tracking.ghosts.blend.BlendTracker`).  At 1:1 this is :class:`FullSim`.
    """

    family = 'blend'

    def __init__(self, name, workload, scene, ratio, knobs=None, k: int = 3):
        super().__init__(name, workload, scene, knobs or {})
        self.ratio = int(ratio)
        count = workload.count // self.ratio
        if count < 1:
            raise ValueError(f'ratio: 1:{ratio} leaves no guide for {workload.count} strands')
        self.guide_index = choose_guides(workload.ghost_rest[:, 0], count)
        self.guides = StrandSet.from_rest(workload.ghost_rest[self.guide_index])
        table = ColliderTable(scene)
        self.solver = make_solver(self.guides, scene, colliders=table)
        self.ghosts = StrandSet.from_rest(workload.ghost_rest)
        collider = table.head if scene.tracking.collide else None
        self.tracker = self._tracker(scene, collider, k, table)

    def _tracker(self, scene, collider, k, table):
        return BlendTracker(self.ghosts, self.guides, self.guide_index, scene, collider, k=k,
                            colliders=table)

    def reset(self, head):
        super().reset(head)
        self.tracker.reset(head)

    def output(self, head):
        # the blend and turn trackers place the strands from the guides now and the head
        self.tracker.step(TrackStep(self.dt, 1, None, self.guides.x, head))
        return self.tracker.positions()


class TurnTracking(BlendTracking):
    """As :class:`BlendTracking`, every strand placed by the turn tracker
    (:class:`~hair_tracking.ghosts.turn.TurnTracker`): its segments turned as the matching
    segments of the guide with the nearest root.  At 1:1 this is :class:`FullSim`."""

    family = 'turn'

    def _tracker(self, scene, collider, k, table):
        return TurnTracker(self.ghosts, self.guides, self.guide_index, scene, collider,
                           colliders=table)


class RigidOffset(_GuidedMethod):
    """Ghost = guide point at the same arc-length fraction + rest offset rotated with the head."""

    family = 'rigid'

    def __init__(self, name, workload, scene, ratio, knobs=None):
        super().__init__(name, workload, scene, ratio, knobs or {})
        gr = self.guides.rest
        guide_of, _ = assign_guides(workload.ghost_rest, gr, scene.tracking.candidates)
        seg, t = node_correspondence(workload.rest_length, self.guides.rest_length, guide_of)
        self._g = np.asarray(guide_of, dtype=np.int64)[:, None]
        self._seg = seg
        self._t = t[..., None]
        point_rest = (1.0 - self._t) * gr[self._g, seg] + self._t * gr[self._g, seg + 1]
        self._offset = np.ascontiguousarray(workload.ghost_rest - point_rest)   # head frame
        self._out = np.empty_like(workload.ghost_rest)

    def output(self, head):
        gx = self.guides.x
        p = (1.0 - self._t) * gx[self._g, self._seg] + self._t * gx[self._g, self._seg + 1]
        np.add(p, self._offset @ head.rotation.T, out=self._out)
        return self._out


def pypbd_available() -> str:
    """'' if pypbd imports, else the reason (shown in the report)."""
    try:
        import pypbd  # noqa: F401
    except ImportError as e:         # pragma: no cover - depends on the environment
        return f'pypbd is not installed ({e}); `pip install pypbd` adds the peer'
    return ''


class PyPBD(Method):
    """The peer: pypbd (Bender's PositionBasedDynamics) simulating every ghost strand.

    Only one instance may exist at a time (pypbd keeps one global simulation); ``close()``
    releases it.  ``scene.solver.iterations`` iterations, one pypbd step per substep.
    """

    family = 'pypbd'
    _live = False

    def __init__(self, name, workload, scene, knobs=None):
        super().__init__(name, workload, scene, knobs or {})
        if PyPBD._live:
            raise RuntimeError('only one PyPBD method can be alive at a time; close() it')
        import pypbd
        g = np.asarray(scene.gravity, dtype=np.float64)
        if not np.allclose(g, (0.0, 0.0, -9.81)):
            raise ValueError(f'pypbd runs with its fixed gravity 9.81 m/s^2; scene gravity {g} '
                             'differs')
        self._pbd = pypbd
        sim = pypbd.Simulation.getCurrent()
        sim.initDefault()
        self._model = sim.getModel()
        self._ts = sim.getTimeStep()
        self._ts.setValueUInt(pypbd.TimeStepController.NUM_SUB_STEPS, 1)
        self._ts.setValueUInt(pypbd.TimeStepController.MAX_ITERATIONS,
                              int(scene.solver.iterations))
        pd = self._model.getParticles()
        self._pd = pd
        s, n, _ = workload.ghost_rest.shape
        self._shape = (s, n)
        for p in workload.ghost_rest.reshape(-1, 3):
            pd.addVertex(p.tolist())
        stiff, bend = float(scene.solver.stiffness), float(scene.solver.bend_stiffness)
        for i in range(s):
            b = i * n
            pd.setMass(b, 0.0)
            pd.setMass(b + 1, 0.0)
            for k in range(n - 1):
                self._model.addDistanceConstraint(b + k, b + k + 1, stiff)
            if bend > 0.0:
                for k in range(n - 2):
                    self._model.addDistanceConstraint(b + k, b + k + 2, bend)
        self._root_index = (np.arange(s)[:, None] * n + np.arange(2)[None]).reshape(-1)
        self._out = np.empty((s, n, 3))
        PyPBD._live = True
        self.note = 'no head collider, no damping; roots set by Python calls'

    def _to_pbd(self, pts):
        return pts @ PYPBD_FROM_WORLD.T

    def reset(self, head):
        x = self._to_pbd(head.to_world(self.workload.ghost_rest)).reshape(-1, 3)
        pd = self._pd
        zero = [0.0, 0.0, 0.0]
        for i, p in enumerate(x.tolist()):
            pd.setPosition(i, p)
            pd.setPosition0(i, p)
            pd.setVelocity(i, zero)

    def step(self, dt, head_prev, head):
        import time
        t0 = time.perf_counter()
        roots = self._to_pbd(head.to_world(self.workload.ghost_rest[:, :2])).reshape(-1, 3)
        pd = self._pd
        for i, p in zip(self._root_index.tolist(), roots.tolist()):
            pd.setPosition(i, p)
        self.excluded_seconds += time.perf_counter() - t0
        self._pbd.TimeManager.getCurrent().setTimeStepSize(float(dt))
        self._ts.step(self._model)

    def output(self, head):
        x = np.asarray(self._pd.getVertices())
        np.matmul(x.reshape(self._shape + (3,)), PYPBD_FROM_WORLD, out=self._out)
        return self._out

    def close(self):
        if PyPBD._live:
            self._model.cleanup()
            PyPBD._live = False
