"""What the blend and the turn tracker share (hair_tracking.ghosts.stateless): guides chosen
among the strands, so one guide per strand is full simulation, and a head that carries the guides
rigidly carries every ghost rigidly."""
import numpy as np
import pytest

from hair_tracking.core.model import HeadPose
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from hair_tracking.ghosts import blend, turn
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.simulator import HairSimulator

#: Both trackers place the ghosts in float32: near 1.6 m from the origin half an ulp is 6e-8 m.
F32 = 2e-7
#: tracking.mode -> (its tracker, how close 1:1 is to full simulation [m], how close a rigidly
#: carried ghost is to its carried rest shape [m]): the blend copies a guide strand; the turn
#: rebuilds it from float32 rest segments; both keep their rest data and positions in float32
TRACKERS = {'blend': (blend.BlendTracker, F32, F32), 'turn': (turn.TurnTracker, F32, F32)}


def head(angle=0.4, axis=(0.2, 0.3, 1.0), position=(0.05, -0.02, 1.6)):
    """A head pose turned by ``angle`` about ``axis``, at ``position``."""
    q = quat_from_axis_angle(np.asarray(axis) / np.linalg.norm(axis), angle)
    return HeadPose(np.asarray(position, dtype=float), q, quat_to_matrix(q))


def scene(mode, **changes):
    """The default scene with a small groom, tracker ``mode``, no settling, ``changes``."""
    base = {'groom__guides': 6, 'groom__ghosts_per_guide': 4, 'tracking__mode': mode,
            'solver__settle_time': 0.0}
    base.update(changes)
    return Scene().with_changes(**base)


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_guides_carried_rigidly_carry_every_ghost_rigidly(mode):
    sim = HairSimulator(scene(mode, tracking__collide=False))
    assert isinstance(sim.ghost_tracker, TRACKERS[mode][0])
    h = head(angle=1.1)
    sim.guides.x[...] = h.to_world(sim.guides.rest)
    sim.ghost_tracker.step(TrackStep(1 / 60, 1, sim.guides.x, sim.guides.x, h))
    np.testing.assert_allclose(sim.ghost_tracker.positions(), h.to_world(sim.ghosts.rest),
                               rtol=0, atol=TRACKERS[mode][2])


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_one_guide_per_strand_is_full_simulation(mode):
    sim = HairSimulator(scene(mode, groom__ghosts_per_guide=1, groom__guides=12))
    assert np.array_equal(sim.guide_index, np.arange(12))
    t0 = 1_000_000_000
    for k in range(12):
        q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.3 * np.sin(0.5 * k))
        sim.push_pose(t0 + k * 16_666_667, [0.02 * k, 0.0, 0.0], q)
        sim.advance_to(t0 + k * 16_666_667)
    f = sim.frame()
    # FTL guides keep exact lengths: every strand is its guide, and no contact of its own moves
    # it (the guide solver placed it)
    np.testing.assert_allclose(f.ghosts, f.guides, rtol=0, atol=TRACKERS[mode][1])
    assert sim.ghost_tracker.stats['contacts'] == 0


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_the_simulator_runs_it_once_per_frame_at_rest_lengths_outside_the_head(mode):
    sim = _moved(mode, poses=30)
    assert isinstance(sim.ghost_tracker, TRACKERS[mode][0])
    assert sim.guides.count == 8 and sim.ghosts.count == 64
    np.testing.assert_array_equal(sim.guides.rest, sim.ghosts.rest[sim.guide_index])
    assert sim.ghost_tracker.stats['steps'] == 29        # once per advance_to call
    f = sim.frame()
    assert np.all(np.isfinite(f.ghosts))
    seg = np.linalg.norm(np.diff(f.ghosts, axis=1), axis=2)
    stretch = np.abs(seg / sim.ghosts.rest_length - 1.0)
    assert stretch.max() < 0.01                # nodes pressed onto the head: within 1 %
    assert np.median(stretch) < 2e-5           # every other segment exact to float32 rounding
    assert sim.penetration() < 1e-6            # on the surface to rounding
    np.testing.assert_allclose(f.ghosts[:, :2], f.head.to_world(sim.ghosts.rest[:, :2]),
                               atol=F32)       # roots pinned


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_the_first_pose_places_the_ghosts_before_any_step(mode):
    """Without settling the first pose carries the hair rigidly and no step follows: what is
    read (positions, frame, cloud) is that carried rest shape, not the one at build time."""
    sim = HairSimulator(scene(mode))
    h = head(angle=0.8, position=(0.3, 0.1, 1.2))
    sim.push_pose(1000, h.position, h.quaternion)
    sim.advance_to(1000)
    want = h.to_world(sim.ghosts.rest)
    np.testing.assert_allclose(sim.ghost_tracker.positions(), want, rtol=0, atol=F32)
    np.testing.assert_allclose(sim.frame(copy=False).strands, want, rtol=0, atol=F32)


def _moved(mode, poses=20, **changes):
    """A simulator of ``mode`` (8 guides x 8 strands) after ``poses`` head poses (guides bent,
    nodes pressed on the head), its last step not read yet."""
    sim = HairSimulator(scene(mode, groom__guides=8, groom__ghosts_per_guide=8, **changes))
    t0 = 1_000_000_000
    for k in range(poses):
        q = quat_from_axis_angle(np.array([0.0, 0.3, 1.0]) / np.hypot(0.3, 1.0),
                                 0.6 * np.sin(0.4 * k))
        sim.push_pose(t0 + k * 16_666_667, [0.03 * np.sin(0.3 * k), 0.0, 0.0], q)
        sim.advance_to(t0 + k * 16_666_667)
    return sim


def _records(sim, head_frame, stride=5):
    """The ghosts' point records as the node writes them (fill words kept), and is_dense."""
    n_strands, n_points, write = sim.record_writer(False, head_frame)
    words = np.full(n_strands * n_points * stride, 7.0, dtype=np.float32)
    dense = write(words, stride)
    return words.reshape(-1, stride), dense


@pytest.mark.parametrize('head_frame', [False, True])
@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_a_cloud_written_before_any_read_is_the_one_written_from_the_positions(mode, head_frame):
    """The kernel writes the records itself when nothing has read the step yet: the points are
    those written from the placed positions (in the world frame bit for bit), and the positions
    are placed from the same step when read afterwards."""
    fused, after = _moved(mode), _moved(mode)
    placed = fused.ghost_tracker.stats['evaluations']
    assert after.ghost_tracker.stats['evaluations'] == placed
    words, dense = _records(fused, head_frame)
    assert dense and fused.ghost_tracker.stats['evaluations'] == placed + 1   # the records
    after.ghost_tracker.positions()
    assert after.ghost_tracker.stats['evaluations'] == placed + 1             # the positions
    want, want_dense = _records(after, head_frame)
    assert after.ghost_tracker.stats['evaluations'] == placed + 1   # from the positions
    assert want_dense
    if head_frame:      # carried to the head frame before its one rounding to float32
        np.testing.assert_allclose(words[:, :3], want[:, :3], rtol=0, atol=F32)
    else:
        np.testing.assert_array_equal(words[:, :3], want[:, :3])
    assert (words[:, 3:] == 7.0).all()                   # the other words untouched
    np.testing.assert_array_equal(fused.ghost_tracker.positions(),
                                  after.ghost_tracker.positions())
    # the records were written without placing the positions: the read placed them
    assert fused.ghost_tracker.stats['evaluations'] == placed + 2
    assert fused.ghost_tracker.stats['contacts'] == after.ghost_tracker.stats['contacts'] > 0


@pytest.mark.parametrize('mode', sorted(TRACKERS))
def test_a_cloud_written_from_guides_that_are_not_finite_is_not_dense(mode):
    sim = _moved(mode, tracking__collide=False)
    sim.guides.x[3, 5:] = np.nan
    sim.ghost_tracker.step(TrackStep(1 / 60, 1, sim.guides.x, sim.guides.x, sim.head))
    words, dense = _records(sim, False)
    assert not dense and np.isnan(words[:, :3]).any()
    assert np.isfinite(words[:, :3]).any()
