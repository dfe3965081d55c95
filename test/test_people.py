"""Every person in view, without ROS: the crowd's batched guides against one simulator per
person, one compiled call a run for all people, the roster's lifetimes and the sellion offset."""
import numpy as np
import pytest

from hair_tracking.core.head_track import PoseResult
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.guides import ftl
from hair_tracking.guides.solver import GuideSolver
from hair_tracking.people.crowd import Crowd, CrowdFull
from hair_tracking.people.roster import face_id, id_problem, Roster
from hair_tracking.simulator import HairSimulator

pytestmark = pytest.mark.usefixtures('one_numba_thread')

SMALL = dict(groom__guides=10, groom__ghosts_per_guide=3, groom__guide_nodes=6,
             groom__ghost_nodes=6, solver__settle_time=0.05)
T0 = 1_000_000_000
PERIOD = 16_666_667


def small(**changes):
    return Scene().with_changes(**dict(SMALL, **changes))


def yaw(a):
    return [0.0, 0.0, float(np.sin(a / 2)), float(np.cos(a / 2))]


def pose(k, i, fast=False):
    """Person ``i``'s head at pose ``k``: side by side, nodding their own way (``fast``: a
    turn of 1.2 rad in one pose at pose 5, which the split rule splits)."""
    a = 0.3 * np.sin(0.4 * k + i)
    if fast and k >= 5:
        a += 1.2
    return [0.5 * i + 0.02 * np.sin(0.3 * k), 0.0, 0.0], yaw(a)


@pytest.mark.parametrize('changes, fast', [({}, False), ({}, True),
                                           ({'tracking__mode': 'paper'}, False),
                                           ({'solver__type': 'pbd'}, False)])
def test_each_persons_hair_is_the_hair_of_one_simulator(changes, fast):
    """(A substep split for one person is split for all, so with a fast turn one person's hair
    is compared: the split rule's run is the single head's.)"""
    scene = small(**changes)
    crowd = Crowd(scene, 4)
    alone = [HairSimulator(scene) for _ in range(1 if fast else 3)]
    for i, sim in enumerate(alone):
        p, q = pose(0, i)
        assert crowd.add(str(i), T0, p, q) is PoseResult.ACCEPTED
        sim.push_pose(T0, p, q)
    for k in range(1, 12):
        t = T0 + k * PERIOD
        for i, sim in enumerate(alone):
            p, q = pose(k, i, fast)
            crowd.push_pose(str(i), t, p, q)
            sim.push_pose(t, p, q)
            sim.advance_to(t)
        crowd.advance_to(t)
        for i, sim in enumerate(alone):
            mine, theirs = crowd.people[str(i)].frame(), sim.frame()
            np.testing.assert_allclose(mine.guides, theirs.guides, rtol=0, atol=1e-12)
            np.testing.assert_allclose(mine.ghosts, theirs.ghosts, rtol=0, atol=1e-12)
    if fast:
        assert crowd.people['0'].counters.extra.get('split_substeps', 0) > 0
        assert crowd.people['0'].counters.resets == 0


def test_the_guides_of_all_people_advance_in_one_call(monkeypatch):
    crowd = Crowd(small(), 8)
    for i in range(4):
        p, q = pose(0, i)
        crowd.add(str(i), T0, p, q)
    calls = []
    kernel = ftl.ftl_advance_serial

    def spy(*args):
        calls.append(args[-1].copy())
        return kernel(*args)
    monkeypatch.setattr(ftl, 'ftl_advance_serial', spy)
    for name in ('advance', 'step'):
        monkeypatch.setattr(GuideSolver, name, lambda *a, **k: pytest.fail('a solver a head'))
    t = T0 + 4 * crowd.dt_ns
    for i in range(4):
        p, q = pose(1, i)
        crowd.push_pose(str(i), t, p, q)
    assert crowd.advance_to(t) == 4
    assert len(calls) == 1 and sorted(calls[0].tolist()) == [0, 1, 2, 3]


def test_a_person_is_placed_and_freed():
    crowd = Crowd(small(), 2)
    crowd.add('a', T0, [0, 0, 0], yaw(0))
    crowd.add('b', T0, [1, 0, 0], yaw(0))
    with pytest.raises(CrowdFull):
        crowd.add('c', T0, [2, 0, 0], yaw(0))
    crowd.remove('a')
    crowd.add('c', T0, [2, 0, 0], yaw(0))
    assert sorted(crowd.people) == ['b', 'c']
    assert np.shares_memory(crowd.people['c'].guides.x, crowd.x)


def test_face_frames_and_ids():
    assert face_id('face_ab3') == 'ab3' and face_id('/face_x') == 'x'
    assert face_id('face_') is None and face_id('body_ab3') is None
    assert id_problem('ab3') is None and id_problem('a_b') is None
    assert 'cannot name a topic' in id_problem('3ab')
    assert id_problem('a-b') and id_problem('a__b')


def test_the_head_centre_lies_at_the_sellion_offset_in_the_face_frame():
    scene = small(people__sellion_offset=[-0.09, 0.0, 0.02])
    roster = Roster(scene)
    q = yaw(np.pi / 2)                                   # facing +y
    roster.face('a', T0, [1.0, 2.0, 1.5], q, now_ns=0)
    head = roster.crowd.people['a'].head
    expected = np.array([1.0, 2.0, 1.5]) + quat_to_matrix(np.array(q)) @ [-0.09, 0.0, 0.02]
    np.testing.assert_allclose(head.position, expected, atol=1e-12)
    np.testing.assert_allclose(head.position, [1.0, 1.91, 1.52], atol=1e-12)


def test_people_come_and_go_and_come_back_with_fresh_hair():
    scene = small(people__lost_timeout_s=0.5, people__max=2)
    roster = Roster(scene)
    roster.listed(['a', 'b', 'c'], now_ns=0)
    assert roster.crowd.people == {}                      # listed, no pose yet
    for pid, x in (('a', 0.0), ('b', 1.0)):
        assert roster.face(pid, T0, [x, 0, 0], yaw(0), now_ns=0) is PoseResult.ACCEPTED
    assert roster.face('c', T0, [2, 0, 0], yaw(0), now_ns=0) is None    # no place
    assert roster.appeared == ['a', 'b'] and roster.waiting == 1
    roster.appeared.clear()
    for k in range(1, 40):
        now = k * PERIOD
        roster.listed(['a'], now_ns=now)
        roster.face('a', T0 + now, [0.1 * np.sin(k), 0, 0], yaw(0.2 * k), now_ns=now)
        roster.advance_to(T0 + now)
        roster.expire(now)
    assert roster.removed == ['b'] and sorted(roster.crowd.people) == ['a']
    # b comes back far away: fresh hair, settled and carried there, not dragged from before
    now = 40 * PERIOD
    p, q = [3.0, 1.0, 0.5], yaw(1.0)
    roster.face('b', T0 + now, p, q, now_ns=now)
    fresh = HairSimulator(scene)
    offset = quat_to_matrix(np.array(q)) @ np.array(scene.people.sellion_offset)
    fresh.push_pose(T0 + now, np.array(p) + offset, q)
    back = roster.crowd.people['b']
    np.testing.assert_allclose(back.guides.x, fresh.guides.x, atol=1e-12)
    np.testing.assert_allclose(back.frame().ghosts, fresh.frame().ghosts, atol=1e-12)
    assert np.all(back.guides.v == 0.0)
