"""The run-time choice between a parallel kernel and its serial twin."""
import numpy as np
import pytest

from hair_tracking.core.groom import make_groom
from hair_tracking.core.head_track import IDENTITY
from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.ghosts import tracker as ghosts_module
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.guides import integrate
from hair_tracking.guides.solver import GuideSolver
from hair_tracking.parallel_choice import ParallelChooser


def drive(chooser, calls, parallel_s, serial_s, static=True):
    """Run ``calls`` calls with fixed durations per variant; returns the variants used."""
    used = []
    for _ in range(calls):
        par = chooser.choose(static)
        used.append(par)
        chooser.record(parallel_s if par else serial_s)
    return used


def fake_timed(chooser, seconds):
    """``chooser.timed`` with made-up durations ``seconds[parallel]`` instead of the clock."""
    def timed(static, par_fn, ser_fn, *args):
        par = chooser.choose(static)
        out = (par_fn if par else ser_fn)(*args)
        chooser.record(seconds[par])
        return out
    return timed


def test_keeps_the_static_choice_until_it_has_settled_then_tries_the_other():
    c = ParallelChooser(window=4, settle=10, reprobe=20)
    used = drive(c, 10, 1.0, 2.0)
    assert used == [True] * 10                        # settling on the static rule's choice
    used = drive(c, 3, 1.0, 2.0)
    assert used == [False] * 3 and c.trials == 1      # a trial of the serial twin ...
    assert c.parallel and c.switches == 0             # ... slower: parallel kept
    assert drive(c, 20, 1.0, 2.0) == [True] * 20      # no trial before reprobe calls
    assert drive(c, 3, 1.0, 2.0) == [False] * 3 and c.trials == 2


@pytest.mark.parametrize('window', [1, 4, 5, 8])
def test_a_trial_ends_as_soon_as_it_cannot_win(window):
    """More than half of a trial's window at or above the bar (margin x the current median)
    decides it: it stops there; a trial that is winning runs its whole window."""
    c = ParallelChooser(window=window, settle=window, reprobe=100)
    drive(c, window, 1.0, 2.0)
    used = drive(c, window, 1.0, 2.0)                 # serial twice as slow
    need = window // 2 + 1
    assert used == [False] * need + [True] * (window - need)
    assert c.trials == 1 and c.parallel
    # slow calls mixed with fast ones: still undecided until the window is full
    c = ParallelChooser(window=window, settle=window, reprobe=100)
    drive(c, window, 1.0, 2.0)
    times = [2.0 if k % 2 else 0.5 for k in range(window)]     # median 0.5 or 1.25
    used = []
    for t in times:
        used.append(c.choose(True))
        c.record(t)
    assert used == [False] * window and c.trials == 1
    assert c.switches == (1 if window % 2 else 0)


def test_switches_to_the_faster_variant_and_back_when_the_machine_changes():
    c = ParallelChooser(window=4, settle=8, reprobe=16)
    drive(c, 8 + 4, 3.0, 2.0)                         # steal: parallel 3 s, serial 2 s
    assert not c.parallel and c.switches == 1 and not c.in_use
    assert drive(c, 16, 3.0, 2.0) == [False] * 16     # serial kept between trials
    used = drive(c, 4 + 16, 1.0, 2.0)                 # quiet again: parallel 1 s
    assert used[:4] == [True] * 4 and c.parallel and c.switches == 2 and c.in_use


def test_a_difference_within_the_margin_does_not_switch():
    c = ParallelChooser(window=4, settle=8, reprobe=8, margin=0.9)
    drive(c, 8 + 4 * 10, 1.0, 0.95)                   # serial only 5 % faster
    assert c.parallel and c.switches == 0 and c.trials >= 4


def test_a_problem_the_static_rule_keeps_serial_is_never_tried_in_parallel():
    c = ParallelChooser(window=2, settle=2, reprobe=2)
    assert drive(c, 50, 0.1, 5.0, static=False) == [False] * 50
    assert c.trials == 0 and not c.in_use
    # allowed again (more threads, a larger scene): starts over from parallel and settles
    assert drive(c, 2, 0.1, 5.0) == [True, True]


def test_bad_settings_are_rejected():
    with pytest.raises(ValueError, match='window'):
        ParallelChooser(window=0)
    with pytest.raises(ValueError, match='margin'):
        ParallelChooser(margin=1.5)


def test_timed_runs_the_chosen_function_and_returns_its_result():
    c = ParallelChooser(window=1, settle=1, reprobe=1)
    calls = []
    out = c.timed(True, lambda a: calls.append(('par', a)) or 1,
                  lambda a: calls.append(('ser', a)) or 2, 7)
    assert out == 1 and calls == [('par', 7)]
    out = c.timed(True, lambda a: 1, lambda a: calls.append(('ser', a)) or 2, 8)
    assert out == 2 and calls[-1] == ('ser', 8)        # the trial of the serial twin


def test_ghost_tracker_gives_the_same_hair_whichever_variant_the_timings_pick(monkeypatch):
    """A tracker large enough for the parallel kernel, stepped with the serial twin made to
    look faster (a fake clock), switches to it; its hair equals a tracker that stays
    parallel, bit for bit."""
    scene = Scene().with_changes(groom__guides=24, groom__ghosts_per_guide=16,
                                 groom__guide_nodes=16, groom__ghost_nodes=16)
    groom = make_groom(scene.groom)

    def tracker():
        guides = StrandSet.from_rest(groom.guide_rest)
        t = GhostTracker(StrandSet.from_rest(groom.ghost_rest), guides, scene, None)
        t.reset(IDENTITY)
        guides.place_at(IDENTITY)
        return t, guides

    monkeypatch.setattr(ghosts_module, 'runs_parallel', lambda nodes: True)
    a, ga = tracker()
    b, gb = tracker()
    a.threads = ParallelChooser(window=2, settle=4, reprobe=4)
    b.threads = ParallelChooser(window=2, settle=10 ** 9)          # never tries the other
    a.threads.timed = fake_timed(a.threads, {True: 10.0, False: 1.0})   # serial looks faster
    for k in range(30):
        for t, g in ((a, ga), (b, gb)):
            old = g.x.copy()
            g.x[:, 2:, 0] = groom.guide_rest[:, 2:, 0] + 0.01 * np.sin(0.3 * k)
            t.step(1.0 / 240.0, old, IDENTITY)
    assert a.stats['thread_switches'] == 1 and a.stats['parallel'] == 0
    assert b.stats['thread_switches'] == 0 and b.stats['parallel'] == 1
    np.testing.assert_array_equal(a.positions(), b.positions())
    np.testing.assert_array_equal(a.ghosts.v, b.ghosts.v)


@pytest.mark.parametrize('solver', ['pbd', 'xpbd', 'ftl'])
def test_guide_solver_gives_the_same_hair_whichever_variant_the_timings_pick(monkeypatch,
                                                                             solver):
    """The guide solvers choose the same way; a solver switched to the serial twins moves its
    strands exactly as one that stays on the parallel kernels."""
    monkeypatch.setattr(integrate, 'runs_parallel', lambda nodes: True)
    scene = Scene().with_changes(groom__guides=64, solver__type=solver)
    groom = make_groom(scene.groom)
    a = GuideSolver(StrandSet.from_rest(groom.guide_rest), scene)
    b = GuideSolver(StrandSet.from_rest(groom.guide_rest), scene)
    a.threads = ParallelChooser(window=2, settle=4, reprobe=4)
    a.threads.timed = fake_timed(a.threads, {True: 10.0, False: 1.0})
    b.threads = ParallelChooser(window=2, settle=10 ** 9)
    head_prev = IDENTITY
    for s in (a, b):
        s.reset(IDENTITY)
    for k in range(40):
        yaw = 0.4 * np.sin(0.2 * k)
        q = np.array([0.0, 0.0, np.sin(yaw / 2), np.cos(yaw / 2)])
        head = HeadPose(np.array([0.02 * np.sin(0.3 * k), 0.0, 0.0]), q, quat_to_matrix(q))
        for s in (a, b):
            s.step(1.0 / 240.0, head_prev, head)
        head_prev = head
    assert a.threads.switches == 1 and not a.threads.in_use and b.threads.in_use
    np.testing.assert_array_equal(a.strands.x, b.strands.x)
    np.testing.assert_array_equal(a.strands.v, b.strands.v)
