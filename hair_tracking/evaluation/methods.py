"""The methods compared by the accuracy evaluation, behind one small interface.

Every method produces the positions of the *same* ghost strands (the workload's ``ghost_rest``,
head frame) node for node, so its output can be compared with the reference.  The package's
methods run through the package's one loop, a :class:`~hair_tracking.simulator.HairSimulator`
of the method's scene on the method's own strands (its split rule, its solver and tracker
objects, its tracking schedule), so the evaluation measures the product:

* :class:`FullSim` -- every ghost strand simulated as a guide (PBD, XPBD or FTL at the scene's
  settings, no ghosts).  With a fine step, many iterations and XPBD at compliance 0 this is the
  reference.
* :class:`GhostTracking` -- the method of the package (Park & Kim): ``S / ratio`` guides made by
  :func:`~hair_tracking.core.groom.make_groom` (as the procedural groom makes them), the ghosts
  moved by :class:`~hair_tracking.ghosts.tracker.GhostTracker` each substep (or once per output
  frame over all its substeps with ``tracking.every_substep: false``).
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
``step(dt, head_prev, head)`` advances one substep of ``dt`` seconds (the scene's
``solver.dt``) while the head moves from ``head_prev`` to ``head``; ``advance(dt, head_prev,
heads)`` advances one substep a pose of ``heads`` (a frame's substeps; the guide solver's one
compiled call where the method allows it: the same engineering for every method);
``output(head)`` returns the ghost positions (S, N, 3),
world frame [m], at the end of the frame (a view that stays valid until the next ``step``);
``zero_velocities()`` puts the hair at rest where it is.
"""
from dataclasses import dataclass, field, replace
from typing import Dict

import numpy as np

from hair_tracking.core.groom import Groom, make_groom
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.ghosts.stateless import choose_guides
from hair_tracking.ghosts.correspondence import assign_guides, node_correspondence
from hair_tracking.simulator import HairSimulator

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


class _Simulated(Method):
    """A method run by the package's loop: a :class:`~hair_tracking.simulator.HairSimulator`
    of ``scene`` on the strands of ``groom`` (the method's own guides and ghosts), driven pose
    by pose (:meth:`~hair_tracking.simulator.HairSimulator.advance_poses`: the guide substeps
    of a frame in one solver call, split where the simulator's split rule splits them, the
    ghosts tracked as the scene says) and read without a frame
    (:meth:`~hair_tracking.simulator.HairSimulator.strand_positions`)."""

    def __init__(self, name, workload, scene, knobs, groom: Groom):
        super().__init__(name, workload, scene, knobs)
        self.sim = HairSimulator(scene, groom=groom, settled=False)
        # the paper tracker stores the ghosts grouped by guide: row i is the user's ghost perm[i]
        perm = self.sim.ghost_tracker.permutation if self.sim.ghost_tracker else None
        self._perm = None
        if perm is not None and np.any(perm != np.arange(len(perm))):
            self._perm = np.asarray(perm, dtype=np.int64)
            self._out = np.empty_like(workload.ghost_rest)

    def reset(self, head):
        self.sim.rest_at(head, settle=False)

    def step(self, dt, head_prev, head):
        self.advance(dt, head_prev, [head])

    def advance(self, dt, head_prev, heads):
        if dt != self.dt:
            raise ValueError(f'dt: {self.name} steps the scene\'s solver.dt {self.dt} s, '
                             f'got {dt}')
        self.sim.advance_poses(list(heads))

    def output(self, head):
        x = self.sim.strand_positions()
        if self._perm is None:
            return x
        self._out[self._perm] = x
        return self._out

    def zero_velocities(self):
        self.sim.zero_velocities()


def _no_strands(rest: np.ndarray) -> np.ndarray:
    """No strands of ``rest``'s node count."""
    return np.zeros((0,) + rest.shape[1:])


class FullSim(_Simulated):
    """All ghost strands simulated as guides (the reference at high fidelity)."""

    family = 'full'

    def __init__(self, name, workload, scene, knobs=None):
        rest = workload.ghost_rest
        super().__init__(name, workload, scene, knobs or {}, Groom(rest, _no_strands(rest)))


class GhostTracking(_Simulated):
    """``S / ratio`` guides grown by the groom generator, the ghosts moved by
    :class:`~hair_tracking.ghosts.tracker.GhostTracker` (``tracking.mode: paper``; every substep
    or, with ``tracking.every_substep: false``, once a frame over its substeps)."""

    family = 'ghost'

    def __init__(self, name, workload, scene, ratio, knobs=None):
        self.ratio = int(ratio)
        super().__init__(name, workload, scene.with_changes(tracking__mode='paper'),
                         knobs or {}, Groom(workload.guide_rest(self.ratio),
                                            workload.ghost_rest))


class BlendTracking(_Simulated):
    """Guides chosen among the strands (``S / ratio`` of them, :func:`choose_guides`) simulated
    by the scene's solver; every strand blended from its ``k`` nearest guides once per output
    frame (:class:`~hair_tracking.ghosts.blend.BlendTracker`, ``tracking.mode: blend``).  At
    1:1 this is :class:`FullSim`.
    """

    family = 'blend'
    mode = 'blend'

    def __init__(self, name, workload, scene, ratio, knobs=None, k: int = 3):
        self.ratio = int(ratio)
        count = workload.count // self.ratio
        if count < 1:
            raise ValueError(f'ratio: 1:{ratio} leaves no guide for {workload.count} strands')
        rest = workload.ghost_rest
        index = choose_guides(rest[:, 0], count)
        super().__init__(name, workload,
                         scene.with_changes(tracking__mode=self.mode, tracking__blend_guides=k),
                         knobs or {}, Groom(rest[index], rest, guide_index=index))


class TurnTracking(BlendTracking):
    """As :class:`BlendTracking`, every strand placed by the turn tracker
    (:class:`~hair_tracking.ghosts.turn.TurnTracker`, ``tracking.mode: turn``): its segments
    turned as the matching segments of the guide with the nearest root.  At 1:1 this is
    :class:`FullSim`."""

    family = 'turn'
    mode = 'turn'


class RigidOffset(_Simulated):
    """Ghost = guide point at the same arc-length fraction + rest offset rotated with the head
    (the guides grown as :class:`GhostTracking` grows them, simulated without ghosts)."""

    family = 'rigid'

    def __init__(self, name, workload, scene, ratio, knobs=None):
        self.ratio = int(ratio)
        gr = workload.guide_rest(self.ratio)
        super().__init__(name, workload, scene, knobs or {}, Groom(gr, _no_strands(gr)))
        guide_of, _ = assign_guides(workload.ghost_rest, gr, scene.tracking.candidates)
        seg, t = node_correspondence(workload.rest_length, StrandSet.from_rest(gr).rest_length,
                                     guide_of)
        self._g = np.asarray(guide_of, dtype=np.int64)[:, None]
        self._seg = seg
        self._t = t[..., None]
        point_rest = (1.0 - self._t) * gr[self._g, seg] + self._t * gr[self._g, seg + 1]
        self._offset = np.ascontiguousarray(workload.ghost_rest - point_rest)   # head frame
        self._out = np.empty_like(workload.ghost_rest)

    def output(self, head):
        gx = self.sim.strand_positions()
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
