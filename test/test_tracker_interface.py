"""Every ghost tracker implements the declared interface
(:class:`hair_tracking.ghosts.interface.GhostTracking`), and the simulator reaches the ghosts
through it only."""
import inspect

import numpy as np
import pytest

from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from hair_tracking.ghosts.blend import BlendTracker
from hair_tracking.ghosts.interface import GhostTracking, TrackStep
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.ghosts.turn import TurnTracker
from hair_tracking.simulator import HairSimulator

TRACKERS = {'paper': GhostTracker, 'blend': BlendTracker, 'turn': TurnTracker}


def small(mode, **changes):
    return Scene().with_changes(groom__guides=4, groom__ghosts_per_guide=3, tracking__mode=mode,
                                solver__settle_time=0.0, **changes)


def _methods(cls):
    return {name for name, member in inspect.getmembers(cls, inspect.isfunction)
            if not name.startswith('_')}


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_each_tracker_implements_the_interface_with_its_signatures(mode):
    sim = HairSimulator(small(mode))
    tracker = sim.ghost_tracker
    assert type(tracker) is TRACKERS[mode]
    assert isinstance(tracker, GhostTracking)
    declared = _methods(GhostTracking)
    assert declared == {'step', 'reset', 'carry', 'zero_velocities', 'positions', 'velocities',
                        'part_positions', 'write_records'}
    for name in declared:
        want = inspect.signature(getattr(GhostTracking, name))
        got = inspect.signature(getattr(TRACKERS[mode], name))
        assert list(got.parameters) == list(want.parameters), (mode, name)
        for p, q in zip(got.parameters.values(), want.parameters.values()):
            assert p.kind == q.kind and p.default == q.default, (mode, name, p.name)
    assert isinstance(tracker.stats, dict) and {'steps', 'parallel'} <= set(tracker.stats)


def test_an_object_without_the_interface_is_not_a_tracker():
    class Partial:
        stats = {}

        def step(self, motion):
            pass
    assert not isinstance(Partial(), GhostTracking)


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_the_state_is_the_trackers_and_moves_only_through_its_interface(mode):
    """The ghosts' StrandSet is plain data: a step, a reset or a carry changes what the
    tracker shows, never the arrays the tracker started from."""
    sim = HairSimulator(small(mode))
    tracker = sim.ghost_tracker
    start = sim.ghosts.x.copy(), sim.ghosts.v.copy()
    q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.4)
    head = HeadPose(np.array([0.1, 0.0, 0.0]), q, quat_to_matrix(q))
    old = sim.guides.x.copy()
    sim.guides.x[...] = head.to_world(sim.guides.rest)
    tracker.step(TrackStep(1 / 60, 4, old, sim.guides.x, head))
    x = np.array(tracker.positions(), dtype=np.float64)
    np.testing.assert_allclose(x[:, :2], head.to_world(sim.ghosts.rest[:, :2]), atol=2e-7)
    assert np.abs(x - start[0]).max() > 0.05
    np.testing.assert_array_equal(sim.ghosts.x, start[0])
    np.testing.assert_array_equal(sim.ghosts.v, start[1])
    tracker.zero_velocities()
    assert not np.asarray(tracker.velocities()).any()
    back = HeadPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.eye(3))
    tracker.carry(head, back)
    np.testing.assert_allclose(tracker.positions()[:, :2], sim.ghosts.rest[:, :2], atol=2e-7)
    tracker.reset(head)
    np.testing.assert_allclose(tracker.positions(), head.to_world(sim.ghosts.rest), atol=2e-7)
    with pytest.raises(ValueError):
        tracker.positions()[0, 0, 0] = 1.0          # read only
    np.testing.assert_array_equal(sim.ghosts.x, start[0])


def test_a_rebuilt_tracker_starts_where_the_old_one_left_the_ghosts():
    sim = HairSimulator(small('paper'))
    t0 = 1_000_000_000
    for k in range(6):
        q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.2 * k)
        sim.push_pose(t0 + k * 16_666_667, [0.01 * k, 0.0, 0.0], q)
        sim.advance_to(t0 + k * 16_666_667)
    x, v = sim.frame().ghosts, np.array(sim.ghost_tracker.velocities())
    assert np.abs(v).max() > 0.0
    assert sim.update_scene(sim.scene.with_changes(tracking__com_strength=0.3)) is False
    np.testing.assert_array_equal(sim.frame().ghosts, x)
    np.testing.assert_array_equal(sim.ghost_tracker.velocities(), v)


def test_strandset_is_plain_data():
    s = StrandSet.from_rest(np.zeros((2, 4, 3)))
    assert set(vars(s)) == {'rest', 'rest_length', 'inv_mass', 'x', 'v'}
    x = np.ones((2, 4, 3))
    s.x = x
    assert s.x is x
