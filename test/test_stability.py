"""Stability: the reduced matrix of stiff and extreme cases (CI), the checks themselves, and the
simulation fixes the matrix led to (each kernel against a plain-numpy reference)."""
from dataclasses import replace
import math

import numpy as np
import pytest

from hair_tracking.guides import ftl

from hair_tracking.guides import split

from hair_tracking.colliders.contact import SHALLOW_LEVEL, surface_point
from hair_tracking.core.metrics import max_stretch
from hair_tracking.core.model import StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from hair_tracking.evaluation import stability
from hair_tracking.evaluation.provenance import provenance
from hair_tracking.evaluation import synthetic_motion as sm
from hair_tracking.colliders.head import HeadCollider, placed
from hair_tracking.colliders.margin import outside_distance
from hair_tracking.guides.solver import (BEND_REFERENCE_DT, GuideSolver, ftl_inner_steps,
                                         ftl_bend_stiffness)
from hair_tracking.simulator import HairSimulator

QUICK = stability.matrix(quick=True)


# behaviour, not speed: these modules run numba on one thread (conftest.py)
pytestmark = pytest.mark.usefixtures('one_numba_thread')


# ------------------------------------------------------------------ the reduced matrix
@pytest.mark.parametrize('case', QUICK, ids=[c.name for c in QUICK])
def test_reduced_matrix_case_passes(case):
    r = stability.run_case(case)
    assert r.passed, f'{case.name}: {r.failures} (worst {r.worst})'
    # the run really happened and was measured
    assert r.counters['substeps'] > 0 and r.sim_s > 0.5
    assert math.isfinite(r.worst['ke_end']) and r.worst['ke_peak'] > 0.0


def test_reduced_matrix_covers_the_issue():
    groups = {c.group for c in QUICK}
    assert groups == {'iterations', 'segment length', 'time step', 'head speed', 'teleport',
                      'gravity', 'invalid poses', 'pose rate', 'long run', 'shape spring',
                      'volume'}
    names = ' '.join(c.name for c in QUICK)
    for needle in ('1 it', '200 it', '1 mm', '100 mm', '1/1000', '1/10 s', '50 rad/s',
                   '20 m/s', 'teleport 1 m', '10 g', 'NaN', '1 kHz', 'shape stiffness 1e+06'):
        assert needle in names, needle


def test_full_matrix_is_larger_and_has_the_hour():
    full = stability.matrix(quick=False)
    assert len(full) > 2 * len(QUICK)
    long = [c for c in full if c.group == 'long run']
    assert len(long) == 1 and 'one hour' in long[0].name
    for solver in ('ftl', 'pbd', 'xpbd'):
        assert any(c.scene.solver.type == solver and c.group == 'time step' for c in full)
    body = [c for c in full if c.group == 'body']
    assert len(body) == 5 and sum(c.scene.body.bust for c in body) == 4
    names = ' '.join(c.name for c in body)
    for needle in ('50 rad/s', 'walk', 'teleports 1 m', 'switched on inside the hair'):
        assert needle in names, needle


# ------------------------------------------------------------- the checks can fail
def _case(scene, stream, **kw):
    return stability.Case('probe', 'probe', scene, stream, 'probe', **kw)


def test_check_catches_non_finite_state(monkeypatch):
    real = GuideSolver.advance

    def poisoned(self, dt, head_prev, heads, **kw):
        out = real(self, dt, head_prev, heads, **kw)
        if self.stats['substeps'] > 200:
            self.strands.x[0, 5, 0] = np.nan
        return out
    monkeypatch.setattr(GuideSolver, 'advance', poisoned)
    r = stability.run_case(_case(stability.BASE, lambda: sm.shake(5.0, 2.0, duration_s=0.5)))
    assert not r.passed
    assert any('non-finite' in f for f in r.failures)


def test_check_catches_detached_roots_and_stretch(monkeypatch):
    real = GuideSolver.advance

    def dragged(self, dt, head_prev, heads, **kw):
        out = real(self, dt, head_prev, heads, **kw)
        self.strands.x[:, :, 0] += 0.01 * np.arange(self.strands.nodes)
        return out
    monkeypatch.setattr(GuideSolver, 'advance', dragged)
    r = stability.run_case(_case(stability.BASE, lambda: sm.still(0.3), tail_s=0.0))
    assert not r.passed
    assert any('roots detached' in f for f in r.failures)
    assert any('guide stretch' in f for f in r.failures)


def test_check_catches_energy_growth(monkeypatch):
    real = GuideSolver.advance

    def pumped(self, dt, head_prev, heads, **kw):         # every substep
        out = []
        for head in heads:
            out.extend(real(self, dt, head_prev, (head,), **kw))
            self.strands.v[:, 2:] *= 1.2
            self.strands.v[:, 2:, 0] += 0.2
            head_prev = head
        return np.array(out)
    monkeypatch.setattr(GuideSolver, 'advance', pumped)
    r = stability.run_case(_case(stability.BASE, lambda: sm.still(0.5)))
    assert not r.passed
    assert any('kinetic energy' in f for f in r.failures)


def test_glitch_expectation_is_checked():
    def stream():
        return sm.glitch_stream(sm.shake(5.0, 2.0, duration_s=1.0), nan_every=10,
                                zero_every=15, flip_every=3, scale_every=5, seed=3)
    probe = stream()
    bad = int((~probe.valid).sum())
    assert bad > 5
    ok = stability.run_case(_case(stability.BASE, stream, expect={'rejected': bad}))
    assert ok.passed and ok.counters['rejected'] == bad
    wrong = stability.run_case(_case(stability.BASE, stream, expect={'rejected': bad + 1}))
    assert not wrong.passed


def test_a_bust_switched_on_inside_the_hair_pushes_it_out_without_launching_it():
    """The switch case of the full matrix, shortened: the push-out bound keeps the guides'
    velocity gain within the case's bound; without it (``body.max_push_speed`` 100 m/s, the
    bound kept) the check fails."""
    case = next(c for c in stability.matrix() if 'switched on' in c.name)
    short = replace(case, stream=lambda: sm.still(1.0), tail_s=0.3)
    ok = stability.run_case(short)
    assert ok.passed, ok.failures
    assert 0.0 < ok.worst['push_gain'] <= case.expect['push_gain'][1]
    on = case.scene.with_changes(body__bust=True, body__max_push_speed=100.0)
    loose = replace(short, scene=case.scene.with_changes(body__max_push_speed=100.0),
                    events=lambda sim, t: stability._switch_bust_on(sim, t, on))
    bad = stability.run_case(loose)
    assert not bad.passed and any('gained' in f for f in bad.failures), bad.failures


def test_check_catches_energy_gained_over_the_still_tail(monkeypatch):
    real = GuideSolver.advance

    def lifted(self, dt, head_prev, heads, **kw):   # a slow, steady gain: within the KE bound
        out = []
        for head in heads:
            out.extend(real(self, dt, head_prev, (head,), **kw))
            self.strands.v[:, 2:, 0] += 0.02
            head_prev = head
        return np.array(out)
    monkeypatch.setattr(GuideSolver, 'advance', lifted)
    r = stability.run_case(_case(stability.BASE, lambda: sm.still(0.5), tail_s=1.0))
    assert any('energy rose' in f for f in r.failures), r.failures


def test_energy_bound_grows_with_the_motion():
    scene = stability.BASE
    slow = stability.energy_bound(sm.shake(1.0, 1.0), scene)
    fast = stability.energy_bound(sm.shake(50.0, 8.0), scene)
    dash = stability.energy_bound(sm.dash(20.0), scene)
    assert slow < fast and slow < dash
    # the motion's own energy, four times, plus the fall: the fast shake moves tips at ~19 m/s
    assert 4 * 0.5 * 19.0 ** 2 < fast < 4 * 0.5 * 23.0 ** 2 + 4 * 9.81 * 0.3 + 0.5


def test_outputs_written(tmp_path):
    results = stability.run_matrix([c for c in QUICK if c.group == 'teleport'], log=lambda s: 0)
    paths = stability.write_outputs(results, str(tmp_path),
                                    provenance('hair_sim_eval stability --quick', 1))
    text = open(paths['md']).read()
    assert '1/1 cases passed' in text and '- Command: `hair_sim_eval stability --quick`' in text
    rows = open(paths['csv']).read().splitlines()
    assert rows[0].startswith('case,group,solver,passed') and len(rows) == 2


# ------------------------------------------------------------------ the fixes
def ref_ftl_collide_pass(x, x_ref, rest, rest_length, rot, pos, center, axes, refine,
                         friction, corr, iterations, tolerance):
    """Plain numpy/python reference of the FTL pass with the head collider
    (:func:`ftl.ftl_pass_block` with ``collide``, corrections added): node by node, each put at
    its rest distance from its predecessor; one inside the ellipsoid goes to its surface point,
    friction moves it back toward ``x_ref`` by ``friction`` of the tangential part, and it is put
    back at its rest distance while inside the ellipsoid scaled by ``1 - tolerance /
    max(axes)`` (at most ``iterations`` surface points).  ``corr`` receives the placements, not
    the push.  A node less than 1 % of the semi-axes deep goes one Newton step along the
    gradient instead (the fast path of :func:`contact.ellipsoid_contact`)."""
    x = x.copy()
    corr = corr.copy()
    c_world = rot @ center + pos

    def place(p, s, i):
        d = p - x[s, i - 1]
        n = np.linalg.norm(d)
        if n > 1e-12:
            return x[s, i - 1] + rest_length[s, i - 1] * d / n
        e = rot @ (rest[s, i] - rest[s, i - 1])
        return x[s, i - 1] + rest_length[s, i - 1] * e / np.linalg.norm(e)

    for i in range(2, x.shape[1]):
        for s in range(x.shape[0]):
            p = place(x[s, i], s, i)
            corr[s, i] += p - x[s, i]
            q = rot.T @ (p - c_world)
            level = np.sum((q / axes) ** 2)
            if level < 1.0:
                if level > SHALLOW_LEVEL:   # one Newton step; friction about the gradient
                    g = q / axes ** 2
                    y = q - 0.5 * (level - 1.0) * g / (g @ g)
                    normal = g
                else:
                    y = np.array(surface_point(q[0], q[1], q[2], axes[0], axes[1], axes[2],
                                               refine))
                    normal = y / axes ** 2
                if friction > 0:
                    normal = normal / np.linalg.norm(normal)
                    m = y - rot.T @ (x_ref[s, i] - c_world)
                    y = y - friction * (m - (m @ normal) * normal)
                pushed = rot @ y + c_world
                p = pushed
                for k in range(iterations + 1):
                    p = place(p, s, i)
                    if k == iterations:
                        break
                    q = rot.T @ (p - c_world)
                    if np.sqrt(np.sum((q / axes) ** 2)) >= 1.0 - tolerance / axes.max():
                        break
                    y = np.array(surface_point(q[0], q[1], q[2], axes[0], axes[1], axes[2],
                                               refine))
                    p = rot @ y + c_world
                corr[s, i] += p - pushed
            x[s, i] = p
    return x, corr


def _random_strands(rng, s=7, n=9):
    rest = np.zeros((s, n, 3))
    d = rng.normal(size=(s, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rest[:, 0] = d * 0.1
    rest[:, 1] = d * 0.115
    for i in range(2, n):
        step = rng.normal(size=(s, 3))
        step /= np.linalg.norm(step, axis=1, keepdims=True)
        rest[:, i] = rest[:, i - 1] + 0.02 * (0.5 * step + d)
    return rest


def _into_head(rest, rng):
    """Positions (head frame) with the free nodes pulled toward the centre: many inside."""
    x = rest + rng.normal(scale=0.01, size=rest.shape)
    x[:, 2:] *= rng.uniform(0.3, 1.0, size=(rest.shape[0], rest.shape[1] - 2, 1))
    x[:, :2] = rest[:, :2]
    return x


@pytest.mark.parametrize('friction', [0.0, 0.4])
def test_ftl_collide_pass_matches_reference_and_keeps_lengths(friction):
    rng = np.random.default_rng(11)
    rest = _random_strands(rng)
    st = StrandSet.from_rest(rest)
    rot = quat_to_matrix(quat_from_axis_angle([0.3, -0.2, 1.0], 0.7))
    pos = np.array([0.2, -0.1, 1.5])
    center = np.array([0.0, 0.0, 0.01])
    axes = np.array([0.1, 0.09, 0.11])
    # world positions scattered around the head, many inside the ellipsoid
    x = _into_head(rest, rng) @ rot.T + pos
    x_ref = x + rng.normal(scale=5e-3, size=x.shape)
    corr = rng.normal(scale=1e-3, size=x.shape)
    x_want, corr_want = ref_ftl_collide_pass(x, x_ref, rest, st.rest_length, rot, pos, center,
                                             axes, 2, friction, corr, ftl.RESTORE_ITERATIONS,
                                             ftl.RESTORE_TOLERANCE)
    xk, ck = x.copy(), corr.copy()
    contact = placed((center, axes, 0.0, friction, 2), rot, pos)
    pushed = ftl.ftl_pass_block(xk, rest, st.rest_length, rot, ck, 0, xk.shape[0], True,
                                (x_ref, st.inv_mass, contact))
    assert pushed >= 5
    np.testing.assert_allclose(xk, x_want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ck, corr_want, rtol=0, atol=1e-12)
    assert max_stretch(xk, st.rest_length) < 1e-12          # exact lengths
    # the pass really moved nodes out of the ellipsoid (not a no-op on this input): from
    # centimetres inside to a fraction of a millimetre
    probe = HeadCollider('ellipsoid', center, axes, 0.0, 0.0)
    from hair_tracking.core.model import HeadPose
    head = HeadPose(pos, np.zeros(4), rot)
    assert probe.penetration(x, head, st.inv_mass) > 0.02
    assert probe.penetration(xk, head, st.inv_mass) < 1e-3


def test_outside_distance_matches_brute_force():
    rng = np.random.default_rng(5)
    radii = np.array([0.095, 0.08, 0.105])
    u = rng.normal(size=(200000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    surface = u * radii
    q = rng.normal(size=(40, 3)) * 0.12
    d = outside_distance(q, radii)
    inside = np.sum((q / radii) ** 2, axis=1) <= 1.0
    assert np.all(d[inside] == 0.0) and inside.sum() > 3
    brute = np.array([np.min(np.linalg.norm(surface - p, axis=1)) for p in q[~inside]])
    assert np.allclose(d[~inside], brute, atol=2e-4)        # sampling resolution ~1e-4 m
    assert np.all(d[~inside] <= brute + 1e-12)               # exact closest is never farther


def test_ftl_bending_acts_as_dt_squared():
    k = 0.3
    assert ftl_bend_stiffness(k, BEND_REFERENCE_DT) == k
    assert ftl_inner_steps(BEND_REFERENCE_DT) == 1
    half = ftl_bend_stiffness(k, 0.5 * BEND_REFERENCE_DT)
    assert ftl_inner_steps(0.5 * BEND_REFERENCE_DT) == 1
    assert math.isclose((1 - half) ** 4, 1 - k, rel_tol=1e-12)   # a quarter of the push
    assert ftl_inner_steps(4 * BEND_REFERENCE_DT) == 4               # inner steps of dt_ref
    assert ftl_bend_stiffness(k, 4 * BEND_REFERENCE_DT) == k
    assert ftl_inner_steps(2.5 * BEND_REFERENCE_DT) == 3             # of 5/6 dt_ref
    short = ftl_bend_stiffness(k, 2.5 * BEND_REFERENCE_DT)
    assert math.isclose((1 - short) ** 36, (1 - k) ** 25, rel_tol=1e-12)
    assert ftl_bend_stiffness(0.0, 0.001) == 0.0 and ftl_bend_stiffness(1.0, 0.001) == 1.0


def test_settled_shape_hardly_depends_on_the_step():
    """Settled until still, the hair rests in nearly one shape at dt 1/60, 1/240 and 1/960 s:
    a long substep runs inner steps of 1/240 s (``ftl_inner_steps``)."""
    base = Scene().with_changes(tracking__mode='paper', groom__ghosts_per_guide=0,
                                groom__guides=16, solver__settle_time=0.5,
                                solver__settle_speed=0.002, solver__max_substeps=10_000)
    shapes = {}
    for dt in (1 / 60, 1 / 240, 1 / 960):
        sim = HairSimulator(base.with_changes(solver__dt=dt))
        assert sim.settled_s < 29.0                 # came to rest before the cap
        shapes[dt] = sim.frame(head_frame=True).guides
    length = sim.guides.strand_length[:, None]

    def apart(a, b):
        d = np.linalg.norm(shapes[a] - shapes[b], axis=2) / length
        return np.sqrt(np.mean(d * d))
    assert apart(1 / 60, 1 / 240) < 0.004           # 0.03 % L measured
    assert max(apart(1 / 60, 1 / 960), apart(1 / 240, 1 / 960)) < 0.012    # 0.64 % L


def test_guide_margin_fits_short_segments_only():
    short = Scene().with_changes(groom__guides=8, groom__ghosts_per_guide=0,
                                 groom__length=0.015)
    sim = HairSimulator(short)
    assert sim.guide_solver.margin < 0.5 * sim.guides.rest_length.min() + 1e-15
    default = HairSimulator(Scene().with_changes(groom__guides=8, groom__ghosts_per_guide=0))
    assert default.guide_solver.margin == pytest.approx(Scene().collider.margin, abs=5e-4)


def _translate(sim_scene, speed, monkeypatch=None, max_split=None):
    if max_split is not None:
        monkeypatch.setattr(split, 'MAX_SPLIT', max_split)
    sim = HairSimulator(sim_scene)
    motion = sm.oscillate(speed, 0.5, duration_s=0.6)
    worst = 0.0
    for t, p, q in zip(motion.t_ns, motion.position, motion.quaternion):
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
        worst = max(worst, max_stretch(sim.guides.x, sim.guides.rest_length))
    return sim, worst


def test_fast_head_splits_substeps_and_ftl_stays_inextensible(monkeypatch):
    scene = stability.BASE.with_changes(collider__shape='none')
    sim, worst = _translate(scene, 20.0)
    assert sim.counters.extra.get('split_substeps', 0) > 50
    assert worst < 1e-9
    # without the split the displacement clamp tears the strands apart
    _, torn = _translate(scene, 20.0, monkeypatch, max_split=1)
    assert torn > 0.5


def test_slow_motion_is_not_split():
    sim = HairSimulator(stability.BASE)
    motion = sm.shake(2.0, 1.0, duration_s=0.5)
    for t, p, q in zip(motion.t_ns, motion.position, motion.quaternion):
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
    assert sim.counters.extra.get('split_substeps', 0) == 0


def test_split_never_below_min_dt():
    sim = HairSimulator(stability.BASE)
    head0 = sim.head
    q = quat_from_axis_angle([0, 0, 1], 3.0)
    from hair_tracking.core.model import HeadPose
    far = HeadPose(np.array([0.5, 0.0, 0.0]), q, quat_to_matrix(q))
    dt = sim.scene.solver.dt
    rule = sim.split_rule
    n = rule.parts(dt, rule.rigid(head0, far), 0.0)
    assert n == int(dt / split.MIN_SPLIT_DT + 1e-9) and n > 1
    assert rule.parts(0.1, rule.rigid(head0, far), 0.0) == split.MAX_SPLIT


@pytest.mark.parametrize('max_disp', [0.004, 0.0])
def test_the_split_rule_between_runs_and_inside_them_agree(max_disp):
    """A substep is split between runs (SplitRule.parts) exactly when the compiled runs' stop
    rule (split_due, where SplitRule.stop applies it) names it, NaN speeds included."""
    rule = split.SplitRule(max_disp, 9.81, 0.4)
    rng = np.random.default_rng(5)
    for dt in (1 / 240, 1 / 60, 1 / 30, 1 / 1000):
        _, limit, gdt2 = rule.stop(dt, None)
        far = np.append(rng.uniform(0.0, 2.0 * rule.limit(dt)[0], 300) ** 2, np.nan)
        rigid = np.append(rng.uniform(0.0, 2.0 * rule.limit(dt)[0], 300), 0.0)
        for f, r in zip(far.tolist(), rigid.tolist()):
            due = limit > 0.0 and split.split_due(f, dt, r, gdt2, limit)
            assert (rule.parts(dt, r, math.sqrt(f) / dt) > 1) == due, (dt, f, r)


@pytest.mark.parametrize('mode,stretch', [('paper', 1e-9), ('blend', 1e-7), ('turn', 1e-6)])
def test_ghost_collision_keeps_lengths(mode, stretch):
    # the blend and the turn keep their rest lengths or segments, and their positions, in
    # float32: beyond the rounding of the positions (stability.float32_slack)
    scene = stability.BASE.with_changes(tracking__collide=True, tracking__mode=mode)
    sim = HairSimulator(scene)
    motion = sm.shake(20.0, 4.0, duration_s=0.5)
    contacts = 0
    for t, p, q in zip(motion.t_ns, motion.position, motion.quaternion):
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
        contacts += sim.ghost_tracker.stats['contacts']
        x, rl = sim.ghost_tracker.positions(), sim.ghosts.rest_length
        slack = 0.0 if mode == 'paper' else 2.0 * stability.float32_slack(x) / rl.min()
        assert max_stretch(x, rl) < stretch + slack
    assert contacts > 0
    c = HeadCollider('ellipsoid', scene.collider.center, scene.collider.radii, 0.0, 0.0)
    assert c.penetration(sim.ghost_tracker.positions(), sim.head, sim.ghosts.inv_mass) <= \
        scene.collider.margin


def test_the_matrix_runs_with_any_tracker():
    for mode in ('paper', 'blend', 'turn'):
        cases = stability.matrix(quick=True, tracking_mode=mode)
        assert [c.name for c in cases] == [c.name for c in QUICK]
        assert {c.scene.tracking.mode for c in cases} == {mode}


def _one_by_one(sim):
    """``sim`` taking every substep in a call of its own (no runs: a run the split rule
    applies to is cut to its first substep; a split substep's parts still go in one call)."""
    real = sim.guide_solver.advance

    def advance(dt, head_prev, heads, measure=False, stop=None):
        if stop is not None:
            heads, stop = list(heads)[:1], None
        return real(dt, head_prev, heads, measure=measure, stop=stop)
    sim.guide_solver.advance = advance
    return sim


@pytest.mark.parametrize('solver, dt, motion, splits', [
    ('ftl', None, lambda: sm.oscillate(5.0, 0.5, duration_s=0.6), True),
    ('ftl', None, lambda: sm.oscillate(1.0, 0.5, duration_s=0.6), False),
    ('ftl', 1 / 30, lambda: sm.shake(10.0, 2.0, duration_s=0.6), True),
    ('pbd', 1 / 30, lambda: sm.shake(10.0, 2.0, duration_s=0.6), True)])
@pytest.mark.parametrize('collider', ['none', 'ellipsoid'])
def test_runs_of_substeps_are_the_substeps_one_by_one(solver, dt, motion, splits, collider):
    """The substeps of a pose go to the guide solver in one call, which stops before the
    first substep after one that needs splitting: the hair, and the splits, are those of
    taking them one by one, bit for bit (fast motion, long substeps, PBD)."""
    changes = dict(collider__shape=collider, solver__type=solver)
    if dt is not None:
        changes['solver__dt'] = dt
    scene = stability.BASE.with_changes(**changes)
    runs, single = HairSimulator(scene), _one_by_one(HairSimulator(scene))
    m = motion()
    calls = []
    real = runs.guide_solver.advance
    runs.guide_solver.advance = lambda dt, prev, heads, **k: (calls.append(len(heads)),
                                                              real(dt, prev, heads, **k))[1]
    for t, p, q in zip(m.t_ns, m.position, m.quaternion):
        for sim in (runs, single):
            sim.push_pose(int(t), p, q)
            sim.advance_to(int(t))
        assert np.array_equal(runs.guides.x, single.guides.x)
        assert np.array_equal(runs.frame().strands, single.frame().strands)
    assert runs.counters.extra == single.counters.extra
    assert max(calls) > 1                           # a pose's substeps in one call
    assert (runs.counters.extra.get('split_substeps', 0) > 10) == splits
