"""Stability matrix: stiff and extreme cases, each run to completion with pass/fail.

Every case drives a :class:`~hair_tracking.simulator.HairSimulator` (guides + ghosts, the product
path) with a head-pose stream, calling ``push_pose`` then ``advance_to`` per pose as the ROS node
does, and
ends with a still head (the *tail*) so that a blow-up cannot hide behind motion.  After every
``check_every``-th pose it measures the worst figures; a case **passes** when, everywhere:

1. **finite** -- no NaN or Inf in guide or ghost positions or velocities;
2. **stretch** -- ``max |l/l0 - 1|`` of the guides within the bound of their solver
   (:data:`STRETCH_BOUND`) and of the ghosts within :data:`GHOST_STRETCH_BOUND`;
3. **roots attached** -- nodes 0 and 1 of every guide and ghost within :data:`ROOT_TOLERANCE` of
   ``head.to_world(rest)`` at the simulator's current head pose;

   ghosts placed in float32 (the blend and turn trackers) are measured beyond what rounding
   their positions alone gives (:func:`float32_slack`: half an ulp a coordinate; for a
   segment twice that over its rest length);
4. **penetration** -- the free guide nodes at most one collider margin inside the bare collider
   (``scene.collider.margin``; the ghosts are measured too and reported, and held to the same
   bound when the scene lets them collide, ``tracking.collide``);
5. **bounded energy** -- the kinetic energy per node (unit node mass, guides and ghosts) never
   exceeds :func:`energy_bound`: four times what the head motion and gravity can give a node
   (``0.5 (v_head + w_head (r_head + L))^2 + |g| L``, the fastest a rigidly carried node moves
   plus a fall through one strand length) plus 0.5 J/kg; and over the still tail (no work is
   done on the hair) its mechanical energy, kinetic plus gravitational, does not rise (by more
   than :data:`ENERGY_RISE` of the kinetic peak plus :data:`KE_FLOOR`): a blow-up gains energy
   from nothing, a stable hair loses it (a long strand may still swing at the end of the tail;
   that is physics, not a failure).
   Velocities are taken from the displacement of the nodes between two checks (what the viewer
   sees; FTL's stored velocities do not vanish at rest).  The fastest single node is reported,
   not judged: the tip of a whip legitimately outruns the head several times.

Cases may add expectations (the glitch case: every invalid pose rejected, none of the valid ones;
the teleport: a reset happened).  The matrix (:func:`matrix`) covers stiffness 1 / compliance 0
with 1-200 iterations, segment lengths 1 mm-10 cm, time steps 1/1000-1/10 s, head angular speed
up to 50 rad/s and linear speed up to 20 m/s, a 1 m teleport, gravity up to 10 g, NaN / zero /
sign-flipped / unnormalised quaternions, a 1 kHz pose stream and one hour of simulated time, for
the three solvers where the solver matters.
"""
import csv
from dataclasses import dataclass, field, replace
import math
import os
import time
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np

from hair_tracking.colliders.body import neck_frame
from hair_tracking.core.metrics import max_stretch
from hair_tracking.core.scene import Scene
from hair_tracking.evaluation import synthetic_motion as sm
from hair_tracking.motion.head_motion import angular_speed, HeadMotion, linear_speed
from hair_tracking.motion.pose_table import load_bundled_walk
from hair_tracking.resources import config_path
from hair_tracking.simulator import HairSimulator

#: Bound on the guides' max stretch ``max |l/l0 - 1|`` per solver (see docs/stability.md).
STRETCH_BOUND = {'ftl': 1e-6, 'xpbd': 2.0, 'pbd': 2.0}
#: Bound on the ghosts' max stretch (length restoration on, the default: exact lengths).
GHOST_STRETCH_BOUND = 1e-6
#: Roots must sit this close [m] to where the head carries them.
ROOT_TOLERANCE = 1e-6
#: Energy per node [J/kg] below which changes count as noise (RMS speed 4.5 cm/s).
KE_FLOOR = 1e-3
#: The energy at the start and at the end of the still tail are means over this window [ns]:
#: a strand still swinging trades kinetic and potential energy within a period, and the
#: finite-difference kinetic energy of one sample depends on its phase.
WINDOW_NS = 100_000_000
#: Over the still tail the mechanical energy may rise by at most this fraction of the kinetic
#: energy peak (plus :data:`KE_FLOOR`): finite-difference velocities are a little noisy.
ENERGY_RISE = 0.05
#: Still head appended to every motion [s].
TAIL_S = 1.5

#: The small groom every case uses unless it says otherwise: 16 guides x 4 ghosts, 16 nodes.
BASE = Scene().with_changes(groom__guides=16, groom__ghosts_per_guide=4)


@dataclass
class Case:
    """One stability case: a scene, a head-pose stream and what it checks."""

    name: str
    group: str
    scene: Scene
    stream: Callable[[], object]       # -> HeadMotion or synthetic_motion.RawStream
    description: str
    check_every: int = 1
    tail_s: float = TAIL_S
    expect: Dict[str, object] = field(default_factory=dict)
    #: called with the simulator and the time since the first pose [s] before each pose is
    #: pushed: what changes besides the head (a TF body frame, the scene); returns true when
    #: a body jumped or appeared (the hair it moves out of it is not motion: the interval is
    #: not measured, as over a reset)
    events: Optional[Callable[[HairSimulator, float], bool]] = None


@dataclass
class CaseResult:
    case: Case
    passed: bool
    failures: List[str]
    worst: Dict[str, float]
    counters: Dict[str, int]
    wall_s: float
    sim_s: float


def energy_bound(motion: HeadMotion, scene: Scene, length: Optional[float] = None) -> float:
    """Largest kinetic energy per node [J/kg] a stable simulation of ``motion`` may reach (see
    the module docstring): ``4 (0.5 (v_head + w_head (r_head + L))^2 + |g| L) + 0.5``, with
    ``L`` the longest strand: ``length`` [m] when given (an imported groom's), else the
    procedural groom's longest."""
    v = float(linear_speed(motion).max()) if len(motion) > 1 else 0.0
    w = float(angular_speed(motion).max()) if len(motion) > 1 else 0.0
    r = float(max(scene.collider.radii + (scene.collider.radius,)))
    if length is None:
        length = scene.groom.length * (1.0 + scene.groom.length_variation)
    g = float(np.linalg.norm(scene.gravity))
    return 4.0 * (0.5 * (v + w * (r + length)) ** 2 + g * length) + 0.5


def _roots_error(strands, x, head, slack: float = 0.0) -> float:
    """How far [m] the roots of ``x`` (the positions of ``strands``) are from where the head
    carries them, less ``slack``."""
    want = head.to_world(strands.rest[:, :2])
    return max(0.0, float(np.max(np.abs(x[:, :2] - want))) - slack)


def float32_slack(x: np.ndarray) -> float:
    """The farthest [m] rounding to float32 can move a point of ``x`` (S, N, 3): half an ulp a
    coordinate."""
    return 0.5 * math.sqrt(3.0) * float(np.finfo(np.float32).eps) * float(np.abs(x).max())


def _states(sim):
    """``(strands, positions, velocities)`` of the guides and, with ghosts, of the ghosts (from
    their tracker)."""
    out = [(sim.guides, sim.guides.x, sim.guides.v)]
    if sim.ghost_tracker is not None:
        out.append((sim.ghosts, sim.ghost_tracker.positions(), sim.ghost_tracker.velocities()))
    return out


def _motion_energy(x, x_prev, seconds):
    """(kinetic energy per node [J/kg], fastest node [m/s]) from the displacement of all nodes
    over ``seconds``: the velocity the hair really has, whatever the solver stores (FTL's stored
    velocities do not vanish at rest, see :mod:`hair_tracking.guides.ftl`)."""
    v2 = np.einsum('nk,nk->n', x - x_prev, x - x_prev) / (seconds * seconds)
    return 0.5 * float(v2.mean()), math.sqrt(float(v2.max()))


def run_case(case: Case) -> CaseResult:
    """Run one case to completion (a non-finite state stops it early as a failure)."""
    t_wall = time.perf_counter()
    scene = case.scene
    src = case.stream()
    if isinstance(src, sm.RawStream):
        motion_for_bound = None
        t_ns, pos, quat = src.t_ns, src.position, src.quaternion
        valid = src.valid
        clean = HeadMotion(t_ns[valid], pos[valid], quat[valid] /
                           np.linalg.norm(quat[valid], axis=1, keepdims=True))
        motion_for_bound = clean
    else:
        motion = sm.with_tail(src, case.tail_s) if case.tail_s > 0 else src
        t_ns, pos, quat = motion.t_ns, motion.position, motion.quaternion
        motion_for_bound = motion
    if isinstance(src, sm.RawStream) and case.tail_s > 0:
        # a still tail after the last valid pose
        last = np.flatnonzero(src.valid)[-1]
        extra = sm.times_ns(case.tail_s, 120.0)[1:]
        t_ns = np.concatenate([t_ns, t_ns[-1] + extra])
        pos = np.concatenate([pos, np.repeat(pos[last:last + 1], len(extra), 0)])
        quat = np.concatenate([quat, np.repeat(quat[last:last + 1], len(extra), 0)])
    tail_start = int(t_ns[-1] - round(case.tail_s * 1e9))
    sim = HairSimulator(scene)
    ke_max = energy_bound(motion_for_bound, scene, length=max(
        float(s.strand_length.max()) for s in (sim.guides, sim.ghosts)
        if s is not None) if scene.groom.file else None)
    f32_ghosts = sim.ghost_tracker is not None and \
        sim.ghost_tracker.positions().dtype == np.float32
    if sim.ghosts is not None:         # the shortest ghost segment, for float32 rounding
        rest = sim.ghosts.rest_length
        shortest = float(rest[rest > 0].min())
    worst = {'stretch_guides': 0.0, 'stretch_ghosts': 0.0, 'root_err_m': 0.0,
             'pen_guides_mm': 0.0, 'pen_ghosts_mm': 0.0, 'pen_body_mm': 0.0, 'max_speed': 0.0,
             'push_gain': 0.0,
             'ke_bound': ke_max, 'ke_peak': 0.0, 'ke_end': math.nan, 'energy_rise': math.nan,
             'drift': math.nan}
    failures: List[str] = []
    ke_end_samples: List[float] = []
    end_energy: List[float] = []
    start_energy: List[float] = []
    g_vec = np.asarray(scene.gravity, dtype=np.float64)
    g_mag = float(np.linalg.norm(g_vec))
    up = -g_vec / g_mag if g_mag > 0 else np.zeros(3)
    n = len(t_ns)
    last_check_t = int(t_ns[-1] - WINDOW_NS)     # the last 0.1 s are "the end"
    finite = True
    x_prev, t_prev, resets_prev = None, 0, 0
    event_s = case.expect.get('push_gain', (math.inf, math.inf))[0]
    around = [0.0, 0.0]        # fastest stored guide speed before and after the event
    for i in range(n):
        t = int(t_ns[i])
        jumped = case.events is not None and bool(case.events(sim, (t - int(t_ns[0])) * 1e-9))
        sim.push_pose(t, pos[i], quat[i])
        sim.advance_to(t)
        if i % case.check_every and i != n - 1 and t < last_check_t:
            continue
        states = _states(sim)
        if not all(np.all(np.isfinite(x)) and np.all(np.isfinite(v)) for _, x, v in states):
            failures.append(f'non-finite state at t = {(t - t_ns[0]) * 1e-9:.3f} s')
            finite = False
            break
        head = sim.head
        worst['stretch_guides'] = max(worst['stretch_guides'],
                                      max_stretch(sim.guides.x, sim.guides.rest_length))
        slack = 0.0
        if sim.ghost_tracker is not None:
            ghost_x = states[1][1]
            if f32_ghosts:
                slack = float32_slack(ghost_x)
            worst['stretch_ghosts'] = max(worst['stretch_ghosts'], max_stretch(
                ghost_x, sim.ghosts.rest_length) - 2.0 * slack / shortest)
        worst['root_err_m'] = max(worst['root_err_m'],
                                  *(_roots_error(s, x, head, slack if s is sim.ghosts else 0.0)
                                    for s, x, _ in states))
        collider = sim.colliders.head
        if collider is not None:
            worst['pen_guides_mm'] = max(worst['pen_guides_mm'], 1e3 * collider.penetration(
                sim.guides.x, head, sim.guides.inv_mass))
            if sim.ghost_tracker is not None:
                worst['pen_ghosts_mm'] = max(worst['pen_ghosts_mm'], 1e3 *
                                             collider.penetration(states[1][1], head,
                                                                  sim.ghosts.inv_mass))
        body = sim.guide_solver.body
        if body is not None:             # the bare bust: no node deeper than its margin
            worst['pen_body_mm'] = max(worst['pen_body_mm'], 1e3 * body.depth(
                sim.guides.x, head, sim.guides.inv_mass))
            if sim.ghost_tracker is not None:
                worst['pen_body_mm'] = max(worst['pen_body_mm'], 1e3 * (body.depth(
                    states[1][1], head) - slack))
        since = (t - int(t_ns[0])) * 1e-9 - event_s
        if -PUSH_WINDOW_S <= since < PUSH_WINDOW_S:
            v = math.sqrt(float(np.max(np.einsum('snk,snk->sn', sim.guides.v, sim.guides.v))))
            around[since >= 0.0] = max(around[since >= 0.0], v)
            worst['push_gain'] = around[1] - around[0]
        x_now = np.concatenate([x.reshape(-1, 3) for _, x, _ in states])
        t_sim = sim.time_ns
        moved = x_prev is not None and t_sim > t_prev and sim.counters.resets == resets_prev \
            and not jumped
        last = (x_prev, t_prev)
        if x_prev is None or t_sim > t_prev or sim.counters.resets != resets_prev:
            x_prev, t_prev, resets_prev = x_now, t_sim, sim.counters.resets
        if not moved:       # first check, no substep since the last one, a reset or a jump
            continue
        ke, speed = _motion_energy(x_now, last[0], (t_sim - last[1]) * 1e-9)
        energy = ke + g_mag * float(np.mean(x_now @ up))
        worst['max_speed'] = max(worst['max_speed'], speed)
        worst['ke_peak'] = max(worst['ke_peak'], ke)
        if tail_start <= t < tail_start + WINDOW_NS:
            start_energy.append(energy)
        if t >= last_check_t:
            ke_end_samples.append(ke)
            end_energy.append(energy)
    if finite:
        worst['ke_end'] = float(np.mean(ke_end_samples)) if ke_end_samples else math.nan
        if start_energy and end_energy:
            worst['energy_rise'] = float(np.mean(end_energy)) - float(np.mean(start_energy))
        bound = STRETCH_BOUND[scene.solver.type]
        if worst['stretch_guides'] > bound:
            failures.append(f'guide stretch {worst["stretch_guides"]:.3g} > {bound:g} '
                            f'({scene.solver.type})')
        if worst['stretch_ghosts'] > GHOST_STRETCH_BOUND:
            failures.append(f'ghost stretch {worst["stretch_ghosts"]:.3g} > '
                            f'{GHOST_STRETCH_BOUND:g}')
        if worst['root_err_m'] > ROOT_TOLERANCE:
            failures.append(f'roots detached by {worst["root_err_m"]:.3g} m')
        margin_mm = 1e3 * scene.collider.margin
        if sim.colliders.head is not None and worst['pen_guides_mm'] > margin_mm + 1e-9:
            failures.append(f'guide penetration {worst["pen_guides_mm"]:.2f} mm > margin '
                            f'{margin_mm:g} mm')
        if sim.colliders.head is not None and scene.tracking.collide and \
                worst['pen_ghosts_mm'] > margin_mm + 1e-9:
            failures.append(f'ghost penetration {worst["pen_ghosts_mm"]:.2f} mm > margin '
                            f'{margin_mm:g} mm')
        body = sim.guide_solver.body
        if body is not None and worst['pen_body_mm'] > 1e3 * body.margin + 1e-9:
            failures.append(f'body penetration {worst["pen_body_mm"]:.2f} mm > margin '
                            f'{1e3 * body.margin:g} mm')
        if worst['ke_peak'] > ke_max:
            failures.append(f'kinetic energy {worst["ke_peak"]:.3g} J/kg per node > bound '
                            f'{ke_max:.3g}')
        allowed = ENERGY_RISE * worst['ke_peak'] + KE_FLOOR
        if case.tail_s > 0 and not (worst['energy_rise'] <= allowed):
            failures.append(f'energy rose by {worst["energy_rise"]:.3g} J/kg per node over the '
                            f'still tail (allowed {allowed:.3g})')
    if finite and 'drift' in case.expect:
        worst['drift'] = _drift(sim, scene, t_ns[-1], pos[-1], quat[-1])
        if worst['drift'] > case.expect['drift']:
            failures.append(f'hair at rest after the run differs from freshly settled hair by '
                            f'{worst["drift"]:.3g} L (RMS), more than {case.expect["drift"]:g}')
    track = sim.track.counters
    counters = {'substeps': sim.counters.substeps, 'dropped': sim.counters.substeps_dropped,
                'resets': sim.counters.resets, 'rejected': track['rejected'],
                'accepted': track['accepted'],
                'split': sim.counters.extra.get('split_substeps', 0)}
    exp = case.expect
    if 'rejected' in exp and counters['rejected'] != exp['rejected']:
        failures.append(f'{counters["rejected"]} poses rejected, expected {exp["rejected"]}')
    if 'min_resets' in exp and counters['resets'] < exp['min_resets']:
        failures.append(f'{counters["resets"]} resets, expected at least {exp["min_resets"]}')
    if 'push_gain' in exp and not worst['push_gain'] <= exp['push_gain'][1]:
        failures.append(f'the fastest guide node gained {worst["push_gain"]:.3g} m/s when the '
                        f'body appeared at {exp["push_gain"][0]:g} s, more than '
                        f'{exp["push_gain"][1]:g} m/s')
    sim_s = (int(t_ns[-1]) - int(t_ns[0])) * 1e-9
    return CaseResult(case, not failures, failures, worst, counters,
                      time.perf_counter() - t_wall, sim_s)


def _drift(sim: HairSimulator, scene: Scene, t_last: int, p, q) -> float:
    """RMS node distance / strand length between the guides at the end of a run and the guides
    of a fresh simulator settled at the same head pose for the same tail (no drift: small)."""
    fresh = HairSimulator(scene)
    fresh.push_pose(int(t_last), p, q)
    settle = int(round(scene.solver.settle_time * 1e9)) + 10 ** 9
    for k in range(1, 121):
        fresh.push_pose(int(t_last) + k * settle // 120, p, q)
        fresh.advance_to(int(t_last) + k * settle // 120)
    d = np.linalg.norm(sim.guides.x - fresh.guides.x, axis=2) / \
        sim.guides.strand_length[:, None]
    return float(np.sqrt(np.mean(d * d)))


# ==================================================================================== matrix
SOLVERS = ('ftl', 'pbd', 'xpbd')


def _scene(solver: str, **changes) -> Scene:
    return BASE.with_changes(solver__type=solver, **changes)


def _walk(duration_s: Optional[float] = None) -> HeadMotion:
    w = load_bundled_walk()
    return sm.window(w, 0.0, duration_s) if duration_s else w


def matrix(quick: bool = False, tracking_mode: Optional[str] = None) -> List[Case]:
    """The cases: the full matrix, or the reduced one for CI (``quick``); every scene with
    ``tracking.mode`` set to ``tracking_mode`` when given."""
    d = 1.0 if quick else 2.0                      # length of the moving part [s]
    cases: List[Case] = []

    def add(name, group, scene, stream, description, **kw):
        cases.append(Case(name, group, scene, stream, description, **kw))

    shake = (lambda: sm.shake(10.0, 2.0, duration_s=d))
    # -- stiffness 1 / compliance 0 with 1..200 iterations
    its = (1, 200) if quick else (1, 2, 5, 20, 50, 200)
    for solver in ('pbd', 'xpbd'):
        for it in its:
            add(f'{solver} stiff {it} it', 'iterations',
                _scene(solver, solver__iterations=it, solver__stiffness=1.0,
                       solver__compliance=0.0),
                shake, f'stiffness 1 / compliance 0, {it} iterations, 10 rad/s shake')
    if not quick:
        add('ftl baseline', 'iterations', _scene('ftl'), shake,
            'FTL (no iterations), 10 rad/s shake')
    # -- segment lengths 1 mm .. 10 cm (16 nodes: strands of 1.5 cm .. 1.5 m)
    segs = (0.001, 0.1) if quick else (0.001, 0.003, 0.01, 0.03, 0.1)
    for solver in (('ftl', 'pbd') if quick else SOLVERS):
        for seg in segs:
            add(f'{solver} segment {seg * 1e3:g} mm', 'segment length',
                _scene(solver, groom__length=15 * seg),
                shake, f'segments of {seg * 1e3:g} mm (strands {15 * seg:.3g} m), '
                       '10 rad/s shake')
    # -- time steps 1/1000 .. 1/10 s
    dts = ((0.001, 'xpbd'), (0.1, 'ftl')) if quick else \
        [(dt, s) for s in SOLVERS for dt in (0.001, 1 / 60, 1 / 30, 0.1)]
    for dt, solver in dts:
        add(f'{solver} dt 1/{1 / dt:.0f} s', 'time step',
            _scene(solver, solver__dt=dt), shake, f'substep {dt:.4g} s, 10 rad/s shake')
    # -- angular speed up to 50 rad/s, linear speed up to 20 m/s
    fast = [('shake 50 rad/s', lambda: sm.shake(50.0, 8.0, duration_s=d),
             'head shake, 50 rad/s peak at 8 Hz'),
            ('spin 50 rad/s', lambda: sm.spin(50.0, duration_s=d),
             'spin about z at 50 rad/s, abrupt start and stop'),
            ('oscillate 20 m/s', lambda: sm.oscillate(20.0, 0.5, duration_s=d),
             'translation, 20 m/s peak, 0.5 m amplitude (80 g)'),
            ('dash 20 m/s', lambda: sm.dash(20.0, 0.1, d),
             '0 -> 20 m/s in 0.1 s, cruise, stop in 0.1 s')]
    for label, stream, desc in fast:
        for solver in (('ftl',) if quick else SOLVERS):
            if quick and label == 'dash 20 m/s':
                continue
            add(f'{solver} {label}', 'head speed', _scene(solver), stream, desc)
    if quick:
        add('pbd spin 50 rad/s', 'head speed', _scene('pbd'), fast[1][1], fast[1][2])
    # -- ghosts colliding too (tracking.collide): then the ghosts are held to the margin as well
    add('ftl ghosts collide, shake 50 rad/s', 'head speed',
        _scene('ftl', tracking__collide=True), fast[0][1],
        fast[0][2] + '; ghosts collide with the head (tracking.collide)')
    if not quick:
        add('ftl ghosts collide, walk', 'head speed', _scene('ftl', tracking__collide=True),
            lambda: _walk(), 'bundled walk; ghosts collide with the head (tracking.collide)')
    # -- long hair resting on the body's bust (config/scene_long_hair.yaml with body.bust)
    if not quick:
        long_hair = Scene.from_yaml(config_path('long_hair')).with_changes(
            groom__guides=BASE.groom.guides, groom__ghosts_per_guide=BASE.groom.ghosts_per_guide,
            body__bust=True)
        for label, stream, desc in fast[:2]:
            add(f'ftl long hair on the bust, {label}', 'body', long_hair, stream,
                desc + '; 55 cm hair on the shoulders (body.bust)')
        add('ftl long hair on the bust, walk', 'body', long_hair,
            lambda: sm.window(_walk(), 1.5, 2.5),
            'bundled walk, 1.5-4 s; bending down lays the hair into the creases where the '
            'bust\'s capsules overlap (the shoulders run into the neck and the chest)')
        add('ftl long hair, shoulder teleports 1 m', 'body',
            long_hair.with_changes(body__frame='torso_1'), lambda: sm.still(d),
            f'still head; the bust on a TF frame (body.frame) jumps 1 m aside at '
            f'{BODY_AWAY_S[0]:g} s, the hair falls through where it was, and back into the '
            f'hair at {BODY_AWAY_S[1]:g} s', events=_ShoulderTeleport(),
            expect={'push_gain': (BODY_AWAY_S[1], PUSH_GAIN * _push_speed(long_hair))})
        add('ftl long hair, bust switched on inside the hair', 'body',
            long_hair.with_changes(body__bust=False), lambda: sm.still(d),
            f'still head, the hair hanging through the body; at {BODY_ON_S:g} s the scene '
            'turns body.bust on (update_scene): pushed out, not launched',
            events=lambda sim, t: _switch_bust_on(sim, t, long_hair),
            expect={'push_gain': (BODY_ON_S, PUSH_GAIN * _push_speed(long_hair))})
    # -- teleports
    for solver in (('ftl',) if quick else SOLVERS):
        add(f'{solver} teleport 1 m', 'teleport', _scene(solver),
            lambda: sm.teleport(1.0), 'still head jumps 1 m between two samples',
            expect={'min_resets': 1})
    if not quick:
        add('ftl teleport 1 m + 180 deg', 'teleport', _scene('ftl'),
            lambda: sm.teleport(1.0, turn_rad=math.pi),
            'jump 1 m and turn 180 deg between two samples', expect={'min_resets': 1})
    # -- gravity up to 10 g
    gs = ((10.0, 'xpbd'),) if quick else [(g, s) for s in SOLVERS for g in (3.0, 10.0)]
    for g, solver in gs:
        add(f'{solver} gravity {g:g} g', 'gravity',
            _scene(solver, gravity=(0.0, 0.0, -9.81 * g)), shake,
            f'gravity {g:g} g, 10 rad/s shake')
    # -- the groomed shape held by a spring (solver.shape_stiffness), up to the table's maximum
    springs = ((1e6, 1 / 60),) if quick else ((2000.0, BASE.solver.dt), (1e6, 1 / 60))
    for solver in (('ftl',) if quick else SOLVERS):
        for k, dt in springs:
            add(f'{solver} shape stiffness {k:g}, dt 1/{1 / dt:.0f} s', 'shape spring',
                _scene(solver, solver__shape_stiffness=k, solver__dt=dt), fast[0][1],
                f'solver.shape_stiffness {k:g} 1/s^2 at dt 1/{1 / dt:.0f} s (k dt^2 = '
                f'{k * dt * dt:.3g}); ' + fast[0][2])
    # -- hair-hair interaction through the grid (volume.enabled)
    vol = dict(volume__enabled=True)
    for solver in (('ftl',) if quick else SOLVERS):
        add(f'{solver} volume, shake 50 rad/s', 'volume', _scene(solver, **vol), fast[0][1],
            fast[0][2] + '; volume.enabled')
    add('ftl volume, spin 50 rad/s', 'volume', _scene('ftl', **vol), fast[1][1],
        fast[1][2] + '; volume.enabled')
    add('ftl volume, teleport 1 m', 'volume', _scene('ftl', **vol), lambda: sm.teleport(1.0),
        'still head jumps 1 m between two samples; volume.enabled', expect={'min_resets': 1})
    add('pbd volume, stiff 200 it', 'volume',
        _scene('pbd', solver__iterations=200, solver__stiffness=1.0, **vol), shake,
        'stiffness 1, 200 iterations, 10 rad/s shake; volume.enabled')
    add('ftl volume, segment 1 mm', 'volume', _scene('ftl', groom__length=0.015, **vol), shake,
        'segments of 1 mm (strands 1.5 cm), 10 rad/s shake; volume.enabled')
    if not quick:
        add('ftl volume, long hair on the bust, shake 50 rad/s', 'volume',
            long_hair.with_changes(**vol), fast[0][1],
            fast[0][2] + '; 55 cm hair on the shoulders (body.bust); volume.enabled')
    # -- invalid poses
    for solver in (('ftl',) if quick else SOLVERS):
        def glitches(solver=solver):
            return sm.glitch_stream(_walk(2.0 if quick else None), nan_every=15,
                                    zero_every=25, flip_every=4, scale_every=6, seed=7)
        probe = glitches()
        add(f'{solver} NaN/zero/flipped poses', 'invalid poses', _scene(solver), glitches,
            f'walk with NaN ({probe.injected["nan"]}), zero quaternions '
            f'({probe.injected["zero_quaternion"]}), sign flips '
            f'({probe.injected["sign_flip"]}), unnormalised ({probe.injected["scaled"]})',
            expect={'rejected': int((~probe.valid).sum())})
    # -- a 1 kHz pose stream
    for solver in (('xpbd',) if quick else SOLVERS):
        add(f'{solver} 1 kHz poses', 'pose rate', _scene(solver),
            lambda: sm.resample(_walk(1.0 if quick else 4.0), 1000.0),
            'walk resampled to 1 kHz, advance_to per pose', check_every=10)
    # -- long run
    if quick:
        add('ftl 60 s wander, dt 1/60', 'long run', _scene('ftl', solver__dt=1 / 60),
            lambda: sm.wander(60.0, seed=5, rate_hz=30.0), '60 s of smooth random motion; '
            'at the end the hair at rest must match freshly settled hair', check_every=30,
            tail_s=5.0, expect={'drift': 0.05})
    else:
        add('ftl one hour wander', 'long run', _scene('ftl'),
            lambda: sm.wander(3600.0, seed=5, rate_hz=60.0),
            'one hour of smooth random motion at 60 Hz poses, dt 1/240 s; at the end the hair '
            'at rest must match freshly settled hair', check_every=12, tail_s=5.0,
            expect={'drift': 0.05})
    if tracking_mode is not None:
        cases = [replace(c, scene=c.scene.with_changes(tracking__mode=tracking_mode))
                 for c in cases]
    return cases


#: The body cases' TF torso frame is 1 m aside over this span [s] of the motion.
BODY_AWAY_S = (0.5, 1.2)
#: The switch case turns the bust on at this time [s] of the motion.
BODY_ON_S = 0.5
#: When a body appears in the hair, the fastest guide node's velocity (the solver's, the one
#: the next substep moves it with) over :data:`PUSH_WINDOW_S` after may exceed the fastest of
#: the :data:`PUSH_WINDOW_S` before by at most this many times the push-out bound
#: ``body.max_push_speed``: the bounded normal push of the collision stage, the bounded share
#: of the collision-aware FTL pass's correction, FTL's velocity correction (the next node's
#: share, times ``solver.ftl_damping``), the bending sweep's share of a pushed second
#: neighbour's move (a Jacobi sweep moves both ends of a constraint) and what gravity and the
#: hair's own swing add over the window (gravity alone 0.98 m/s in 0.1 s); unbounded, a node
#: 9 cm inside leaves at 20 m/s.
PUSH_GAIN = 5.0
#: [s] the windows of :data:`PUSH_GAIN`.
PUSH_WINDOW_S = 0.1


def _push_speed(scene: Scene) -> float:
    return float(scene.body.max_push_speed)


class _ShoulderTeleport:
    """The torso frame of the still head's neck frame, 1 m along y during
    :data:`BODY_AWAY_S`; true at the jump back into the hair."""

    def __init__(self):
        self.away = False

    def __call__(self, sim: HairSimulator, t: float) -> bool:
        rot, origin = neck_frame(np.eye(3), np.array([0.0, 0.0, sm.HEAD_HEIGHT]),
                                 sim.scene.body.height)
        away = BODY_AWAY_S[0] <= t < BODY_AWAY_S[1]
        sim.set_body_frame(rot, origin + (np.array([0.0, 1.0, 0.0]) if away else 0.0))
        back = self.away and not away and t > 0.0
        self.away = away
        return back


def _switch_bust_on(sim: HairSimulator, t: float, scene: Scene) -> bool:
    """``scene`` (with the bust) from :data:`BODY_ON_S` on; true when it switches."""
    if t >= BODY_ON_S and not sim.scene.body.bust:
        sim.update_scene(scene)
        return True
    return False


def run_matrix(cases: Sequence[Case], log=print) -> List[CaseResult]:
    out = []
    for c in cases:
        r = run_case(c)
        out.append(r)
        w = r.worst
        log(f'{"PASS" if r.passed else "FAIL"} {c.name:32s} stretch {w["stretch_guides"]:.3g}/'
            f'{w["stretch_ghosts"]:.3g}  pen {w["pen_guides_mm"]:.2f}/{w["pen_ghosts_mm"]:.1f} mm'
            f'  v {w["max_speed"]:.3g} m/s  KE end/peak/bound '
            f'{w["ke_end"]:.2g}/{w["ke_peak"]:.2g}/{w["ke_bound"]:.2g} rise {w["energy_rise"]:.2g}'
            f'  {r.wall_s:.1f} s'
            + ('' if r.passed else '  <- ' + '; '.join(r.failures)))
    return out


# ==================================================================================== output
COLUMNS = ('case', 'group', 'solver', 'passed', 'stretch_guides', 'stretch_bound',
           'stretch_ghosts', 'root_err_m', 'pen_guides_mm', 'pen_ghosts_mm', 'pen_body_mm',
           'margin_mm', 'max_speed', 'push_gain', 'ke_peak', 'ke_bound', 'ke_end', 'energy_rise',
           'substeps', 'dropped', 'resets', 'rejected', 'split', 'drift', 'sim_s', 'wall_s',
           'failures', 'description')


def result_row(r: CaseResult) -> Dict:
    sc = r.case.scene
    row = {'case': r.case.name, 'group': r.case.group, 'solver': sc.solver.type,
           'passed': int(r.passed), 'stretch_bound': STRETCH_BOUND[sc.solver.type],
           'margin_mm': 1e3 * sc.collider.margin, 'sim_s': r.sim_s, 'wall_s': r.wall_s,
           'failures': '; '.join(r.failures), 'description': r.case.description}
    row.update(r.worst)
    row.update(r.counters)
    return row


def write_outputs(results: Sequence[CaseResult], out_dir: str, record: dict,
                  notes: Sequence[str] = ()) -> Dict[str, str]:
    """CSV and Markdown of the results, the Markdown headed by ``record``
    (:func:`hair_tracking.evaluation.provenance.provenance`); returns {kind: path}."""
    from hair_tracking.evaluation.provenance import markdown_lines
    os.makedirs(out_dir, exist_ok=True)
    paths = {'csv': os.path.join(out_dir, 'stability.csv'),
             'md': os.path.join(out_dir, 'stability.md')}
    with open(paths['csv'], 'w', newline='', encoding='utf-8') as f:
        wr = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction='ignore')
        wr.writeheader()
        for r in results:
            wr.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v)
                         for k, v in result_row(r).items()})
    passed = sum(r.passed for r in results)
    lines = ['# Stability matrix', ''] + markdown_lines(record) + [
             f'**{passed}/{len(results)} cases passed.** Bounds: guide stretch '
             + ', '.join(f'{k.upper()} {v:g}' for k, v in STRETCH_BOUND.items())
             + f'; ghost stretch {GHOST_STRETCH_BOUND:g}; roots within {ROOT_TOLERANCE:g} m; '
             'guide penetration within the collider margin; kinetic energy within the bound '
             'of the motion; no energy gained over the still tail (docs/stability.md).', '']
    lines += [f'- {n}' for n in notes]
    lines += ['', '| case | pass | guide stretch | ghost stretch | root err [m] | '
              'penetration guides / ghosts [mm] | max node speed [m/s] | KE end / peak / bound '
              '[J/kg] | tail energy rise [J/kg] | resets | rejected | dropped substeps | '
              'wall [s] |',
              '|---|:---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|']
    for r in results:
        w, c = r.worst, r.counters
        lines.append(
            f'| {r.case.name} | {"yes" if r.passed else "**NO**"} | {w["stretch_guides"]:.3g} | '
            f'{w["stretch_ghosts"]:.3g} | {w["root_err_m"]:.1e} | {w["pen_guides_mm"]:.2f} / '
            f'{w["pen_ghosts_mm"]:.1f} | {w["max_speed"]:.3g} | '
            f'{w["ke_end"]:.2g} / {w["ke_peak"]:.2g} / {w["ke_bound"]:.2g} | '
            f'{w["energy_rise"]:.2g} | {c["resets"]} | '
            f'{c["rejected"]} | '
            f'{c["dropped"]} | {r.wall_s:.1f} |'
            + ('' if r.passed else ' ' + '; '.join(r.failures)))
    lines.append('')
    lines.append('Cases: ' + '; '.join(f'*{r.case.name}*: {r.case.description}'
                                       for r in results) + '.')
    with open(paths['md'], 'w', encoding='utf-8') as f:
        f.write('\n'.join(lines) + '\n')
    return paths
