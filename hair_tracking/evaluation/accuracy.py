"""Error against run time: every method against a high-fidelity full simulation.

The question a user asks of the method (ghost strands following a few simulated guides, Park &
Kim) is what it costs in accuracy for what it saves in time.  This module answers it with
numbers, on the same ghost strands and the same head trajectory for every method:

Reference
    every ghost strand simulated as a guide (:class:`~hair_tracking.evaluation.methods.FullSim`)
    with XPBD (Macklin, Müller & Chentanez 2016) at compliance 0 (inextensible), a small step and
    several
    iterations (:data:`REFERENCE`), with the head collider.  XPBD is the one solver of the package
    whose material does not depend on the step and the iteration count, so its fine-step limit
    is a well-defined model; the other solvers converge to different materials (PBD's stiffness
    depends on the iterations, FTL adds numerical damping, Han & Harada 2013), and part of their
    error is that difference, not a discretisation error.  The reference's own discretisation
    error is measured against a finer run (:func:`reference_convergence`) and reported.

Methods (:func:`default_methods`)
    full simulation at lower substeps/iterations per solver; ghost tracking at guide ratios
    1:1, 1:4, 1:16, 1:64 with the weights on/off, centre-of-mass tracking on/off, length
    restoration on/off, and all off (plain velocity copy); the rigid-offset baseline at the same
    ratios; and the peer pypbd simulating all strands (skipped with a note when not installed).

Metrics (per output frame at :data:`FRAME_RATE`, then aggregated over the run)
    position error ``|x - x_ref| / L`` (RMS over nodes and frames, and the maximum); motion
    error ``|(x - x0) - (x_ref - x_ref0)| / L`` (RMS), where ``x0`` is each method's own settled
    state before the motion: the position error also counts a different rest shape (ghosts
    hang like their guides, PBD sags by its stretch), the motion error only how differently the
    hair moves; tip error
    (mean tip distance / L), max stretch ``max |l/l0 - 1|`` of the output, head penetration of the
    free nodes into the bare collider [mm], spread ratio (the variance of fixed ghost groups
    about their centre of mass, over the reference's: below 1 the hair clumps, above it fans out)
    and run time per frame: the median of per-run medians over the accuracy run and ``repeats``
    timing runs, all methods timed in the same process, interleaved, after every kernel was
    compiled and warmed up (metric computation is not timed).

Every method starts from its own settled rest state at the first head pose (``settle_time`` of
the scene with a still head, velocities then zeroed, as
:class:`~hair_tracking.simulator.HairSimulator` does), and then steps its own fixed substep; head
poses at substep times are interpolated
linearly / by slerp from the recorded samples.
"""
import csv
from dataclasses import dataclass, field
import math
import os
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from hair_tracking.colliders.table import ColliderTable
from hair_tracking.core.metrics import max_stretch, position_error, tip_error
from hair_tracking.core.model import HeadPose
from hair_tracking.core.scene import Scene
from hair_tracking.core.settle import settle as settle_until_still
from hair_tracking.core.transforms import quat_to_matrix, slerp
from hair_tracking.evaluation.methods import (FullSim, GhostTracking, Method, PyPBD, RigidOffset,
                                              Workload,
                                              make_workload, pypbd_available)
from hair_tracking.motion.head_motion import HeadMotion

#: Output frame rate [Hz]: errors are measured and time is charged per frame of this rate.
FRAME_RATE = 60.0

#: The reference setting: XPBD, compliance 0, substep FRAME/32 (1/1920 s), 8 iterations.
REFERENCE = {'type': 'xpbd', 'substeps': 32, 'iterations': 8}

#: The reference is run a second time with its settled state perturbed by this much [m]: the
#: growth of that perturbation shows where the hair's motion stops being predictable.
CHAOS_PERTURBATION = 1e-6
#: The predictable window ends where the perturbed reference is farther than this RMS [L] from
#: the reference: errors after it measure the chaos of hair-head contact, not the methods.
CHAOS_RMS = 0.01

#: Per-frame metrics (see the module docstring).
METRICS = ('rms', 'max', 'tip', 'stretch', 'pen', 'pen_body', 'spread', 'motion')


# ============================================================== head poses at substep times
def interpolate_poses(motion: HeadMotion, t_s: np.ndarray):
    """Head positions (K, 3) and unit quaternions (K, 4) at times ``t_s`` [s from the motion's
    start]: linear in position, slerp (shortest arc) in orientation; held outside the samples."""
    ts = motion.t_s
    t = np.clip(np.asarray(t_s, dtype=np.float64), ts[0], ts[-1])
    if len(ts) == 1:
        return (np.repeat(motion.position, len(t), 0), np.repeat(motion.quaternion, len(t), 0))
    i = np.clip(np.searchsorted(ts, t, side='right'), 1, len(ts) - 1)
    u = ((t - ts[i - 1]) / (ts[i] - ts[i - 1]))[:, None]
    p = (1.0 - u) * motion.position[i - 1] + u * motion.position[i]
    q = slerp(motion.quaternion[i - 1], motion.quaternion[i], u[:, 0])
    return p, q


class HeadSchedule:
    """Head poses of one trajectory at the output frames and at every substep time.

    Frame ``j`` (``1 <= j <= frames``) ends at ``j / FRAME_RATE`` seconds after the first
    sample; a method with ``k`` substeps per frame sees the head at ``(j - 1 + i / k) / rate``,
    ``i = 1..k``.
    """

    def __init__(self, motion: HeadMotion, frame_rate: float = FRAME_RATE,
                 duration_s: Optional[float] = None):
        self.motion = motion
        self.frame_rate = float(frame_rate)
        span = motion.duration_s if duration_s is None else min(duration_s, motion.duration_s)
        self.frames = int(math.floor(span * frame_rate + 1e-9))
        if self.frames < 1:
            raise ValueError(f'motion {motion.source!r} is shorter than one frame')
        self._cache: Dict[int, List[List[HeadPose]]] = {}

    @property
    def duration_s(self) -> float:
        return self.frames / self.frame_rate

    def start(self) -> HeadPose:
        """The head at the first sample (where every method settles)."""
        return _poses(*interpolate_poses(self.motion, np.zeros(1)))[0]

    def poses(self, k: int) -> List[List[HeadPose]]:
        """``[frame][substep]`` head poses for ``k`` substeps per frame (cached)."""
        if k not in self._cache:
            t = (np.arange(self.frames * k) + 1.0) / (k * self.frame_rate)
            flat = _poses(*interpolate_poses(self.motion, t))
            self._cache[k] = [flat[j * k:(j + 1) * k] for j in range(self.frames)]
        return self._cache[k]


def _poses(p, q) -> List[HeadPose]:
    rot = quat_to_matrix(q)
    return [HeadPose(p[i].copy(), q[i].copy(), rot[i].copy()) for i in range(len(p))]


def substeps_per_frame(dt: float, frame_rate: float = FRAME_RATE) -> int:
    """Substeps per output frame for a substep ``dt``; it must divide the frame period."""
    k = 1.0 / (dt * frame_rate)
    if abs(k - round(k)) > 1e-6 or round(k) < 1:
        raise ValueError(f'solver.dt {dt!r} s must divide the frame period 1/{frame_rate:g} s')
    return int(round(k))


# ================================================================================= scoring
class Scorer:
    """Per-frame metrics of a method's output against stored reference frames."""

    def __init__(self, workload: Workload, ref_frames: np.ndarray, ref_settled: np.ndarray):
        self.w = workload
        self.ref = ref_frames                          # (F, S, N, 3) float32
        self.ref0 = np.asarray(ref_settled, dtype=np.float64)
        #: the scene's colliders, measured bare: the head (``pen``), the bust and slots
        #: (``pen_body``)
        self.colliders = ColliderTable(workload.scene)
        self._order = np.argsort(workload.groups, kind='stable')
        g = workload.groups[self._order]
        self._starts = np.flatnonzero(np.r_[True, g[1:] != g[:-1]])
        self._sizes = np.diff(np.r_[self._starts, len(g)])
        self.ref_spread = np.array([self.spread(f.astype(np.float64)) for f in ref_frames])

    def spread(self, x: np.ndarray) -> float:
        """Sum over fixed groups and free nodes of the squared distance to the group's centre of
        mass (same node index) [m^2]."""
        xs = x[self._order, 2:]
        com = np.add.reduceat(xs, self._starts, axis=0) / self._sizes[:, None, None]
        d = xs - np.repeat(com, self._sizes, axis=0)
        return float(np.einsum('snk,snk->', d, d))

    def frame(self, j: int, x: np.ndarray, head: HeadPose, x0: np.ndarray) -> Dict[str, float]:
        """Metrics of frame ``j``; ``x0`` is the method's settled state before the motion (for
        the motion error: how far the hair moved from where it started, against how far the
        reference moved from where it started)."""
        if not np.all(np.isfinite(x)):
            return {'rms': math.inf, 'max': math.inf, 'tip': math.inf, 'stretch': math.inf,
                    'pen': math.inf, 'pen_body': math.inf, 'spread': math.nan,
                    'motion': math.inf}
        ref = self.ref[j].astype(np.float64)
        rms, mx = position_error(x, ref, self.w.strand_length)
        motion, _ = position_error(x - x0, ref - self.ref0, self.w.strand_length)
        pen = pen_body = 0.0
        if self.colliders.head is not None:
            pen = self.colliders.head.penetration(x, head, self.w.inv_mass)
        pen_body = self.colliders.body_depth(x, head, self.w.inv_mass)
        rs = self.ref_spread[j]
        return {'rms': rms, 'max': mx, 'tip': tip_error(x, ref, self.w.strand_length),
                'stretch': max_stretch(x, self.w.rest_length), 'pen': pen, 'pen_body': pen_body,
                'spread': self.spread(x) / rs if rs > 0 else math.nan, 'motion': motion}


@dataclass
class RunResult:
    """One method on one trajectory."""

    spec: 'MethodSpec'
    name: str
    family: str
    knobs: Dict
    note: str = ''
    per_frame: Dict[str, np.ndarray] = field(default_factory=dict)   # metric -> (F,)
    frame_ms: List[np.ndarray] = field(default_factory=list)        # one array per timed run
    failed: str = ''
    horizon: int = 0                  # frames of the predictable window (0: all)

    def summary(self) -> Dict[str, float]:
        pf = self.per_frame
        runs = [float(np.median(r)) for r in self.frame_ms if len(r)]
        h = self.horizon or None
        out = {
            'ms_frame': float(np.median(runs)) if runs else math.nan,
            'ms_frame_min_run': min(runs) if runs else math.nan,
            'ms_frame_max_run': max(runs) if runs else math.nan,
            'rms_err': float(np.sqrt(np.mean(pf['rms'] ** 2))) if 'rms' in pf else math.nan,
            'motion_err': float(np.sqrt(np.mean(pf['motion'] ** 2))) if 'motion' in pf
            else math.nan,
            'rms_err_pred': float(np.sqrt(np.mean(pf['rms'][:h] ** 2))) if 'rms' in pf
            else math.nan,
            'tip_err_pred': float(np.mean(pf['tip'][:h])) if 'tip' in pf else math.nan,
            'max_err': float(np.max(pf['max'])) if 'max' in pf else math.nan,
            'tip_err': float(np.mean(pf['tip'])) if 'tip' in pf else math.nan,
            'max_stretch': float(np.max(pf['stretch'])) if 'stretch' in pf else math.nan,
            'penetration_mm': 1e3 * float(np.max(pf['pen'])) if 'pen' in pf else math.nan,
            'spread_ratio': float(np.nanmean(pf['spread'])) if 'spread' in pf else math.nan,
        }
        return out


def settle(method: Method, head: HeadPose, seconds: float, speed: float = 0.0) -> float:
    """Rest shape at ``head``: ``seconds`` of substeps with the head still, then, with ``speed``
    [m/s], on until no output node moves faster (:func:`hair_tracking.core.settle.settle`);
    velocities zeroed.  Returns the time simulated [s]."""
    method.reset(head)
    simulated = settle_until_still(
        lambda steps: method.advance(method.dt, head, [head] * steps),
        lambda: [method.output(head)], method.dt, seconds, speed)
    method.output(head)             # methods that work per frame catch up here
    method.zero_velocities()
    return simulated


def run_frames(method: Method, schedule: HeadSchedule, frames: int,
               on_frame: Optional[Callable[[int, np.ndarray, HeadPose], None]] = None,
               settle_s: float = 0.0, settle_speed: float = 0.0) -> np.ndarray:
    """Settle (:func:`settle`), then run ``frames`` output frames; returns the seconds each
    frame took (only the stepping and the output, not ``on_frame`` nor what the method reports
    in ``excluded_seconds``, i.e. pypbd's root driving).  ``on_frame(j, x, head)`` is called with
    ``j = -1`` once after settling, then for every frame ``j = 0 .. frames - 1``.  Stops early
    (returning fewer times) when the output becomes non-finite."""
    k = substeps_per_frame(method.dt, schedule.frame_rate)
    poses = schedule.poses(k)
    head0 = schedule.start()
    settle(method, head0, settle_s, settle_speed)
    if on_frame is not None:
        on_frame(-1, method.output(head0), head0)       # the settled state, before the motion
    secs = np.empty(frames)
    prev = head0
    dt = method.dt
    perf = time.perf_counter
    for j in range(frames):
        excluded = method.excluded_seconds
        t0 = perf()
        method.advance(dt, prev, poses[j])
        prev = poses[j][-1]
        x = method.output(prev)
        secs[j] = perf() - t0 - (method.excluded_seconds - excluded)
        if on_frame is not None:
            on_frame(j, x, prev)
        if j % 16 == 0 and not np.all(np.isfinite(x)):
            return secs[:j + 1]
    return secs


def reference_scene(scene: Scene, substeps: int = REFERENCE['substeps'],
                    iterations: int = REFERENCE['iterations'],
                    frame_rate: float = FRAME_RATE) -> Scene:
    return scene.with_changes(solver__type='xpbd', solver__compliance=0.0,
                              solver__dt=1.0 / (frame_rate * substeps),
                              solver__iterations=iterations, solver__max_substeps=10_000)


def record_reference(workload: Workload, schedule: HeadSchedule,
                     scene: Optional[Scene] = None, log=print):
    """Run the reference; returns its frames (F, S, N, 3) as float32 [m], its settled state
    before the motion (S, N, 3) and the seconds each frame took."""
    scene = scene or reference_scene(workload.scene)
    ref = FullSim('reference', workload, scene)
    out = np.empty((schedule.frames,) + workload.ghost_rest.shape, dtype=np.float32)
    settled = np.empty(workload.ghost_rest.shape)

    def keep(j, x, head):
        if j < 0:
            settled[...] = x
        else:
            out[j] = x

    t0 = time.perf_counter()
    secs = run_frames(ref, schedule, schedule.frames, keep, scene.solver.settle_time,
                      scene.solver.settle_speed)
    if len(secs) < schedule.frames:
        raise RuntimeError('the reference run produced non-finite positions')
    log(f'  reference ({scene.solver.type}, dt 1/{1 / scene.solver.dt:.0f} s, '
        f'{scene.solver.iterations} it): {time.perf_counter() - t0:.1f} s, '
        f'{1e3 * np.median(secs):.1f} ms/frame')
    return out, settled, secs


def perturbed_reference(workload: Workload, schedule: HeadSchedule, ref_frames: np.ndarray,
                        ref_settled: np.ndarray, scene: Scene,
                        perturbation: float = CHAOS_PERTURBATION, seed: int = 0) -> np.ndarray:
    """Per-frame RMS distance [L] between the reference and the reference rerun with its
    settled state moved by ``perturbation`` [m] (normal noise on the free nodes): a measure of
    how sensitive the motion is (hair sliding over the scalp can fall either way)."""
    method = FullSim('reference perturbed', workload, scene)
    rng = np.random.default_rng(seed)
    out = np.empty(schedule.frames)

    def watch(j, x, head):
        if j < 0:                       # x is the solver's state: perturb it in place
            x[:, 2:] += rng.normal(scale=perturbation, size=x[:, 2:].shape)
            return
        out[j] = position_error(x, ref_frames[j].astype(np.float64), workload.strand_length)[0]
    run_frames(method, schedule, schedule.frames, watch, scene.solver.settle_time,
               scene.solver.settle_speed)
    return out


def reference_convergence(workload: Workload, schedule: HeadSchedule, ref_frames: np.ndarray,
                          ref_settled: np.ndarray, frames: int, log=print) -> Dict[str, float]:
    """Error of the reference against a run with twice the substeps and twice the iterations
    over the first ``frames`` frames: the reference's own discretisation error."""
    fine = reference_scene(workload.scene, 2 * REFERENCE['substeps'],
                           2 * REFERENCE['iterations'], schedule.frame_rate)
    scorer = Scorer(workload, ref_frames[:frames], ref_settled)
    method = FullSim('reference x2', workload, fine)
    res = RunResult(None, method.name, method.family, {})
    pf = {k: np.empty(frames) for k in METRICS}
    x0 = np.empty(workload.ghost_rest.shape)

    def score(j, x, head):
        if j < 0:
            x0[...] = x
            return
        for key, val in scorer.frame(j, x, head, x0).items():
            pf[key][j] = val
    run_frames(method, schedule, frames, score, fine.solver.settle_time,
               fine.solver.settle_speed)
    res.per_frame = pf
    s = res.summary()
    log(f'  reference self-convergence over {frames} frames: RMS {s["rms_err"]:.2e} L, '
        f'max {s["max_err"]:.2e} L')
    return {'frames': frames, 'rms_err': s['rms_err'], 'max_err': s['max_err'],
            'tip_err': s['tip_err'], 'motion_err': s['motion_err']}


# ============================================================================ method lists
@dataclass
class MethodSpec:
    """How to build one method (built lazily: pypbd can hold one model at a time)."""

    name: str
    family: str
    build: Callable[[Workload], Method]
    knobs: Dict = field(default_factory=dict)


GHOST_VARIANTS = {
    # name: (tracking changes, description)
    'all on': ({}, 'weights, CoM tracking, length restoration, collision (defaults)'),
    'no collision': ({'collide': False}, 'ghosts pass through the head'),
    'once per frame': ({'every_substep': False},
                       'tracked once per 1/60 s frame over its substeps'),
    'no weights': ({'elastic_weight': False, 'tip_weight': 0.0, 'com_weight': 0.0},
                   'equations (4)-(5) off'),
    'no CoM': ({'com_strength': 0.0}, 'centre-of-mass tracking off'),
    'no restore': ({'length_restore': False}, 'length restoration (FTL pass) off'),
    'plain copy': ({'elastic_weight': False, 'tip_weight': 0.0, 'com_weight': 0.0,
                    'com_strength': 0.0, 'length_restore': False, 'collide': False},
                   'velocity copy + offset feedback only'),
}


def _solver_scene(scene: Scene, kind: str, dt: float, iterations: int) -> Scene:
    return scene.with_changes(solver__type=kind, solver__dt=dt, solver__iterations=iterations,
                              solver__max_substeps=10_000)


def default_methods(scene: Scene, quick: bool = False, with_pypbd: bool = True
                    ) -> List[MethodSpec]:
    """The compared methods and their knob ranges (fewer with ``quick``)."""
    f = FRAME_RATE
    specs: List[MethodSpec] = []
    full = {
        'pbd': [(1, 4), (2, 4), (4, 1), (4, 4), (4, 16)],
        'xpbd': [(1, 4), (2, 4), (4, 1), (4, 4), (4, 16)],
        'ftl': [(1, 1), (2, 1), (4, 1), (8, 1)],
    }
    if quick:
        full = {'pbd': [(4, 4)], 'xpbd': [(4, 4)], 'ftl': [(1, 1), (4, 1)]}
    for kind, settings in full.items():
        for k, it in settings:
            sc = _solver_scene(scene, kind, 1.0 / (f * k), it)
            label = f'full {kind.upper()} dt 1/{int(f * k)}' + \
                (f' {it} it' if kind != 'ftl' else '')
            specs.append(MethodSpec(label, 'full', lambda w, sc=sc, n=label: FullSim(n, w, sc),
                                    {'solver': kind, 'dt': sc.solver.dt, 'iterations': it}))
    ratios = (1, 4, 16, 64) if not quick else (4, 16)
    variants = list(GHOST_VARIANTS) if not quick else ['all on', 'plain copy']
    for r in ratios:
        for v in variants:
            sc = scene.with_changes(**{'tracking__' + a: b
                                       for a, b in GHOST_VARIANTS[v][0].items()})
            label = f'ghost 1:{r} {v}'
            specs.append(MethodSpec(
                label, 'ghost', lambda w, sc=sc, n=label, r=r: GhostTracking(n, w, sc, r),
                {'ratio': r, 'variant': v, 'solver': scene.solver.type, 'dt': scene.solver.dt,
                 'iterations': scene.solver.iterations}))
    if not quick:
        # the ghost method at coarser substeps (guides and ghosts step together)
        for k in (1, 2):
            for r in (4, 16, 64):
                sc = _solver_scene(scene, scene.solver.type, 1.0 / (f * k),
                                   scene.solver.iterations)
                label = f'ghost 1:{r} all on dt 1/{int(f * k)}'
                specs.append(MethodSpec(
                    label, 'ghost', lambda w, sc=sc, n=label, r=r: GhostTracking(n, w, sc, r),
                    {'ratio': r, 'variant': f'all on, dt 1/{int(f * k)}',
                     'solver': scene.solver.type, 'dt': sc.solver.dt,
                     'iterations': scene.solver.iterations}))
    for r in ratios:
        label = f'rigid offset 1:{r}'
        specs.append(MethodSpec(label, 'rigid',
                                lambda w, n=label, r=r: RigidOffset(n, w, scene, r),
                                {'ratio': r, 'solver': scene.solver.type,
                                 'dt': scene.solver.dt}))
    if with_pypbd:
        for k, it in ([(1, 4), (4, 4)] if not quick else [(4, 4)]):
            sc = _solver_scene(scene, 'pbd', 1.0 / (f * k), it)
            label = f'pypbd dt 1/{int(f * k)} {it} it'
            specs.append(MethodSpec(label, 'pypbd',
                                    lambda w, sc=sc, n=label: PyPBD(n, w, sc),
                                    {'solver': 'pbd', 'dt': sc.solver.dt, 'iterations': it}))
    return specs


# ============================================================================== evaluation
@dataclass
class Trajectory:
    name: str
    motion: HeadMotion
    description: str
    duration_s: Optional[float] = None


@dataclass
class MotionReport:
    trajectory: Trajectory
    frames: int
    reference_ms: float
    convergence: Dict[str, float]
    results: List[RunResult]
    skipped: List[str]
    chaos: Optional[np.ndarray] = None    # (F,) RMS [L] of the perturbed reference
    horizon: int = 0                      # frames of the predictable window

    @property
    def horizon_s(self) -> float:
        return (self.horizon or self.frames) / FRAME_RATE


def evaluate(workload: Workload, trajectory: Trajectory, specs: Sequence[MethodSpec],
             repeats: int = 2, timing_frames: int = 120, log=print,
             convergence_frames: int = 0) -> MotionReport:
    """Run the reference and every method on one trajectory; see the module docstring."""
    sched = HeadSchedule(trajectory.motion, FRAME_RATE, trajectory.duration_s)
    log(f'{trajectory.name}: {sched.frames} frames ({sched.duration_s:.1f} s), '
        f'{workload.count} ghost strands x {workload.ghost_rest.shape[1]} nodes')
    ref_scene = reference_scene(workload.scene)
    ref, ref0, ref_secs = record_reference(workload, sched, ref_scene, log)
    ref_ms = 1e3 * float(np.median(ref_secs))
    conv = {}
    if convergence_frames:
        conv = reference_convergence(workload, sched, ref, ref0,
                                     min(convergence_frames, sched.frames), log)
    chaos = perturbed_reference(workload, sched, ref, ref0, ref_scene)
    above = np.flatnonzero(chaos > CHAOS_RMS)
    horizon = int(above[0]) if above.size else sched.frames
    horizon = max(horizon, 1)
    log(f'  1 um perturbation of the reference grows past {100 * CHAOS_RMS:g} % L after '
        f'{horizon / FRAME_RATE:.2f} s (predictable window), ends at {100 * chaos[-1]:.1f} % L')
    scorer = Scorer(workload, ref, ref0)
    settle_s = workload.scene.solver.settle_time
    settle_speed = workload.scene.solver.settle_speed
    results, skipped = [], []
    for spec in specs:
        try:
            method = spec.build(workload)
        except Exception as e:            # noqa: BLE001 - reported, the rest still runs
            skipped.append(f'{spec.name}: could not be built ({e})')
            log(f'  skip {spec.name}: {e}')
            continue
        res = RunResult(spec, method.name, method.family, {**method.knobs, **spec.knobs},
                        horizon=horizon)
        pf = {k: np.full(sched.frames, np.nan) for k in METRICS}
        x0 = np.empty(workload.ghost_rest.shape)

        def score(j, x, head, pf=pf, x0=x0):
            if j < 0:
                x0[...] = x
                return
            for key, val in scorer.frame(j, x, head, x0).items():
                pf[key][j] = val
        try:
            run_frames(method, sched, 2, None, 0.0)            # compile + warm up, not timed
            method.excluded_seconds = 0.0
            secs = run_frames(method, sched, sched.frames, score, settle_s,
                              settle_speed)
            res.frame_ms.append(1e3 * secs)
            if len(secs) < sched.frames:
                res.failed = f'non-finite output at frame {len(secs)}'
                for key in pf:
                    pf[key][len(secs):] = math.inf
            if method.excluded_seconds > 0.0:
                method.note += (f'; {1e3 * method.excluded_seconds / len(secs):.2f} ms/frame '
                                'of Python root driving not counted')
        finally:
            res.per_frame = pf
            res.note = method.note
            method.close()
        results.append(res)
        s = res.summary()
        log(f'  {spec.name:34s} {s["ms_frame"]:8.2f} ms/frame  RMS {s["rms_err"]:.3e} L  '
            f'max {s["max_err"]:.3e} L  stretch {s["max_stretch"]:.2e}  '
            f'pen {s["penetration_mm"]:.2f} mm  spread {s["spread_ratio"]:.2f}'
            + (f'  FAILED: {res.failed}' if res.failed else ''))
    # timing runs, interleaved so that load changes on the machine hit every method alike
    frames = min(timing_frames, sched.frames)
    for rep in range(repeats):
        for res in results:
            method = res.spec.build(workload)
            try:
                run_frames(method, sched, 2, None, 0.0)
                res.frame_ms.append(1e3 * run_frames(method, sched, frames, None, settle_s,
                                                     settle_speed))
            finally:
                method.close()
        log(f'  timing run {rep + 1}/{repeats} done')
    return MotionReport(trajectory, sched.frames, ref_ms, conv, results, skipped, chaos,
                        horizon)


# ================================================================================== output
CSV_COLUMNS = ('motion', 'method', 'family', 'ratio', 'variant', 'solver', 'dt', 'iterations',
               'ms_frame', 'ms_frame_min_run', 'ms_frame_max_run', 'rms_err_pred',
               'tip_err_pred', 'rms_err', 'motion_err', 'max_err', 'tip_err', 'max_stretch',
               'penetration_mm', 'spread_ratio', 'pareto', 'pareto_full', 'predictable_s',
               'note')


def pareto_front(points: Sequence[tuple]) -> List[int]:
    """Indices of the points (time, error) not dominated by another point (no other point is at
    least as fast and at least as accurate, and strictly better in one), sorted by time."""
    idx = [i for i, (t, e) in enumerate(points) if math.isfinite(t) and math.isfinite(e)]
    idx.sort(key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in idx:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def rows(report: MotionReport) -> List[Dict]:
    out = []
    summaries = [r.summary() for r in report.results]
    front = set(pareto_front([(s['ms_frame'], s['rms_err_pred']) for s in summaries]))
    front_f = set(pareto_front([(s['ms_frame'], s['rms_err']) for s in summaries]))
    for i, (res, s) in enumerate(zip(report.results, summaries)):
        k = res.knobs
        row = {'motion': report.trajectory.name, 'method': res.name, 'family': res.family,
               'ratio': k.get('ratio', ''), 'variant': k.get('variant', ''),
               'solver': k.get('solver', ''), 'dt': k.get('dt', ''),
               'iterations': k.get('iterations', ''), 'pareto': int(i in front),
               'pareto_full': int(i in front_f),
               'note': '; '.join(x for x in (res.note, res.failed) if x)}
        row.update(s)
        row['predictable_s'] = report.horizon_s
        out.append(row)
    return out


def write_csv(path: str, all_rows: List[Dict]) -> None:
    with open(path, 'w', newline='', encoding='utf-8') as f:
        wr = csv.DictWriter(f, fieldnames=CSV_COLUMNS, extrasaction='ignore')
        wr.writeheader()
        for r in all_rows:
            wr.writerow({k: _fmt(r.get(k, '')) for k in CSV_COLUMNS})


def _fmt(v):
    if isinstance(v, float):
        if not math.isfinite(v):
            return str(v)
        return f'{v:.6g}'
    return v


def markdown_table(report: MotionReport) -> str:
    conv = report.convergence
    lines = [f'### {report.trajectory.name}: {report.trajectory.description}', '',
             f'{report.frames} frames at {FRAME_RATE:g} Hz; reference '
             f'{report.reference_ms:.0f} ms/frame.'
             + (f' Reference self-convergence (against twice the substeps and iterations, first '
                f'{conv["frames"]} frames): RMS {100 * conv["rms_err"]:.2f} % L, max '
                f'{100 * conv["max_err"]:.1f} % L.' if conv else '')
             + (f' Predictable window: the first {report.horizon_s:.2f} s (a 1 um '
                f'perturbation of the reference stays below {100 * CHAOS_RMS:g} % L RMS; at '
                f'the end it reaches {100 * report.chaos[-1]:.1f} % L).'
                if report.chaos is not None else ''), '',
             '| method | ms/frame | RMS err, predictable [% L] | tip err, predictable [% L] | '
             'RMS err, whole run [% L] | motion err, whole run [% L] | max err [% L] | '
             'max stretch [%] | penetration [mm] | spread ratio | Pareto (pred. / whole) | '
             'note |',
             '|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|:---:|---|']
    for r in rows(report):
        front = ('*' if r['pareto'] else '') + ' / ' + ('*' if r['pareto_full'] else '')
        lines.append(
            f'| {r["method"]} | {r["ms_frame"]:.2f} | {100 * r["rms_err_pred"]:.2f} | '
            f'{100 * r["tip_err_pred"]:.2f} | {100 * r["rms_err"]:.2f} | '
            f'{100 * r["motion_err"]:.2f} | {100 * r["max_err"]:.1f} | '
            f'{100 * r["max_stretch"]:.2f} | {r["penetration_mm"]:.1f} | '
            f'{r["spread_ratio"]:.2f} | {front if front != " / " else ""} | {r["note"]} |')
    for s in report.skipped:
        lines.append(f'\nSkipped: {s}')
    return '\n'.join(lines) + '\n'


# =================================================================================== plots
_STYLE = {
    'full PBD': ('tab:blue', 's'), 'full XPBD': ('tab:cyan', 'D'), 'full FTL': ('tab:purple', 'v'),
    'ghost all on': ('tab:red', 'o'), 'ghost no weights': ('tab:orange', 'o'),
    'ghost no CoM': ('tab:olive', 'o'), 'ghost no restore': ('gold', 'o'),
    'ghost plain copy': ('tab:brown', 'o'), 'ghost no collision': ('darkred', 'P'),
    'ghost once per frame': ('tab:pink', 's'),
    'ghost all on, dt 1/60': ('salmon', 'h'), 'ghost all on, dt 1/120': ('firebrick', 'p'),
    'rigid offset': ('tab:gray', 'x'), 'pypbd': ('tab:green', '^'),
}


def series_of(row: Dict) -> str:
    fam = row['family']
    if fam == 'full':
        return 'full ' + str(row['solver']).upper()
    if fam == 'ghost':
        return 'ghost ' + str(row['variant'])
    if fam == 'rigid':
        return 'rigid offset'
    return fam


def plot_pareto(path: str, report_rows: List[Dict], title: str) -> None:
    """Log-log error against ms/frame, one series per method family, Pareto fronts marked:
    left the position error, right the motion error (see the module docstring)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.4), dpi=100)
    panels = (('rms_err_pred', 'pareto', 'position error |x - x_ref| / L, RMS over the '
                                         'predictable window'),
              ('rms_err', 'pareto_full', 'position error |x - x_ref| / L, RMS over the whole '
                                         'run'))
    for ax, (key, flag, label) in zip(axes, panels):
        by = {}
        for r in report_rows:
            if math.isfinite(r['ms_frame']) and math.isfinite(r[key]) and r[key] > 0:
                by.setdefault(series_of(r), []).append(r)
        for name, rs in by.items():
            color, marker = _STYLE.get(name, ('black', '.'))
            rs = sorted(rs, key=lambda r: r['ms_frame'])
            ax.plot([r['ms_frame'] for r in rs], [100 * r[key] for r in rs], marker=marker,
                    color=color, ls='-' if len(rs) > 1 else 'none', lw=0.8, ms=6, label=name,
                    alpha=0.9)
            for r in rs:
                lab = _short_label(r)
                if lab:
                    ax.annotate(lab, (r['ms_frame'], 100 * r[key]), fontsize=6.5,
                                xytext=(3, 3), textcoords='offset points', color=color)
        front = sorted([r for r in report_rows if r[flag]], key=lambda r: r['ms_frame'])
        if front:
            xs, ys = [], []
            for r in front:
                if xs:
                    xs.append(r['ms_frame'])
                    ys.append(ys[-1])
                xs.append(r['ms_frame'])
                ys.append(100 * r[key])
            ax.plot(xs, ys, color='black', lw=1.6, ls='--', zorder=0, label='Pareto front')
            ax.scatter([r['ms_frame'] for r in front], [100 * r[key] for r in front],
                       s=140, facecolors='none', edgecolors='black', lw=1.2, zorder=5)
        ax.set_xscale('log')
        ax.set_yscale('log')
        ax.set_xlabel('run time per 1/60 s frame [ms] (median, log)')
        ax.set_ylabel(label + ' [% of strand length] (log)')
        ax.grid(True, which='both', alpha=0.3)
    axes[0].legend(fontsize=7.5, loc='best', ncol=2)
    fig.suptitle(title + '  (labels: guide ratio, or substeps per frame x iterations)',
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _short_label(r: Dict) -> str:
    fam = r['family']
    if fam in ('ghost', 'rigid'):
        shown = fam == 'rigid' or str(r.get('variant', '')).startswith(('all on', 'once'))
        return f'1:{r["ratio"]}' if shown else ''
    if fam in ('full', 'pypbd'):
        k = int(round(1.0 / (float(r['dt']) * FRAME_RATE)))
        it = '' if r['solver'] == 'ftl' else f'x{r["iterations"]}'
        return f'{k}{it}'
    return ''


def plot_error_over_time(path: str, report: MotionReport, names: Sequence[str]) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(9.5, 4.5), dpi=110)
    t = (np.arange(report.frames) + 1) / FRAME_RATE
    for res in report.results:
        if res.name in names and 'rms' in res.per_frame:
            ax.plot(t, 100 * res.per_frame['rms'], lw=1.0, label=res.name)
    if report.chaos is not None:
        ax.plot(t, 100 * report.chaos, color='black', ls='--', lw=1.2,
                label='reference perturbed by 1 um')
        ax.axvline(report.horizon_s, color='black', lw=0.8, ls=':')
        ax.annotate('end of the predictable window', (report.horizon_s, 0.98),
                    xycoords=('data', 'axes fraction'), fontsize=7.5, ha='left', va='top',
                    xytext=(3, 0), textcoords='offset points')
    motion = report.trajectory.motion
    from hair_tracking.motion.head_motion import angular_speed
    w = angular_speed(motion)
    ax2 = ax.twinx()
    ax2.plot(motion.t_s[1:], w, color='0.6', lw=0.6, alpha=0.6)
    ax2.set_ylabel('head angular speed [rad/s]', color='0.4')
    ax2.set_xlim(0, t[-1])
    ax.set_xlabel('time [s]')
    ax.set_ylabel('RMS position error [% of strand length]')
    ax.set_title(f'Error over time: {report.trajectory.name} ({report.trajectory.description})',
                 fontsize=10)
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc='upper left')
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_outputs(reports: List[MotionReport], out_dir: str, fig_dir: str, record: dict,
                  notes: Sequence[str] = (), time_series: Sequence[str] = ()) -> Dict[str, str]:
    """CSV, Markdown and PNG plots of the reports, the Markdown headed by ``record``
    (:func:`hair_tracking.evaluation.provenance.provenance`); returns {kind: path}."""
    from hair_tracking.evaluation.provenance import markdown_lines
    os.makedirs(out_dir, exist_ok=True)
    os.makedirs(fig_dir, exist_ok=True)
    all_rows = [r for rep in reports for r in rows(rep)]
    paths = {'csv': os.path.join(out_dir, 'accuracy.csv'),
             'md': os.path.join(out_dir, 'accuracy.md')}
    write_csv(paths['csv'], all_rows)
    md = ['# Error against run time', ''] + markdown_lines(record)
    md += [f'- {n}' for n in notes]
    md.append('')
    for rep in reports:
        png = os.path.join(fig_dir, f'pareto_{rep.trajectory.name}.png')
        plot_pareto(png, rows(rep), f'{rep.trajectory.name}: {rep.trajectory.description}')
        paths['pareto_' + rep.trajectory.name] = png
        md.append(markdown_table(rep))
        md.append(f'![Pareto plot, {rep.trajectory.name}]'
                  f'({os.path.relpath(png, out_dir)})\n')
        if time_series:
            png = os.path.join(fig_dir, f'error_time_{rep.trajectory.name}.png')
            plot_error_over_time(png, rep, time_series)
            paths['time_' + rep.trajectory.name] = png
            md.append(f'![Error over time, {rep.trajectory.name}]'
                      f'({os.path.relpath(png, out_dir)})\n')
    with open(paths['md'], 'w', encoding='utf-8') as f:
        f.write('\n'.join(md))
    return paths


__all__ = ['FRAME_RATE', 'REFERENCE', 'HeadSchedule', 'Scorer', 'RunResult', 'MethodSpec',
           'Trajectory', 'MotionReport', 'default_methods', 'evaluate', 'pareto_front',
           'interpolate_poses', 'record_reference', 'reference_convergence', 'settle',
           'run_frames', 'rows', 'write_csv', 'markdown_table', 'plot_pareto',
           'plot_error_over_time', 'write_outputs', 'make_workload', 'pypbd_available']
