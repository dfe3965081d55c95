"""Evaluation: synthetic head motions, the compared methods, the error/time harness and the CLI."""
import csv
import json
import math
import os

import numpy as np
import pytest

from hair_tracking.core.head_track import IDENTITY
from hair_tracking.core.metrics import max_stretch, position_error
from hair_tracking.core.model import HeadPose
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix, slerp
from hair_tracking.evaluation import accuracy as ea
from hair_tracking.evaluation import cli as eval_cli
from hair_tracking.evaluation import synthetic_motion as sm
from hair_tracking.evaluation.provenance import provenance
from hair_tracking.evaluation.methods import (FullSim, GhostTracking, PyPBD, RigidOffset,
                                              make_workload, pypbd_available)
from hair_tracking.motion.head_motion import angular_speed, HeadMotion, linear_speed
from hair_tracking.motion.pose_table import load_bundled_walk, read_vr360

from recordings import VR_TRACE as VR


# behaviour, not speed: these modules run numba on one thread (conftest.py)
pytestmark = pytest.mark.usefixtures('one_numba_thread')


# ------------------------------------------------------------------ synthetic motions
def test_shake_reaches_its_peak_angular_speed():
    m = sm.shake(50.0, 8.0, duration_s=1.0, rate_hz=2000.0)
    w = angular_speed(m)
    assert w.max() == pytest.approx(50.0, rel=2e-3)
    assert np.all(linear_speed(m) < 1e-9)
    nod = sm.shake(8.0, 2.5, axis=(0, 1, 0), duration_s=1.0, rate_hz=1000.0)
    # a nod turns about the head's y axis: the head x axis tips up and down, y stays put
    rot = nod.rotation()
    assert np.allclose(rot[:, :, 1], [0, 1, 0], atol=1e-12)
    assert np.ptp(rot[:, 2, 0]) > 0.9


def test_spin_oscillate_dash_teleport():
    spin = sm.spin(50.0, duration_s=1.0, rate_hz=1000.0)
    assert np.allclose(angular_speed(spin), 50.0, rtol=1e-6)
    ramp = sm.spin(10.0, duration_s=1.0, ramp_s=0.5, rate_hz=1000.0)
    assert angular_speed(ramp)[:5].max() < 0.2 and angular_speed(ramp)[-5:].min() > 9.9
    osc = sm.oscillate(20.0, 0.5, duration_s=1.0, rate_hz=2000.0)
    assert linear_speed(osc).max() == pytest.approx(20.0, rel=1e-3)
    assert np.abs(osc.position[:, 0]).max() == pytest.approx(0.5, rel=1e-3)
    dash = sm.dash(20.0, 0.1, 1.0, rest_s=0.5, rate_hz=1000.0)
    v = linear_speed(dash)
    assert v.max() == pytest.approx(20.0, rel=1e-3) and v[:400].max() == 0.0
    assert dash.position[-1, 0] == pytest.approx(20.0 * 1.1, rel=1e-6)   # 1 s + two ramps
    tp = sm.teleport(1.0, before_s=1.0, after_s=1.0, turn_rad=math.pi)
    jumps = np.linalg.norm(np.diff(tp.position, axis=0), axis=1)
    assert np.sum(jumps > 0) == 1 and jumps.max() == pytest.approx(1.0)
    assert angular_speed(tp).max() * (1 / 120.0) == pytest.approx(math.pi, rel=1e-6)


def test_wander_is_bounded_smooth_and_deterministic():
    a = sm.wander(600.0, seed=4, rate_hz=30.0)
    b = sm.wander(600.0, seed=4, rate_hz=30.0)
    c = sm.wander(600.0, seed=5, rate_hz=30.0)
    assert np.array_equal(a.position, b.position) and not np.allclose(a.position, c.position)
    assert np.abs(a.position[:, :2]).max() <= 0.3 + 1e-12
    assert angular_speed(a).max() < 2 * math.pi * 1.5 * 0.6 * 1.01
    assert a.duration_s == pytest.approx(600.0)


def test_concat_is_continuous_and_resample_keeps_the_path():
    a, b = sm.shake(5.0, 1.0, duration_s=0.7), sm.dash(2.0, 0.1, 0.2)
    c = sm.concat(a, b)
    assert len(c) == len(a) + len(b)
    assert linear_speed(c).max() <= 2.0 + 1e-9            # no jump where they meet
    assert angular_speed(c).max() <= 5.0 * 1.01
    r = sm.resample(a, 1000.0)
    assert r.rate_hz == pytest.approx(1000.0)
    # resampled orientation at an original sample time equals the original
    k = 60                                   # t = 0.5 s in both
    j = int(round(a.t_s[k] * 1000))
    assert np.allclose(r.quaternion[j], a.quaternion[k], atol=1e-9)
    tail = sm.with_tail(a, 1.0)
    assert tail.duration_s == pytest.approx(a.duration_s + 1.0, abs=1e-2)
    assert np.all(tail.quaternion[-10:] == a.quaternion[-1])


def test_glitch_stream_counts_and_validity():
    m = sm.shake(5.0, 1.0, duration_s=3.0)
    g = sm.glitch_stream(m, nan_every=10, zero_every=20, flip_every=5, scale_every=5, seed=1)
    bad_p = ~np.all(np.isfinite(g.position), axis=1)
    bad_q = ~np.all(np.isfinite(g.quaternion), axis=1) | \
        (np.linalg.norm(np.nan_to_num(g.quaternion), axis=1) == 0)
    assert np.array_equal(~g.valid, bad_p | bad_q)
    assert g.injected['nan'] + g.injected['zero_quaternion'] == int((~g.valid).sum())
    assert g.injected['sign_flip'] > 10 and g.injected['scaled'] > 10
    assert g.valid[0]
    # the valid samples describe the original rotations (up to sign and scale)
    q = g.quaternion[g.valid] / np.linalg.norm(g.quaternion[g.valid], axis=1, keepdims=True)
    dots = np.abs(np.sum(q * m.quaternion[g.valid], axis=1))
    assert np.allclose(dots, 1.0)


def test_generators_name_bad_parameters():
    with pytest.raises(sm.SyntheticMotionError, match='peak_angular_speed'):
        sm.shake(-1.0)
    with pytest.raises(sm.SyntheticMotionError, match='axis'):
        sm.spin(1.0, axis=(0, 0, 0))
    with pytest.raises(sm.SyntheticMotionError, match='rate_hz'):
        sm.still(1.0, rate_hz=0.0)
    with pytest.raises(sm.SyntheticMotionError, match='unknown synthetic motion'):
        sm.named('moonwalk', 1.0)
    assert isinstance(sm.named('shake10', 1.0), HeadMotion)


# ----------------------------------------------------------------------- harness parts
def test_interpolate_poses_matches_slerp():
    m = sm.wander(5.0, seed=2, rate_hz=20.0)
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(-0.5, 5.5, 200))
    p, q = ea.interpolate_poses(m, t)
    ts = m.t_s
    for k in range(len(t)):
        tt = min(max(t[k], 0.0), ts[-1])
        i = min(max(np.searchsorted(ts, tt, side='right'), 1), len(ts) - 1)
        u = (tt - ts[i - 1]) / (ts[i] - ts[i - 1])
        q_ref = slerp(m.quaternion[i - 1], m.quaternion[i], u)
        p_ref = (1 - u) * m.position[i - 1] + u * m.position[i]
        assert np.allclose(p[k], p_ref, atol=1e-12)
        # transforms.slerp switches to normalised lerp within 1.8 deg (error < 1e-6)
        assert min(np.abs(q[k] - q_ref).max(), np.abs(q[k] + q_ref).max()) < 1e-6


def test_pareto_front_matches_brute_force():
    rng = np.random.default_rng(3)
    pts = [tuple(p) for p in rng.uniform(0.1, 10.0, size=(60, 2))]
    pts += [(math.nan, 1.0), (1.0, math.inf)]
    front = set(ea.pareto_front(pts))
    for i, (t, e) in enumerate(pts):
        if not (math.isfinite(t) and math.isfinite(e)):
            assert i not in front
            continue
        dominated = any(t2 <= t and e2 <= e and (t2 < t or e2 < e)
                        for j, (t2, e2) in enumerate(pts) if j != i and math.isfinite(t2 + e2))
        assert (i in front) == (not dominated)


def test_substeps_per_frame():
    assert ea.substeps_per_frame(1 / 240.0) == 4
    assert ea.substeps_per_frame(1 / 60.0) == 1
    with pytest.raises(ValueError, match='must divide'):
        ea.substeps_per_frame(1 / 100.0)


@pytest.fixture(scope='module')
def workload():
    return make_workload(Scene(), 64)


def test_workload_and_guides(workload):
    assert workload.count == 64 and workload.ghost_rest.shape == (64, 16, 3)
    assert len(np.unique(workload.groups)) == 4               # 1:16 groups
    assert workload.guide_rest(4).shape == (16, 16, 3)
    with pytest.raises(ValueError, match='no guide'):
        workload.guide_rest(128)


def test_scorer_zero_for_the_reference_and_sensitive(workload):
    rest = workload.ghost_rest
    ref = np.stack([rest, rest + 0.001]).astype(np.float32)
    sc = ea.Scorer(workload, ref, rest)
    head = IDENTITY
    same = sc.frame(0, rest.copy(), head, rest)
    assert same['rms'] < 1e-7 and same['tip'] < 1e-7 and same['spread'] == pytest.approx(1.0)
    assert same['motion'] < 1e-7
    shift = np.array([0.01, 0.0, 0.0])
    shifted = sc.frame(0, rest + shift, head, rest)
    expected = np.sqrt(np.mean((0.01 / workload.strand_length) ** 2))
    assert shifted['rms'] == pytest.approx(expected, rel=1e-5)
    assert shifted['motion'] == pytest.approx(expected, rel=1e-5)
    # a method that starts 1 cm off and moves exactly like the reference: position error, but
    # no motion error
    moved = sc.frame(1, rest + shift + 0.001, head, rest + shift)
    assert moved['rms'] == pytest.approx(expected, rel=1e-3) and moved['motion'] < 1e-6
    # spreading every group about its centre doubles the spread: ratio 4 (variance)
    x = workload.ghost_rest.copy()
    for g in np.unique(workload.groups):
        m = workload.groups == g
        x[m, 2:] = 2 * x[m, 2:] - x[m, 2:].mean(axis=0)
    assert sc.frame(0, x, head, rest)['spread'] == pytest.approx(4.0, rel=1e-9)
    bad = workload.ghost_rest.copy()
    bad[0, 3, 1] = np.nan
    assert math.isinf(sc.frame(0, bad, head, rest)['rms'])


def _walk_schedule(seconds=0.5):
    return ea.HeadSchedule(load_bundled_walk(), ea.FRAME_RATE, seconds)


def test_rigid_offset_and_ghosts_start_at_rest_in_user_order(workload):
    head = HeadPose(np.array([0.3, -0.2, 1.6]), quat_from_axis_angle([0, 0, 1], 0.8),
                    quat_to_matrix(quat_from_axis_angle([0, 0, 1], 0.8)))
    want = head.to_world(workload.ghost_rest)
    for m in (RigidOffset('r', workload, Scene(), 4), GhostTracking('g', workload, Scene(), 4)):
        m.reset(head)
        assert np.allclose(m.output(head), want, atol=1e-12), m.name
    # under motion the rigid offset keeps every ghost root exactly on the scalp
    r = RigidOffset('r', workload, Scene(), 16)
    sched = _walk_schedule(0.3)
    last = {}
    ea.run_frames(r, sched, sched.frames, lambda j, x, h: last.update(x=x.copy(), h=h), 0.1)
    assert last['h'] is not sched.start()
    assert np.allclose(last['x'][:, :2], last['h'].to_world(workload.ghost_rest[:, :2]),
                       atol=1e-12)


def test_ghost_tracking_follows_the_full_simulation(workload):
    """At a 1:1 ratio, with the same solver, the ghosts stay close to the full simulation;
    with fewer guides they deviate more (the approximation the report quantifies)."""
    sched = _walk_schedule(1.0)
    runs = {}
    for name, m in (('full', FullSim('full', workload, Scene())),
                    ('1:1', GhostTracking('1:1', workload, Scene(), 1)),
                    ('1:16', GhostTracking('1:16', workload, Scene(), 16))):
        xs = []
        ea.run_frames(m, sched, sched.frames,
                      lambda j, x, h, xs=xs: xs.append(x.copy()) if j >= 0 else None, 0.5)
        runs[name] = np.array(xs)
    e1 = position_error(runs['1:1'][-1], runs['full'][-1], workload.strand_length)[0]
    e16 = position_error(runs['1:16'][-1], runs['full'][-1], workload.strand_length)[0]
    assert e1 < 0.25 and e1 < e16
    assert max_stretch(runs['1:16'][-1], workload.rest_length) < 1e-6   # length restoration


@pytest.mark.skipif(bool(pypbd_available()), reason='pypbd not installed (pip install pypbd)')
def test_pypbd_peer_hangs_like_our_pbd(workload, monkeypatch):
    # pypbd's OpenMP pool stalls on a loaded machine like numba's (read when pypbd loads)
    monkeypatch.setenv('OMP_NUM_THREADS', '1')
    scene = Scene().with_changes(solver__type='pbd', solver__iterations=4,
                                 collider__shape='none', damping=0.0)
    ours = FullSim('ours', workload, scene)
    peer = PyPBD('peer', workload, scene)
    try:
        with pytest.raises(RuntimeError, match='one PyPBD'):
            PyPBD('second', workload, scene)
        for m in (ours, peer):
            m.reset(IDENTITY)
            for _ in range(240):
                m.step(1 / 240.0, IDENTITY, IDENTITY)
        x_peer = peer.output(IDENTITY).copy()
        assert peer.excluded_seconds > 0.0
    finally:
        peer.close()
    x_ours = ours.output(IDENTITY)
    assert np.allclose(x_peer[:, :2], workload.ghost_rest[:, :2], atol=1e-12)
    # gravity is -z in the world for both (pypbd runs y-up internally)
    assert x_peer[:, -1, 2].mean() < workload.ghost_rest[:, -1, 2].mean() - 0.02
    assert np.abs(x_peer - x_ours).max() < 0.03


def test_evaluate_writes_tables_and_plots(tmp_path, workload):
    scene = Scene()
    specs = [s for s in ea.default_methods(scene, quick=True, with_pypbd=False)
             if s.name in ('full FTL dt 1/60', 'ghost 1:16 all on', 'ghost 1:16 plain copy',
                           'rigid offset 1:16')]
    assert len(specs) == 4
    tr = ea.Trajectory('walk', load_bundled_walk(), 'walk', 0.5)
    rep = ea.evaluate(workload, tr, specs, repeats=1, timing_frames=10, log=lambda s: None)
    rows = {r['method']: r for r in ea.rows(rep)}
    assert set(rows) == {s.name for s in specs}
    for r in rows.values():
        assert r['ms_frame'] > 0 and 0 < r['rms_err'] < 1 and r['max_err'] >= r['rms_err']
        assert 0 < r['motion_err'] < 1
        assert len(next(x for x in rep.results if x.name == r['method']).frame_ms) == 2
    # length restoration: the default ghosts keep exact lengths, the plain copy does not
    assert rows['ghost 1:16 all on']['max_stretch'] < 1e-6
    assert rows['ghost 1:16 plain copy']['max_stretch'] > 1e-3
    assert any(r['pareto'] for r in rows.values())
    paths = ea.write_outputs([rep], str(tmp_path / 'res'), str(tmp_path / 'fig'),
                             provenance('hair_sim_eval accuracy --test', 1), ['a note'],
                             time_series=('ghost 1:16 all on',))
    with open(paths['csv']) as f:
        table = list(csv.DictReader(f))
    assert len(table) == 4 and table[0]['motion'] == 'walk'
    md = open(paths['md']).read()
    assert '- Command: `hair_sim_eval accuracy --test`' in md and '| ghost 1:16 all on |' in md
    assert '- Date: ' in md and '1 thread(s) used' in md and '- a note' in md
    for key in ('pareto_walk', 'time_walk'):
        assert os.path.getsize(paths[key]) > 10_000
        assert open(paths[key], 'rb').read(8) == b'\x89PNG\r\n\x1a\n'


def test_cli_quick_subset(tmp_path, capsys):
    rc = eval_cli.main(['accuracy', '--quick', '--ghosts', '64', '--repeats', '0',
                        '--only', 'rigid offset 1:16', '--out', str(tmp_path / 'r'),
                        '--figures', str(tmp_path / 'f'), '--duration', '0.4'])
    assert rc == 0
    out = capsys.readouterr().out
    assert 'wrote csv' in out
    rows = list(csv.DictReader(open(tmp_path / 'r' / 'accuracy.csv')))
    assert [r['method'] for r in rows] == ['rigid offset 1:16']
    with pytest.raises(SystemExit):
        eval_cli.main(['accuracy', '--ghosts', '10'])


def test_vr_trajectory_is_the_busiest_window():
    trs = eval_cli.trajectories(eval_cli.MOTIONS, False, VR, log=lambda s: None)
    names = [t.name for t in trs]
    assert names == ['walk', 'vr', 'shake']
    vr = trs[1].motion
    assert 9.5 < vr.duration_s <= 10.0
    # the head centre moves (neck pivot), and the window is busier than the trace on average
    assert linear_speed(vr).max() > 0.05
    whole = read_vr360(VR)
    assert whole.duration_s > 11.0
    assert angular_speed(vr).mean() > angular_speed(whole).mean() > 0.3


def test_busiest_window_and_window():
    calm, busy = sm.still(3.0), sm.shake(6.0, 1.0, duration_s=2.0)
    m = sm.concat(calm, busy, sm.still(3.0))
    start = sm.busiest_window(m, 2.0)
    assert 2.5 <= start <= 3.5
    w = sm.window(m, start, 2.0)
    assert w.duration_s == pytest.approx(2.0, abs=0.01)
    with pytest.raises(sm.SyntheticMotionError, match='fewer than 2 samples'):
        sm.window(m, 100.0, 1.0)


def test_ghosts_once_per_frame_track_like_every_substep(workload):
    """The simulator's cheaper schedule (tracking.every_substep false): the eval method tracks
    once per output frame over its substeps; the hair stays close to the per-substep one."""
    sched = _walk_schedule(0.5)
    out = {}
    for every in (True, False):
        scene = Scene().with_changes(tracking__every_substep=every)
        m = GhostTracking(str(every), workload, scene, 4)
        assert m.sim.tracks_every_substep is every
        xs = []
        ea.run_frames(m, sched, sched.frames,
                      lambda j, x, h, xs=xs: xs.append(x.copy()) if j >= 0 else None, 0.25)
        out[every] = np.array(xs)
    d = position_error(out[False][-1], out[True][-1], workload.strand_length)[0]
    assert 0.0 < d < 0.05


def test_perturbed_reference_measures_the_perturbation(workload):
    """With a still head nothing amplifies the perturbation: the curve starts at its size
    (1 um on 25 cm strands: a few 1e-6 L), stays there, and scales with it."""
    scene = ea.reference_scene(Scene(), substeps=4, iterations=4)
    sched = ea.HeadSchedule(sm.still(0.5), ea.FRAME_RATE)
    ref, ref0, _ = ea.record_reference(workload, sched, scene, log=lambda s: None)
    small = ea.perturbed_reference(workload, sched, ref, ref0, scene, perturbation=1e-6)
    large = ea.perturbed_reference(workload, sched, ref, ref0, scene, perturbation=1e-4)
    assert 1e-7 < small[0] < 1e-5 and small.max() < 1e-5
    assert large[0] / small[0] == pytest.approx(100.0, rel=0.05)


# ------------------------------------------------------------------ dominance study
def test_dominance_scores_once_and_times_per_thread_count(tmp_path):
    from hair_tracking.evaluation import dominance as dm
    workload = make_workload(Scene(), 64)
    tr = ea.Trajectory('walk', load_bundled_walk(), 'walk', 0.3)
    reps = dm.study(workload, tr, 0.3, repeats=1, timing_frames=5, thread_counts=[1, 2],
                    log=lambda s: None)
    assert [r['threads'] for r in reps] == [1, 2]
    names = [c.name for c in dm.candidates(workload.scene)]
    for rep in reps:
        rows = {r.name: r for r in rep['rows']}
        assert list(rows) == names and not rows[dm.BASELINE].ghost
        for r in rows.values():
            assert len(r.frame_ms) == 1 and r.ms > 0
            assert 0 < r.motion_err < 100 and r.stretch < 2e-5   # float32 ghost positions
            share_ok = r.ms <= dm.TIME_SHARE * rows[dm.BASELINE].ms
            err_ok = r.motion_err <= rows[dm.BASELINE].motion_err
            assert r.dominates == (r.ghost and r.admitted and share_ok and err_ok)
    # the errors are scored once: the same for every thread count
    assert [r.motion_err for r in reps[0]['rows']] == [r.motion_err for r in reps[1]['rows']]
    md = dm.markdown(reps[0], 1)
    assert '| full FTL dt 1/60 |' in md and '1 thread(s)' in md
    png = dm.plot(reps, str(tmp_path / 'dominance.png'))
    assert open(png, 'rb').read(8) == b'\x89PNG\r\n\x1a\n'


def test_dominance_summary_counts_the_cases_each_tracker_wins():
    from hair_tracking.evaluation import dominance as dm

    def case(motion, *rows):
        return {'motion': motion, 'strands': 64, 'threads': 1,
                'rows': [dm.Row(dm.BASELINE, False, [3.0], 10.0)] + [
                    dm.Row(name, True, [ms], err, dominates=wins) for name, ms, err, wins in rows]}
    reports = [case('walk', ('turn 1:16, guides dt 1/60', 0.9, 9.0, True),
                    ('blend 1:16, guides dt 1/60', 0.6, 9.5, True),
                    ('paper 1:16', 2.0, 8.0, False)),
               case('shake', ('turn 1:16, guides dt 1/60', 1.2, 11.0, False),
                    ('blend 1:16, guides dt 1/60', 0.8, 9.0, True),
                    ('paper 1:16', 2.0, 8.0, False)),
               case('vr', ('turn 1:16, guides dt 1/60', 1.2, 11.0, False),
                    ('blend 1:16, guides dt 1/60', 1.5, 9.0, False),
                    ('paper 1:16', 2.0, 8.0, False))]
    text = dm.summary(reports)
    assert text.startswith('**A ghost setting dominates the baseline in 2/3 cases**; cases won '
                           'by each tracker: turn 1/3, blend 2/3, paper 0/3.')
    lines = text.splitlines()
    assert lines[4] == ('| walk | 64 | 1 | 3.00, 10.00 | blend 1:16, guides dt 1/60 | 0.60 | '
                        '0.20 | 9.50 |')                 # the cheaper of the two that win
    assert lines[6].startswith('| vr | 64 | 1 | 3.00, 10.00 | - |')
    # the JSON form of a report reads back into the same summary
    dumped = [{**r, 'rows': [dict(x.__dict__, ms=x.ms) for x in r['rows']]} for r in reports]
    assert dm.summary([dm.rows_from_json(json.loads(json.dumps(r))) for r in dumped]) == text


def test_dominance_cli_writes_tables_and_the_plot(tmp_path):
    rc = eval_cli.main(['dominance', '--ghosts', '64', '--motions', 'walk', '--duration', '0.2',
                        '--repeats', '1', '--thread-counts', '1', '--out', str(tmp_path / 'r'),
                        '--figures', str(tmp_path / 'f')])
    assert rc == 0
    md = open(tmp_path / 'r' / 'dominance.md').read()
    assert 'hair_sim_eval dominance --ghosts 64' in md and '#### walk, 64 strands' in md
    assert '**A ghost setting dominates the baseline in ' in md.split('#### walk')[0]
    with open(tmp_path / 'r' / 'dominance.json') as f:
        report = json.load(f)
    assert report['provenance']['command'].startswith('hair_sim_eval dominance --ghosts 64')
    assert report['studies'][0]['motion'] == 'walk' and report['studies'][0]['strands'] == 64
    assert os.path.getsize(tmp_path / 'f' / 'dominance.png') > 5_000


def test_dominance_cli_evaluates_recorded_motions_a_bag_and_a_pose_csv(tmp_path):
    """``--motion FILE`` (repeatable) adds a user's recording, read as hair_sim_bag reads it."""
    bag = os.path.join(os.path.dirname(ea.__file__), '..', 'data', 'walk_head_pose.mcap')
    nod = tmp_path / 'nod.csv'
    with open(nod, 'w', newline='') as f:
        w = csv.writer(f)
        w.writerow(['t_s', 'px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw'])
        for k in range(40):
            q = quat_from_axis_angle([0.0, 1.0, 0.0], 0.3 * math.sin(0.2 * k))
            w.writerow([0.01 * k, 0.0, 0.0, 1.6] + [float(c) for c in q])
    rc = eval_cli.main(['dominance', '--ghosts', '64', '--motions', '--motion', bag,
                        '--motion', str(nod), '--duration', '0.2', '--repeats', '1',
                        '--thread-counts', '1', '--out', str(tmp_path / 'r'),
                        '--figures', str(tmp_path / 'f')])
    assert rc == 0
    md = open(tmp_path / 'r' / 'dominance.md').read()
    assert '#### walk_head_pose, 64 strands' in md and '#### nod, 64 strands' in md
    assert '#### walk, 64 strands' not in md                   # no built-in motion asked for


@pytest.mark.parametrize('cmd', ['accuracy', 'dominance'])
@pytest.mark.parametrize('content, name, message', [
    ('not a bag', 'motion.mcap', 'not a bag'),
    ('t_s px\n1 2\n', 'motion.csv', 'no quaternion columns recognised'),
    (None, 'missing.bvh', 'BVH file not found'),
])
def test_a_bad_motion_file_is_refused_before_any_work_with_a_clear_message(
        tmp_path, capsys, cmd, content, name, message):
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(SystemExit) as e:
        eval_cli.main([cmd, '--motion', str(path), '--out', str(tmp_path / 'out')])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert '--motion: ' in err and message in err and 'Traceback' not in err
    assert not (tmp_path / 'out').exists()


def _dominance_rows(path):
    """The figures of every row of dominance.json that do not depend on timing."""
    import json
    keys = ('name', 'ghost', 'motion_err', 'settled_err', 'stretch', 'penetration_mm',
            'admitted')
    with open(path) as f:
        studies = json.load(f)['studies']
    return [[{k: r[k] for k in keys} for r in rep['rows']] for rep in studies]


def test_motion_files_evaluate_as_they_import(tmp_path, capsys):
    """``--motion F`` reads F as ``hair_sim_bag import F`` does (units, columns, ticks): a BVH
    in centimetres and a ``timestamp,x,y,z,qx,qy,qz,qw`` table in 100 ns ticks give the
    figures their imported bags give."""
    import argparse
    from hair_tracking.bags import recording
    from hair_tracking.bags.cli import main as bag_main
    from test_import_units import write_bvh
    bvh = write_bvh(tmp_path / 'walk_cm.bvh', 0.01, frames=48)
    table = tmp_path / 'tracker.csv'
    t0 = 638_680_000_000_000_000
    rows = ['timestamp,x,y,z,qx,qy,qz,qw']
    for k in range(40):
        q = quat_from_axis_angle([0.0, 1.0, 0.0], 0.3 * math.sin(0.2 * k))
        rows.append(f'{t0 + k * 100_000},{0.002 * k},0,1.6,' + ','.join(f'{c:.9f}' for c in q))
    table.write_text('\n'.join(rows) + '\n')
    bags = []
    for f in (bvh, table):
        bags.append(tmp_path / (f.stem + '_bag.mcap'))
        assert bag_main(['import', str(f), '-o', str(bags[-1])]) == 0
    rc = eval_cli.main(['dominance', '--ghosts', '64', '--motions', '--duration', '0.3',
                        '--repeats', '1', '--thread-counts', '1', '--out', str(tmp_path / 'r'),
                        '--motion', str(bvh), '--motion', str(table),
                        '--motion', str(bags[0]), '--motion', str(bags[1])])
    assert rc == 0
    files, imported = _dominance_rows(tmp_path / 'r' / 'dominance.json')[:2], \
        _dominance_rows(tmp_path / 'r' / 'dominance.json')[2:]
    assert files == imported
    md = open(tmp_path / 'r' / 'dominance.md').read()
    assert '#### walk_cm, 64 strands' in md and '#### tracker_bag, 64 strands' in md
    # the head of the BVH moves at a walker's speed (CMU units would make it 5.6 times faster)
    p = argparse.ArgumentParser()
    recording.add_arguments(p)
    walk = eval_cli.recorded(argparse.Namespace(motion=[str(bvh)], **vars(p.parse_args([]))))
    assert linear_speed(walk[0].motion).mean() == pytest.approx(1.2, rel=0.1)


@pytest.mark.parametrize('cmd', ['accuracy', 'dominance'])
def test_unknown_motion_names_are_a_usage_error(tmp_path, capsys, cmd):
    with pytest.raises(SystemExit) as e:
        eval_cli.main([cmd, '--quick' if cmd == 'accuracy' else '--duration=0.2',
                       '--motions', 'wlak', '--out', str(tmp_path / 'out')])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'wlak'" in err and "'walk', 'vr', 'shake'" in err
    assert not (tmp_path / 'out').exists()


def test_built_in_motions_and_files_are_kept_alike(tmp_path):
    """``--motions walk --motion F``: the walk and the file, in accuracy as in dominance."""
    bag = os.path.join(os.path.dirname(ea.__file__), '..', 'data', 'walk_head_pose.mcap')
    rc = eval_cli.main(['accuracy', '--quick', '--ghosts', '64', '--repeats', '0',
                        '--only', 'rigid offset 1:16', '--duration', '0.2', '--motions', 'walk',
                        '--motion', bag, '--out', str(tmp_path / 'a')])
    assert rc == 0
    rows = list(csv.DictReader(open(tmp_path / 'a' / 'accuracy.csv')))
    assert [r['motion'] for r in rows] == ['walk', 'walk_head_pose']
    assert os.path.isfile(tmp_path / 'a' / 'figures' / 'pareto_walk_head_pose.png')
    rc = eval_cli.main(['dominance', '--ghosts', '64', '--motions', 'walk', '--motion', bag,
                        '--duration', '0.2', '--repeats', '1', '--out', str(tmp_path / 'd')])
    assert rc == 0
    md = open(tmp_path / 'd' / 'dominance.md').read()
    assert '#### walk, 64 strands' in md and '#### walk_head_pose, 64 strands' in md
    assert os.path.isfile(tmp_path / 'd' / 'figures' / 'dominance.png')


@pytest.mark.parametrize('argv', [
    ['stability', '--quick', '--only', 'ftl teleport 1 m'],
    ['accuracy', '--quick', '--ghosts', '64', '--repeats', '0', '--only', 'rigid offset 1:16',
     '--duration', '0.2'],
    ['dominance', '--ghosts', '64', '--motions', 'walk', '--duration', '0.2', '--repeats', '1'],
])
def test_commands_write_under_out_of_the_current_folder(tmp_path, monkeypatch, argv):
    """Without --out nothing is written outside out/eval/<command>/ (the committed reports
    under docs/ are left alone)."""
    monkeypatch.chdir(tmp_path)
    assert eval_cli.main(argv) == 0
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob('*') if p.is_file())
    assert written and all(w.startswith(os.path.join('out', 'eval', argv[0], '')) for w in written)
