"""Head-pose hygiene: normalisation, sign continuity, rejection, resets, interpolation."""
import math

import numpy as np
import pytest

from hair_tracking.core.head_track import HeadTrack, PoseResult, StreamClock
from hair_tracking.core.scene import HeadTrackSpec
from hair_tracking.core.transforms import quat_angle, quat_from_axis_angle, quat_to_matrix

MS = 1_000_000


def test_normalises_and_keeps_sign_continuity():
    tr = HeadTrack()
    q = quat_from_axis_angle([0, 0, 1], 0.3)
    assert tr.push(0, [0, 0, 0], 3.0 * q) is PoseResult.ACCEPTED
    assert np.isclose(np.linalg.norm(tr.latest().quaternion), 1.0)
    assert tr.push(10 * MS, [0, 0, 0], -q) is PoseResult.ACCEPTED
    assert tr.latest().quaternion @ q > 0.999          # stored as +q again


@pytest.mark.parametrize('p, q', [
    ([np.nan, 0, 0], [0, 0, 0, 1]),
    ([0, 0, 0], [0, 0, 0, 0]),
    ([0, 0, 0], [np.inf, 0, 0, 1]),
    ([0, 0], [0, 0, 0, 1]),
    ('abc', [0, 0, 0, 1]),
])
def test_rejects_bad_poses_with_count(p, q):
    tr = HeadTrack()
    tr.push(0, [0, 0, 0], [0, 0, 0, 1])
    assert tr.push(MS, p, q) is PoseResult.REJECTED
    assert tr.counters['rejected'] == 1
    assert tr.last_rejection
    assert tr.last_time == 0                         # nothing else changed


def test_slerp_interpolation_between_samples():
    tr = HeadTrack()
    q0 = quat_from_axis_angle([0, 0, 1], 0.0)
    q1 = quat_from_axis_angle([0, 0, 1], 1.0)
    tr.push(0, [0, 0, 0], q0)
    tr.push(100 * MS, [0.4, 0, 0], q1)
    mid = tr.sample(25 * MS)
    assert np.allclose(mid.position, [0.1, 0, 0])
    assert math.isclose(quat_angle(mid.quaternion, q0), 0.25, rel_tol=1e-9)
    assert np.allclose(mid.rotation, quat_to_matrix(mid.quaternion))
    # outside the samples the pose is held
    assert np.allclose(tr.sample(10_000 * MS).position, [0.4, 0, 0])
    assert np.allclose(tr.sample(-5).position, [0, 0, 0])


def test_time_backwards_and_teleports_reset():
    tr = HeadTrack(HeadTrackSpec(teleport_distance=0.5, teleport_angle_deg=90.0, max_gap=0.5))
    q = [0, 0, 0, 1]
    tr.push(100 * MS, [0, 0, 0], q)
    assert tr.push(50 * MS, [0, 0, 0], q) is PoseResult.RESET_BACKWARDS
    assert tr.push(60 * MS, [1.0, 0, 0], q) is PoseResult.RESET_TELEPORT
    assert tr.push(70 * MS, [1.0, 0, 0], quat_from_axis_angle([1, 0, 0], 2.0)) \
        is PoseResult.RESET_TELEPORT
    assert tr.push(2000 * MS, [1.0, 0, 0], quat_from_axis_angle([1, 0, 0], 2.0)) \
        is PoseResult.RESET_TELEPORT
    assert tr.push(2010 * MS, [1.01, 0, 0], quat_from_axis_angle([1, 0, 0], 2.01)) \
        is PoseResult.ACCEPTED
    assert tr.counters == {'accepted': 2, 'rejected': 0, 'reset_backwards': 1,
                           'reset_teleport': 3}
    assert tr.first_time == 2000 * MS                # history before the reset was dropped


def test_repeated_stamp_updates_sample():
    tr = HeadTrack()
    tr.push(0, [0, 0, 0], [0, 0, 0, 1])
    tr.push(0, [0.1, 0, 0], [0, 0, 0, 1])
    assert np.allclose(tr.latest().position, [0.1, 0, 0])


def test_sampled_orientation_is_the_slerp_of_its_neighbours():
    """The track's interpolation on Python floats agrees with transforms.slerp to rounding,
    for nearly equal, far apart and opposite-signed neighbours (shortest arc)."""
    from hair_tracking.core.transforms import slerp, slerp_floats
    rng = np.random.default_rng(3)
    for spread in (1e-4, 0.05, 1.0, 3.0):
        for _ in range(200):
            a = rng.normal(size=4)
            a /= np.linalg.norm(a)
            b = a + spread * rng.normal(size=4)
            b /= np.linalg.norm(b)
            if rng.random() < 0.5:
                b = -b
            u = rng.random()
            np.testing.assert_allclose(slerp_floats(tuple(a), tuple(b), u), slerp(a, b, u),
                                       rtol=0, atol=1e-14)


def test_stream_clock_maps_stamps_onto_the_simulator_time():
    """Stamps are the simulator's time, except after a stale stretch the hair settled past the
    newest stamp: the stream then continues one substep after the hair (the outputs are
    stamped back in the stream's time); time going back drops the offset."""
    clock = StreamClock()
    dt = 10
    assert clock.stamp(None) == 0
    assert clock.sim_time(1000, None, dt) == (1000, 0)
    clock.accept(1000, 0)
    assert clock.sim_time(1020, 1000, dt) == (1020, 0)      # a fresh pose: as stamped
    clock.accept(1020, 0)
    # the hair settled to 1500 while no pose came; the stream resumes at 1040
    sim_t, offset = clock.sim_time(1040, 1500, dt)
    assert (sim_t, offset) == (1510, 470)
    assert clock.offset_ns == 0                               # nothing kept before accept
    clock.accept(1040, offset)
    assert clock.stamp(1510) == 1040
    assert clock.sim_time(1060, 1510, dt) == (1530, 470)     # and keeps going from there
    clock.accept(1060, 470)
    assert clock.sim_time(500, 1530, dt) == (500, 0)         # backwards: the hair resets
