"""The live node's load-shedding policy (hair_tracking.ros.load_shedding), without ROS."""
import pytest

from hair_tracking.ros.load_shedding import LoadShedder, RESTORE_FRACTION, URGENT, \
    URGENT_POSES, WINDOW

PERIOD_NS = 16_666_667          # 60 Hz poses
SUBSTEPS = 4                    # 240 Hz substeps


def feed(shedder, poses, step_ms, track_ms, start=0):
    """``poses`` poses 60 Hz apart; returns the decision after each."""
    out = []
    for k in range(start, start + poses):
        out.append(shedder.update(k * PERIOD_NS, step_ms, track_ms, SUBSTEPS))
    return out


def test_steps_that_fit_never_shed():
    s = LoadShedder(0.6)
    assert not any(feed(s, 50, step_ms=9.0, track_ms=2.0))      # 9 ms < 0.6 x 16.7 ms
    assert s.switches == 0


def test_slow_steps_shed_after_half_a_window_and_stay_shed_while_the_estimate_is_high():
    s = LoadShedder(0.6)
    decisions = feed(s, WINDOW, step_ms=14.0, track_ms=3.0)
    first = decisions.index(True)
    assert first == WINDOW // 2          # needs WINDOW//2 periods and full-schedule steps
    assert all(decisions[first:])
    # shed steps of 6 ms with 3 ms of tracking: the full schedule is estimated at
    # 6 + 3 x 3 = 15 ms > 10 ms allowed: keep shedding
    assert all(feed(s, 30, step_ms=6.0, track_ms=3.0, start=WINDOW))
    assert s.switches == 1


def test_restores_only_below_two_thirds_of_the_budget():
    s = LoadShedder(0.6)
    feed(s, WINDOW, step_ms=14.0, track_ms=3.0)
    allowed = 0.6 * PERIOD_NS * 1e-6
    # estimate 5.0 + 3 x 1.0 = 8.0 ms: below the budget (10 ms) but above 2/3 of it (6.7 ms)
    assert 5.0 + 3 * 1.0 > RESTORE_FRACTION * allowed
    assert all(feed(s, 20, step_ms=5.0, track_ms=1.0, start=WINDOW))
    # estimate 3.0 + 3 x 0.5 = 4.5 ms: restored once the window's median drops below 6.7 ms
    # (half a window of such poses: median of four 8.0 and four 4.5 is 6.25 ms)
    later = feed(s, WINDOW, step_ms=3.0, track_ms=0.5, start=WINDOW + 20)
    k = WINDOW // 2 - 1
    assert later[:k] == [True] * k and not any(later[k:])
    assert s.switches == 2


def test_one_slow_pose_does_not_shed_and_reset_forgets_the_timings():
    s = LoadShedder(0.6)
    feed(s, WINDOW, step_ms=5.0, track_ms=1.0)
    assert s.update(WINDOW * PERIOD_NS, 40.0, 10.0, SUBSTEPS) is False     # median, not max
    assert s.update((WINDOW + 1) * PERIOD_NS, 5.0, 1.0, SUBSTEPS) is False
    s.reset()
    # after a reset the periods are unknown again: no decision for half a window (over the
    # budget, 14 ms > 0.6 x 16.7 ms, but under two periods: not urgent)
    assert feed(s, WINDOW // 2, step_ms=14.0, track_ms=3.0, start=100) == \
        [False] * (WINDOW // 2)
    assert feed(s, 1, step_ms=14.0, track_ms=3.0, start=100 + WINDOW // 2) == [True]


def test_poses_far_over_the_period_shed_after_two():
    """Two poses in a row that each took more than URGENT pose periods shed at once (the
    node falls further behind with every such pose), also right after a start or reset."""
    s = LoadShedder(0.6)
    slow = URGENT * PERIOD_NS * 1e-6 + 1.0
    assert feed(s, URGENT_POSES, step_ms=slow, track_ms=8.0) == \
        [False] * (URGENT_POSES - 1) + [True]   # the second pose gives the first period
    s = LoadShedder(0.6)
    feed(s, WINDOW, step_ms=5.0, track_ms=1.0)
    assert feed(s, URGENT_POSES, step_ms=slow, track_ms=8.0, start=WINDOW) == \
        [False] * (URGENT_POSES - 1) + [True]
    s = LoadShedder(0.6)
    feed(s, WINDOW, step_ms=5.0, track_ms=1.0)          # alternating: never two in a row
    for k in range(WINDOW // 2):                        # (and the median stays low)
        assert not s.update((WINDOW + k) * PERIOD_NS, slow if k % 2 else 5.0, 1.0, SUBSTEPS)


def test_poses_without_substeps_do_not_count_and_the_budget_is_checked():
    s = LoadShedder(0.6)
    for k in range(3 * WINDOW):
        assert s.update(k * 1_000_000, 50.0, 10.0, 0) is False   # nothing simulated
    with pytest.raises(ValueError, match='budget'):
        LoadShedder(0.0)
