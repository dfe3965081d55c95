"""Guide (target) strands: the few strands simulated with position-based dynamics.

Section 1 of the method (``seed/digest.md``): guides are simulated with PBD (Müller et al. 2007)
and their roots follow the head. One call of :meth:`GuideSolver.step` is one substep ``dt``:

1. roots follow the head: nodes 0 and 1 of every strand are set kinematically to
   ``head.to_world(rest[:, :2])`` (inverse mass 0), which pins the root position *and* the root
   direction (as in AMD TressFX);
2. optional velocity shock propagation (``scene.solver.shock_propagation`` = s): the free nodes
   are carried rigidly with the fraction s of the head's motion from ``head_prev`` to ``head``
   before integrating (TressFX; keeps fast head turns from stretching the hair);
3. explicit Euler of gravity (``scene.gravity``, world frame) and damping
   (``v *= exp(-scene.damping dt)``), prediction ``p = x + v dt``;
4. constraint projection by the solver chosen in ``scene.solver.type`` (:func:`make_solver`,
   the one place that reads it): ``'pbd'`` classic Gauss–Seidel PBD (:class:`PbdSolver`),
   ``'xpbd'`` XPBD with compliance (:class:`XpbdSolver`), ``'ftl'`` Follow-The-Leader
   (:class:`FtlSolver`; see :mod:`~hair_tracking.guides.pbd_constraints` and
   :mod:`~hair_tracking.guides.ftl`); the rest of the substep is their base class's,
   :class:`GuideSolver`;
5. head collision, only if the scene has a collider (:mod:`~hair_tracking.colliders.head`),
   with friction measured against the start-of-substep positions carried rigidly with the head
   (FTL: within its pass, node by node, :func:`~hair_tracking.guides.ftl.contact_node`); then,
   only if the scene has a body (``body.bust``), the bust's capsules
   (:class:`~hair_tracking.colliders.scene_body.SceneBody`, the contact model's collision stage
   :func:`~hair_tracking.colliders.kernels.collide` with its push-out velocity bound; FTL
   then walks the pushed strands again, :func:`~hair_tracking.guides.ftl.ftl_restore_shapes`);
6. per-substep displacement clamp (``scene.solver.max_displacement``, FTL's an inner step;
   0 disables) and the velocity update ``v = (p - x) / dt`` (FTL: minus
   ``ftl_damping d_{i+1} / dt``) —
   :mod:`~hair_tracking.guides.integrate`.

Without a collider steps 1–6 run in one fused numba kernel per block of strands (the strands stay
in cache), and so do FTL's with a collider (:func:`~hair_tracking.guides.ftl.ftl_collide_step`:
the collision is part of the pass); PBD and XPBD with a collider stop after step 4, the
collision kernel runs, then the finalize kernel; so do all three with a body (FTL: its pass
with the head collider, then the bust), one substep a call.
:meth:`GuideSolver.advance` takes a run of substeps in one call: for FTL one compiled call for
all of them (:func:`~hair_tracking.guides.ftl.ftl_advance`), whose state has a head axis: one
person's guides are a run of one head, several people's (:class:`HeadBatch`) one call for all
of them, the same code. Kernels are
looked up on their modules at call time, so only the ones the scene needs are ever called (and
compiled), and tests can spy on them.

Masses are uniform (``StrandSet.from_rest``: inverse mass 1 for free nodes, 0 for the two roots);
general inverse masses are accepted by PBD/XPBD (a free node with 0 is static), FTL needs every
free node to be movable. ``strands.inv_mass`` is read when the solver is built.
"""
import math
from typing import Any, Dict, Optional, Sequence

import numpy as np

from hair_tracking.colliders import kernels as contact_kernels
from hair_tracking.colliders.table import ColliderTable
from hair_tracking.guides import ftl

from hair_tracking.guides import integrate

from hair_tracking.core.kernels import runs_parallel
from hair_tracking.core.metrics import max_stretch
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.guides import pbd_constraints
from hair_tracking.guides.split import split_due
from hair_tracking.guides.volume import VolumeGrid

#: Substep [s] at which ``solver.bend_stiffness`` applies as given to FTL (the default dt), and
#: the longest inner step of an FTL substep; see :func:`ftl_bend_stiffness` and
#: :func:`ftl_inner_steps`.
BEND_REFERENCE_DT = 1.0 / 240.0
#: A substep within this fraction of :data:`BEND_REFERENCE_DT` is that substep (the presets'
#: 0.004166667 s is 1/240 s).
REFERENCE_TOLERANCE = 1e-6
#: What the FTL kernels take as the collider where there is none (not read; the fields of
#: :data:`~hair_tracking.colliders.head.ColliderModel`).
NO_COLLIDER = (np.zeros(3), np.ones(3), 0.0, 0.0, 0)
#: The slots of a run of one head's guides (:meth:`FtlSolver.run_heads`).
ONE_HEAD = np.zeros(1, dtype=np.int64)


class GuideSolver:
    """Advances ``strands.x`` / ``strands.v`` (world frame) one substep at a time: the part
    every solver shares (the head's poses, the head collider where a solver's pass does not
    meet it, the bust, finalize, the counters); the constraint projection is the subclass's
    (:class:`FtlSolver`, :class:`PbdSolver`, :class:`XpbdSolver`), built from the scene by
    :func:`make_solver`.

    ``strands``: a :class:`~hair_tracking.core.model.StrandSet` (changed in place; its ``x`` and
    ``v`` must be C-contiguous float64 ``(S, N, 3)``, ``N >= 3``); ``scene``: a
    :class:`~hair_tracking.core.scene.Scene` (solver, gravity, damping, collider);
    ``parallel``: run the parallel kernels rather than their serial variants (default: by the
    node count, :func:`~hair_tracking.core.kernels.runs_parallel`; the simulator decides
    for the whole scene); ``colliders``: the scene's
    :class:`~hair_tracking.colliders.table.ColliderTable` (the simulator's; default: one built
    from ``scene``).

    Attributes: ``collider`` (the table's head row for these strands, ``None`` when the scene
    has none), ``body`` (its bust and slot shapes), ``kind`` (the solver's name in
    ``scene.solver.type``, reported in :attr:`stats`), ``margin`` the collider margin in use
    [m]: ``scene.collider.margin``, but at most the rest clearance of the closest free node and
    half the shortest segment (:meth:`~hair_tracking.colliders.head.HeadCollider.fitted`);
    ``parallel`` the kernel variant; ``model`` the kernels' static data, the
    fields of :data:`~hair_tracking.guides.ftl.FtlModel`,
    :data:`~hair_tracking.guides.pbd_constraints.PbdModel` or
    :data:`~hair_tracking.guides.pbd_constraints.XpbdModel` as a plain tuple (XPBD's from
    the first substep on: its gains depend on ``dt``).
    """

    kind = ''

    def __init__(self, strands: StrandSet, scene, parallel: Optional[bool] = None,
                 colliders: Optional[ColliderTable] = None):
        self._check_strands(strands)
        self.strands = strands
        self.scene = scene
        self.parallel = bool(runs_parallel(strands.count * strands.nodes)
                             if parallel is None else parallel)
        #: the scene's collider table (the simulator's, or one of this solver's own)
        self.colliders = colliders if colliders is not None else ColliderTable(scene)
        mine = self.colliders.for_strands(strands)
        #: the head's row, margin fitted to the strands (``None`` without a head collider)
        self.collider = mine.head
        self.margin = self.collider.margin if self.collider is not None else 0.0
        #: the bust and slot shapes (``None`` without either)
        self.body = mine.body
        sv = scene.solver
        self._gravity = np.ascontiguousarray(scene.gravity, dtype=np.float64)
        self._damping = float(scene.damping)
        self._shock = float(sv.shock_propagation)
        self._shape = float(sv.shape_stiffness)
        self._max_disp = float(sv.max_displacement)
        self._iterations = int(sv.iterations)
        self._x_old = np.empty_like(strands.x)
        self._rot_rel = np.empty((3, 3))
        self._bend_rest = pbd_constraints.second_neighbour_rest(strands.rest)
        self._build_model()
        need_ref = self.collider is not None and self.collider.friction > 0.0
        self._x_ref = np.empty_like(strands.x) if need_ref else None
        self._x_before = np.empty_like(strands.x)      # advance(measure=True)'s work space
        #: the hair-hair stage (``volume.enabled``, every VolumeGrid.period substeps), or None
        self.volume = VolumeGrid(strands.rest, strands.inv_mass, scene.volume,
                                 self.parallel) if scene.volume.enabled else None
        self._since, self._since_s = 0, 0.0     # substeps and seconds since the stage ran
        self._counters = {'substeps': 0, 'clamped': 0, 'clamped_total': 0,
                          'contacts': 0, 'contacts_total': 0}

    # ------------------------------------------------------------------ API
    def reset(self, head: HeadPose) -> None:
        """Put every strand in its rest shape carried by ``head``, at rest; clear counters."""
        self.strands.place_at(head)
        for key in self._counters:
            self._counters[key] = 0

    def set_gravity(self, gravity) -> None:
        """Gravity [m/s^2] (3,) in the fixed frame of the head poses from the next substep on
        (a per-step input: nothing is rebuilt)."""
        self._gravity[...] = np.asarray(gravity, dtype=np.float64).reshape(3)

    def leave_body(self, head: HeadPose) -> int:
        """Move the strands, as they stand, out of the bust posed at the head pose ``head``:
        after the hair was placed or carried rigidly with the head, which the bust does not
        follow (it stays upright on the neck frame, or rides on its own TF frame), so a head
        tilted by 10 degrees swings 55 cm hair 9 cm into the trunk.  The contact stage with
        the bust still (no motion, no push-out bound) and the solver's repair of the pushed
        strands (FTL: the collision-aware pass that puts the lengths back); the velocities are
        not touched (the caller places hair at rest).  Returns the number of nodes the contact
        moved (0 without a body)."""
        if self.body is None:
            return 0
        st = self.strands
        rot, _ = _pose('head', head)
        bust = self.body.posed(head, head, self.scene.solver.dt)
        start = st.x.copy()
        pushed = contact_kernels.collide(st.x, start, st.inv_mass, bust, -1.0, start)
        if pushed:
            self._after_push(start, rot, bust, -1.0, still=True)
        return int(pushed)

    def step(self, dt: float, head_prev: HeadPose, head: HeadPose) -> None:
        """Advance one substep ``dt`` [s] while the head moves from ``head_prev`` to ``head``."""
        self._step(dt, head_prev, head, self.parallel)
        self._volume(dt, 1, head)

    def advance(self, dt: float, head_prev: HeadPose, heads: Sequence[HeadPose],
                measure: bool = False, stop=None) -> Optional[np.ndarray]:
        """Advance ``len(heads)`` substeps ``dt`` [s], the head moving from ``head_prev`` to
        ``heads[0]``, then on to each next pose: the same as :meth:`step` for each pose in turn
        (FTL without a body in one compiled call, :meth:`FtlSolver._run`; a single substep not
        measured takes the one-substep kernels).  With ``measure``, returns every substep's
        largest squared node displacement [m^2] (the simulator's speed estimate).  ``stop``
        (with ``measure``): ``(rigid, limit, gdt2)``, the split rule
        (:meth:`~hair_tracking.guides.split.SplitRule.stop`, ``rigid`` one value a substep): the
        run stops before the first substep after the first that the rule would split
        (:func:`~hair_tracking.guides.split.split_due`), and the displacements returned are
        those of the substeps taken.  With the volume stage (``volume.enabled``) the substeps
        run in parts that end where the stage is due (:meth:`_volume`)."""
        heads = list(heads)
        if not heads:
            return np.zeros(0) if measure else None
        if self.volume is None:
            return self._advance(dt, head_prev, heads, measure, stop)
        # the volume stage every volume_period(dt) substeps, counted across calls
        out, k, prev = [], 0, head_prev
        while k < len(heads):
            n = min(max(1, self.volume.period(dt) - self._since), len(heads) - k)
            part = None if stop is None else (stop[0][k:k + n], stop[1], stop[2])
            steps = self._advance(dt, prev, heads[k:k + n], measure, part)
            taken = n if steps is None else len(steps)
            if measure:
                out.append(steps)
            self._volume(dt, taken, heads[k + taken - 1])
            if taken < n:
                break                               # the split rule stopped the run
            k, prev = k + n, heads[k + n - 1]
        return np.concatenate(out) if measure else None

    def _advance(self, dt: float, head_prev: HeadPose, heads: list, measure: bool, stop):
        """:meth:`advance` without the volume stage."""
        if len(heads) == 1 and not measure:
            self._step(dt, head_prev, heads[0], self.parallel)    # the one-substep kernels
            return None
        rule = stop is not None and measure and stop[1] > 0.0
        return self._run(dt, head_prev, heads, measure, stop if rule else None)

    def head_batch(self, places: int) -> Optional['HeadBatch']:
        """Room for the guides of ``places`` heads advanced together in one compiled call
        (:class:`HeadBatch`), or None where this solver takes one call a head."""
        return None

    def _volume(self, dt: float, taken: int, head: HeadPose) -> None:
        """Count ``taken`` substeps ``dt`` (the last at the head pose ``head``) toward the
        volume stage (``volume.enabled``), and run it when its period is full
        (:meth:`~hair_tracking.guides.volume.VolumeGrid.period`), over the time since it last
        ran."""
        if self.volume is None:
            return
        self._since += taken
        self._since_s += taken * dt
        if self._since >= self.volume.period(dt):
            rot, pos = _pose('head', head)
            self.volume.apply(self.strands.x, self.strands.v, rot, pos, self._since_s)
            self._since, self._since_s = 0, 0.0

    @property
    def stats(self) -> Dict[str, Any]:
        """Counters of the solver (a new dict on each access).

        ``substeps`` run since the last reset; ``clamped`` nodes whose displacement (or velocity)
        the clamp limited in the last substep, ``clamped_total``; ``contacts`` nodes projected out
        of the collider in the last substep, ``contacts_total``; ``max_stretch`` = max over
        segments of ``|l / l0 - 1|`` of the current state, i.e. after the last substep (computed
        on access); ``margin`` the collider margin in use [m]
        (see :attr:`margin`).
        """
        out = dict(self._counters)
        out['solver'] = self.kind
        out['margin'] = self.margin
        out['max_stretch'] = max_stretch(self.strands.x, self.strands.rest_length)
        return out

    # ------------------------------------------------------- solver's parts
    def _build_model(self) -> None:
        """The kernels' static data (``self.model``) and work space."""
        raise NotImplementedError

    def _project(self, state, motion, dt: float, parallel: bool, fused: bool):
        """The constraint projection of a substep (after the predict stage, in the same
        kernel): ``(clamped, contacts, finished)``, ``finished`` when the kernel also ran the
        collision and finalize (``fused``: without a collider or a body)."""
        raise NotImplementedError

    def _head_contacts(self, rot, pos, parallel: bool) -> int:
        """The head collider's stage after the projection (none without a collider)."""
        if self.collider is None:
            return 0
        st = self.strands
        return self.collider.project(st.x, self._friction_ref(), st.inv_mass, rot, pos,
                                     parallel)

    def _after_push(self, start, rot, bust, cap: float, still: bool = False) -> None:
        """Repair the strands the bust ``bust`` pushed from ``start`` (push-out bound ``cap``;
        ``still``: outside a substep, :meth:`leave_body`); nothing here."""

    def _finalize_args(self, dt: float):
        """``(corr, max_disp, s_damp)`` of finalize (:func:`~hair_tracking.guides.integrate.
        finalize`) after a substep ``dt``."""
        return self._x_old, self._max_disp, 0.0

    # ------------------------------------------------------------ internals
    def _run(self, dt: float, head_prev: HeadPose, heads, measure: bool, stop):
        """:meth:`advance` one :meth:`_step` a substep (``stop``: the split rule or None)."""
        out = []
        prev, x0 = head_prev, self._x_before
        for k, head in enumerate(heads):
            if measure:
                np.copyto(x0, self.strands.x)
            self._step(dt, prev, head, self.parallel)
            if measure:
                out.append(integrate.max_step_sq(self.strands.x, x0))
                if stop is not None and k + 1 < len(heads) and \
                        split_due(out[-1], dt, stop[0][k + 1], stop[2], stop[1]):
                    break
            prev = head
        return np.array(out) if measure else None

    def _step(self, dt: float, head_prev: HeadPose, head: HeadPose, parallel: bool) -> None:
        dt = _check_dt(dt)
        rot_prev, pos_prev = _pose('head_prev', head_prev)
        rot, pos = _pose('head', head)
        rot_rel = self._rot_rel
        if not integrate.head_motion(rot_prev, pos_prev, rot, pos, rot_rel):
            bad = 'head_prev' if not (np.all(np.isfinite(rot_prev))
                                      and np.all(np.isfinite(pos_prev))) else 'head'
            raise ValueError(f'{bad}: pose must be finite, got position '
                             f'{pos_prev if bad == "head_prev" else pos}')
        st = self.strands
        damp = math.exp(-self._damping * dt)
        fused = self._fuses()
        # the kernels' arguments, plain tuples in the fields' order of integrate.GuideState,
        # integrate.StepMotion and the solver's Params (built here each substep; the models in
        # _build_model / _xpbd_factors)
        state = (st.x, st.v, self._x_old)
        motion = (rot, pos, rot_rel, pos_prev, self._gravity, damp, dt, self._shock,
                  self._shape)
        clamped, contacts, finished = self._project(state, motion, dt, parallel, fused)
        if not finished:
            contacts += self._head_contacts(rot, pos, parallel)
            if self.body is not None:
                # the start of the substep is the friction reference and, moved by the
                # push-out bound, the velocity's
                bust = self.body.posed(head_prev, head, dt)
                pushed = contact_kernels.collide(st.x, self._x_old, st.inv_mass, bust,
                                                 self.body.push_cap(dt), self._x_old)
                if pushed:
                    self._after_push(self._x_old, rot, bust, self.body.push_cap(dt))
                contacts += pushed
            finalize = integrate.finalize if parallel else integrate.finalize_serial
            corr, max_disp, s_damp = self._finalize_args(dt)
            clamped = finalize(st.x, st.v, self._x_old, st.inv_mass, corr, dt, max_disp, s_damp)
            self._after_finalize(dt, parallel)
        self._count(clamped, contacts)

    def _fuses(self) -> bool:
        """Whether the projection kernel finishes the substep itself (collision and
        finalize have nothing to do)."""
        return self.collider is None and self.body is None

    def _after_finalize(self, dt: float, parallel: bool) -> None:
        """What a solver does to the finished substep (nothing here)."""

    def _friction_ref(self) -> np.ndarray:
        """The collider's friction reference: the start-of-substep positions carried with the
        head (``_x_ref``) when there is friction, else ``x_old`` (not read)."""
        return self._x_ref if self._x_ref is not None else self._x_old

    def _count(self, clamped, contacts) -> None:
        c = self._counters
        c['substeps'] += 1
        c['clamped'] = int(clamped)
        c['clamped_total'] += int(clamped)
        c['contacts'] = int(contacts)
        c['contacts_total'] += int(contacts)

    @staticmethod
    def _check_strands(st: StrandSet) -> None:
        _check_strands(st)


class FtlSolver(GuideSolver):
    """Follow-The-Leader (:mod:`~hair_tracking.guides.ftl`).

    With a collider, a substep is predict, bend, an FTL pass aware of the collider (each node
    placed at its rest distance and, when inside, pushed out with friction and placed again:
    :func:`~hair_tracking.guides.ftl.contact_node`), then finalize, in one kernel: lengths stay
    exact and nodes outside the bare collider (measured in the stability matrix,
    ``docs/stability.md``).  A run of substeps without a body is one compiled call
    (:func:`~hair_tracking.guides.ftl.ftl_advance`); the guides of several heads too
    (:meth:`head_batch`).
    """

    kind = 'ftl'

    def _build_model(self) -> None:
        st = self.strands
        im = st.inv_mass
        self._bend_w = pbd_constraints.pair_weights(im, 2)
        self._corr = np.zeros_like(st.x)
        self.model = tuple(ftl.FtlModel(st.rest, im, st.rest_length, self._bend_rest,
                                        self._bend_w))
        self._spaces: Dict[tuple, tuple] = {}

    @staticmethod
    def _check_strands(st: StrandSet) -> None:
        _check_strands(st)
        if np.any(st.inv_mass[:, 2:] <= 0):
            raise ValueError("strands.inv_mass: the 'ftl' solver moves every free node; nodes "
                             '2.. must have inverse mass > 0')

    def params(self, dt: float, finalize: bool) -> tuple:
        """The FTL kernels' :data:`~hair_tracking.guides.ftl.FtlParams` for a substep ``dt``."""
        sv = self.scene.solver
        return (ftl_inner_steps(dt), ftl_bend_stiffness(sv.bend_stiffness, dt),
                float(sv.ftl_damping), self._ftl_clamp(dt), finalize)

    def drive(self, rots, poss, rels, dt: float) -> tuple:
        """What drives a run of substeps ``dt`` (the fields of
        :data:`~hair_tracking.guides.ftl.RunDrive`): the head's poses ``rots``, ``poss`` and
        motions ``rels`` (:func:`~hair_tracking.guides.integrate.head_motions`), gravity,
        damping and shock propagation."""
        return (rots, poss, rels, self._gravity, math.exp(-self._damping * dt), dt,
                self._shock, self._shape)

    def head_batch(self, places: int) -> Optional['HeadBatch']:
        """Room for ``places`` heads' guides (:class:`HeadBatch`); None with a body, whose
        contact stage takes one call a substep, and with the volume stage, which couples the
        strands after every call."""
        return HeadBatch(self, places) if self.body is None and self.volume is None else None

    def _project(self, state, motion, dt, parallel, fused):
        if self.collider is not None:
            # one kernel: friction reference and the collision-aware FTL pass in the block
            # loop, finalize too without a body
            kernel = ftl.ftl_collide_step if parallel else ftl.ftl_collide_step_serial
            work = (self._corr, self._friction_ref())
            clamped, contacts = kernel(self.model, state, motion,
                                       self.params(dt, self.body is None), work,
                                       self.collider_model())
            return clamped, contacts, self.body is None
        kernel = ftl.ftl_step if parallel else ftl.ftl_step_serial
        return kernel(self.model, state, motion, self.params(dt, fused), self._corr), 0, fused

    def _head_contacts(self, rot, pos, parallel):
        return 0                        # the pass meets the head collider

    def _after_push(self, start, rot, bust, cap, still=False):
        st = self.strands
        ftl.ftl_restore_shapes(st.x, start, st.rest, st.rest_length, rot, bust,
                               np.zeros_like(st.x) if still else self._corr, cap)

    def _finalize_args(self, dt):
        return self._corr, self._ftl_clamp(dt), float(self.scene.solver.ftl_damping)

    def collider_model(self) -> tuple:
        """The collider as the FTL kernels take it
        (:data:`~hair_tracking.colliders.head.ColliderModel`; a stand-in without one)."""
        return self.collider.model if self.collider is not None else NO_COLLIDER

    @property
    def corrections(self) -> np.ndarray:
        """FTL's corrections ``d`` (S, N, 3) [m] of the last substep, which finalize's
        velocity correction ``s_damp d_{i+1} / dt`` reads (:mod:`~hair_tracking.guides.ftl`)."""
        return self._corr

    def _ftl_clamp(self, dt: float) -> float:
        """FTL's displacement clamp over a substep ``dt`` [m]: ``solver.max_displacement`` an
        inner step (:func:`ftl_inner_steps`), so it bounds the same speed at any ``dt``."""
        return self._max_disp * ftl_inner_steps(dt)

    def _run(self, dt, head_prev, heads, measure, stop):
        """Without a body, all substeps in one compiled call
        (:func:`~hair_tracking.guides.ftl.ftl_advance`, the head's guides a run of one head)."""
        if self.body is not None:
            return super()._run(dt, head_prev, heads, measure, stop)
        st = self.strands
        rule = None if stop is None else (np.asarray(stop[0])[None], stop[1], stop[2])
        done, counts, steps = self.run_heads(
            dt, (st.x[None], st.v[None], self._x_old[None]),
            (self._corr[None], self._friction_ref()[None], self._x_before[None]),
            ONE_HEAD, [head_prev], [heads], rule, measure, self.parallel)
        clamped, clamped_total, contacts, contacts_total = ftl.run_counts(counts[0], done)
        cn = self._counters
        cn['substeps'] += done
        cn['clamped'], cn['contacts'] = int(clamped), int(contacts)
        cn['clamped_total'] += int(clamped_total)
        cn['contacts_total'] += int(contacts_total)
        return steps[0, :done].copy() if measure else None

    def run_heads(self, dt: float, state, work, slots: np.ndarray, prev: Sequence[HeadPose],
                  runs, stop, measure: bool, parallel: bool):
        """One call of :func:`~hair_tracking.guides.ftl.ftl_advance`: every head ``i`` (at
        place ``slots[i]`` of ``state = (x, v, x_old)``, each (C, G, N, 3)) from ``prev[i]``
        through its run of poses ``runs[i]`` (all runs the same length), substeps ``dt``, this
        solver's model, collider and parameters; ``work``: ``(corr, x_ref, before)`` shaped
        like ``x``; ``stop``: the split rule (``(rigid (P, K), limit, gdt2)``,
        :meth:`~hair_tracking.guides.split.SplitRule.stop`) or None; ``measure``: the largest
        displacements wanted.  Returns ``(substeps taken, counts (P, B, K, 2), steps (P, B, K)
        or (P, B, 0))``, ``steps[i, 0]`` the largest squared node displacement of each of head
        ``i``'s substeps."""
        dt = _check_dt(dt)
        people, n_sub = len(prev), len(runs[0])
        blocks = integrate.block_count(state[0].shape[1])
        key = (people, n_sub, blocks, measure)
        space = self._spaces.get(key)
        if space is None:           # kept for the next run of the same shape
            space = self._spaces[key] = (
                np.empty((people, n_sub + 1, 3, 3)), np.empty((people, n_sub + 1, 3)),
                np.empty((people, n_sub, 3, 3)),
                np.empty((people, blocks, n_sub, 2), dtype=np.int64),
                np.empty((people, blocks, n_sub if measure else 0)))
        rots, poss, rels, counts, steps = space
        for i, (p, run) in enumerate(zip(prev, runs)):
            for j, head in enumerate([p] + list(run)):
                rots[i, j], poss[i, j] = _pose('head_prev' if j == 0 else 'head', head)
            if not integrate.head_motions(rots[i], poss[i], rels[i]):
                bad = int(np.flatnonzero(~(np.isfinite(rots[i]).all(axis=(1, 2))
                                           & np.isfinite(poss[i]).all(axis=1)))[0])
                raise ValueError(f'{"head_prev" if bad == 0 else "head"}: pose must be '
                                 f'finite, got position {poss[i, bad]}')
        rule = (np.zeros((people, 1)), 0.0, 0.0) if stop is None else \
            (np.ascontiguousarray(stop[0], dtype=np.float64), float(stop[1]), float(stop[2]))
        kernel = ftl.ftl_advance if parallel else ftl.ftl_advance_serial
        corr, x_ref, before = work
        done = kernel(self.model, state, self.drive(rots, poss, rels, dt), self.params(dt, True),
                      self.collider is not None, self.collider_model(),
                      (corr, x_ref, counts, steps, before), rule, slots)
        return int(done), counts, steps[:, 0]


class HeadBatch:
    """The guides of several heads wearing one groom, advanced in one compiled call
    (:meth:`FtlSolver.run_heads`): ``x``, ``v`` shaped ``(places, G, N, 3)``, head ``h``'s
    guides at place ``slots[h]``; ``solver`` the :class:`FtlSolver` of one of them (its model,
    collider and parameters serve all)."""

    def __init__(self, solver: FtlSolver, places: int):
        self.solver = solver
        shape = (places,) + solver.strands.x.shape
        self.x, self.v = np.zeros(shape), np.zeros(shape)
        self._x_old, self._corr = np.zeros(shape), np.zeros(shape)
        self._x_ref, self._before = np.zeros(shape), np.zeros(shape)

    @property
    def places(self) -> int:
        return self.x.shape[0]

    def advance(self, dt: float, slots: np.ndarray, prev: Sequence[HeadPose], runs, stop,
                parallel: bool):
        """Every head ``i`` (at place ``slots[i]``) from ``prev[i]`` through its run of poses
        ``runs[i]`` (all runs the same length), substeps ``dt``; ``stop`` the split rule
        (``(rigid (P, K), limit, gdt2)``, :meth:`~hair_tracking.guides.split.SplitRule.stop`)
        or None.  Returns ``(steps (P, K), substeps taken)``, ``steps`` the largest squared
        node displacement of each head's substeps."""
        done, _, steps = self.solver.run_heads(
            dt, (self.x, self.v, self._x_old), (self._corr, self._x_ref, self._before), slots,
            prev, runs, stop, True, parallel)
        return steps[:, :done].copy(), done


class _LaneSolver(GuideSolver):
    """Shared by PBD and XPBD: the kernels read their per-constraint data block by block,
    strands side by side (:func:`~hair_tracking.guides.pbd_constraints.lane_major`), and
    project in a work space; the friction reference carried with the head before the
    projection."""

    def _build_model(self) -> None:
        lanes = pbd_constraints.lane_major
        st = self.strands
        s, n = st.inv_mass.shape
        self._work = pbd_constraints.lane_work(s, n)
        self._rest_length_l = lanes(st.rest_length)
        self._bend_rest_l = lanes(self._bend_rest)

    def _fuses(self) -> bool:
        return super()._fuses() and not self.scene.solver.max_strain > 0.0

    def _after_finalize(self, dt, parallel):
        """Strain limiting (``solver.max_strain``,
        :func:`~hair_tracking.guides.pbd_constraints.strain_limit`)."""
        limit = float(self.scene.solver.max_strain)
        if limit > 0.0:
            st = self.strands
            kernel = pbd_constraints.strain_limit if parallel else \
                pbd_constraints.strain_limit_serial
            kernel(st.x, st.v, st.inv_mass, st.rest_length, limit, dt)

    def _project(self, state, motion, dt, parallel, fused):
        if self._x_ref is not None:
            carry = integrate.carry_rigid if parallel else integrate.carry_rigid_serial
            _, pos, rot_rel, pos_prev, _, _, _, _, _ = motion         # StepMotion
            carry(self.strands.x, rot_rel, pos_prev, pos, self._x_ref)
        return self._constraints(state, motion, dt, parallel, fused), 0, fused

    def _constraints(self, state, motion, dt, parallel, fused) -> int:
        """The projection kernel (predict, constraints, finalize when ``fused``): clamped."""
        raise NotImplementedError


class PbdSolver(_LaneSolver):
    """Classic Gauss-Seidel PBD (Müller et al. 2007; :mod:`~hair_tracking.guides.
    pbd_constraints`)."""

    kind = 'pbd'

    def _build_model(self) -> None:
        super()._build_model()
        lanes = pbd_constraints.lane_major
        st = self.strands
        im = st.inv_mass
        self._stretch_w = lanes(pbd_constraints.pair_weights(im, 1))
        self._bend_w = lanes(pbd_constraints.pair_weights(im, 2))
        self.model = tuple(pbd_constraints.PbdModel(
            st.rest, im, self._rest_length_l, self._bend_rest_l, self._stretch_w, self._bend_w))

    def _constraints(self, state, motion, dt, parallel, fused):
        sv = self.scene.solver
        kernel = pbd_constraints.pbd_step if parallel else pbd_constraints.pbd_step_serial
        params = (self._iterations, float(sv.stiffness), float(sv.bend_stiffness),
                  self._max_disp, fused)
        return kernel(self.model, state, motion, params, self._work)


class XpbdSolver(_LaneSolver):
    """XPBD with compliance (Macklin, Müller & Chentanez 2016;
    :mod:`~hair_tracking.guides.pbd_constraints`)."""

    kind = 'xpbd'

    def _build_model(self) -> None:
        super()._build_model()
        lanes = pbd_constraints.lane_major
        s, n = self.strands.inv_mass.shape
        self._inv_mass_l = lanes(self.strands.inv_mass)
        self._lam_stretch = lanes(np.zeros((s, n - 1)))
        self._lam_bend = lanes(np.zeros((s, n - 2)))
        self._xpbd_work = tuple(pbd_constraints.XpbdWork(self._work, self._lam_stretch,
                                                         self._lam_bend))
        self._xpbd_dt = None          # the model, with its dt-dependent gains: later

    def _constraints(self, state, motion, dt, parallel, fused):
        a_stretch, a_bend = self._xpbd_factors(dt)
        kernel = pbd_constraints.xpbd_step if parallel else pbd_constraints.xpbd_step_serial
        params = (self._iterations, a_stretch, a_bend, self._max_disp, fused)
        return kernel(self.model, state, motion, params, self._xpbd_work)

    def _xpbd_factors(self, dt):
        sv = self.scene.solver
        a_stretch = float(sv.compliance) / (dt * dt)
        a_bend = float(sv.bend_compliance) / (dt * dt)
        if self._xpbd_dt != dt:
            im = self.strands.inv_mass
            self._stretch_gain = pbd_constraints.lane_major(
                pbd_constraints.xpbd_gain(im, 1, a_stretch))
            self._bend_gain = pbd_constraints.lane_major(
                pbd_constraints.xpbd_gain(im, 2, a_bend))
            st = self.strands
            self.model = tuple(pbd_constraints.XpbdModel(
                st.rest, im, self._inv_mass_l, self._rest_length_l, self._bend_rest_l,
                self._stretch_gain, self._bend_gain))
            self._xpbd_dt = dt
        return a_stretch, a_bend


#: The solvers by their name in ``scene.solver.type``.
SOLVERS = {cls.kind: cls for cls in (FtlSolver, PbdSolver, XpbdSolver)}


def make_solver(strands: StrandSet, scene, parallel: Optional[bool] = None,
                colliders: Optional[ColliderTable] = None) -> GuideSolver:
    """The guide solver ``scene.solver.type`` names (:data:`SOLVERS`) for ``strands``
    (:class:`GuideSolver` for the arguments)."""
    cls = SOLVERS.get(scene.solver.type)
    if cls is None:
        raise ValueError(f'solver.type: {scene.solver.type!r} is not one of ftl, pbd, xpbd')
    return cls(strands, scene, parallel, colliders)


def ftl_inner_steps(dt: float) -> int:
    """Inner steps of an FTL substep ``dt`` [s] (:func:`~hair_tracking.guides.ftl.ftl_block`):
    one up to :data:`BEND_REFERENCE_DT`, beyond it as many as substeps of that length would take
    (``ceil(dt / dt_ref)``, a step within :data:`REFERENCE_TOLERANCE` of a multiple counted
    as that multiple).

    Where the hair comes to rest is a balance struck anew each step: gravity's prediction
    pushes every bend by an amount in ``g h^2``, the bending sweep takes a fraction of it back,
    and the FTL pass and its velocity correction move it again; a step of ``h`` settles where
    steps of ``h`` settle.  So a long substep runs inner steps no longer than ``dt_ref`` (the
    head, the collider and finalize still once a substep), and the settled shape of any longer
    substep is that of ``dt_ref`` or shorter (``scripts/settle_shape.py``, docs/grooms.md).
    """
    return max(1, math.ceil(dt / BEND_REFERENCE_DT - REFERENCE_TOLERANCE))


def ftl_bend_stiffness(k: float, dt: float) -> float:
    """Bending stiffness of the sweep of each :func:`ftl_inner_steps` inner step of an FTL
    substep ``dt`` [s].

    ``solver.bend_stiffness`` ``k`` is the fraction of the bending violation one sweep removes
    at the step :data:`BEND_REFERENCE_DT`.  At rest, each step gravity's prediction pushes
    a bend by an amount proportional to ``g h^2`` (FTL's stored velocities at rest are ``g h``
    times a constant, :mod:`~hair_tracking.guides.ftl`), which the sweep takes back; for the
    hair to settle to the same bend at a shorter inner step ``h``, its sweep must act as
    ``(h / dt_ref)^2`` sweeps of ``k`` do (Müller et al. 2007's rule for a stiffness independent
    of the iteration count, section 3.3: ``n`` sweeps of ``1 - (1 - k)^(m / n)`` remove what
    ``m`` sweeps of ``k`` remove):

        k(h) = 1 - (1 - k)^((h / dt_ref)^2).

    The stiffness falls as ``h^2``, faster than FTL's velocity correction ``s_damp d / h``
    grows: a stiffness that does not fall let 25 cm strands at dt = 1/4000 s and 1.5 m strands
    at 1/480 s never come to rest after a head shake (measured).  A substep of a multiple of
    ``dt_ref`` runs inner steps of ``dt_ref`` with ``k`` itself.
    """
    k = float(k)
    ratio = dt / ftl_inner_steps(dt) / BEND_REFERENCE_DT
    if abs(ratio - 1.0) <= REFERENCE_TOLERANCE or k <= 0.0 or k >= 1.0:
        return k
    return 1.0 - (1.0 - k) ** (ratio * ratio)


def _check_dt(dt) -> float:
    dt = float(dt)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f'dt: must be a positive finite number of seconds, got {dt!r}')
    return dt


def _pose(name, head):
    """(rotation, position) of a head pose as C-contiguous float64 arrays (no copy if already)."""
    rot, pos = head.rotation, head.position
    if not (type(rot) is np.ndarray and rot.dtype == np.float64 and rot.flags.c_contiguous):
        rot = np.ascontiguousarray(rot, dtype=np.float64)
    if not (type(pos) is np.ndarray and pos.dtype == np.float64 and pos.flags.c_contiguous):
        pos = np.ascontiguousarray(pos, dtype=np.float64)
    if rot.shape != (3, 3) or pos.shape != (3,):
        raise ValueError(f'{name}: rotation must be (3, 3) and position (3,), got {rot.shape} '
                         f'and {pos.shape}')
    return rot, pos


def _check_strands(st: StrandSet) -> None:
    rest = st.rest
    if not isinstance(rest, np.ndarray) or rest.ndim != 3 or rest.shape[2] != 3:
        raise ValueError(f'strands.rest: must be an (S, N, 3) array, got '
                         f'{getattr(rest, "shape", type(rest).__name__)}')
    s, n, _ = rest.shape
    if s < 1 or n < 3:
        raise ValueError(f'strands: need at least 1 strand of at least 3 nodes, got {s} x {n}')
    for name, shape in (('rest', (s, n, 3)), ('x', (s, n, 3)), ('v', (s, n, 3)),
                        ('rest_length', (s, n - 1)), ('inv_mass', (s, n))):
        arr = getattr(st, name)
        if not isinstance(arr, np.ndarray) or arr.shape != shape or arr.dtype != np.float64 \
                or not arr.flags.c_contiguous:
            raise ValueError(f'strands.{name}: must be a C-contiguous float64 array shaped '
                             f'{shape}, got {getattr(arr, "dtype", type(arr).__name__)} '
                             f'{getattr(arr, "shape", "")}')
        if not np.all(np.isfinite(arr)):
            raise ValueError(f'strands.{name}: contains NaN or infinity')
    if np.any(st.rest_length < 0):
        raise ValueError('strands.rest_length: must be >= 0 metres')
    im = st.inv_mass
    if np.any(im < 0):
        raise ValueError('strands.inv_mass: must be >= 0')
    if np.any(im[:, :2] != 0):
        raise ValueError('strands.inv_mass: nodes 0 and 1 are attached to the head and must have '
                         'inverse mass 0')
