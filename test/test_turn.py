"""The turn tracker (hair_tracking.ghosts.turn): ghosts grouped by guide into blocks, the
compiled kernels against the plain-numpy reference, exact lengths, nodes kept out of the head,
and the simulator running it per frame (1:1 and rigid motion: test_stateless)."""
import numpy as np
import pytest

from hair_tracking.ghosts import stateless, turn
from hair_tracking.simulator import HairSimulator
from test_stateless import head, scene


def small_scene(**changes):
    return scene('turn', **changes)


def test_blocks_hold_each_guides_strands_and_only_theirs():
    guide_of = np.array([2, 0, 2, 2, 1, 0, 2, 2, 2, 2, 2, 2, 2])     # guide 2: 10 strands
    g, s = turn.group_blocks(guide_of, 4, lanes=4)
    assert g.tolist() == [0, 1, 2, 2, 2]                            # guide 3 has none
    assert s.tolist() == [[1, 5, -1, -1], [4, -1, -1, -1], [0, 2, 3, 6], [7, 8, 9, 10],
                          [11, 12, -1, -1]]
    for b in range(g.shape[0]):
        used = s[b][s[b] >= 0]
        assert (guide_of[used] == g[b]).all()
    assert sorted(s[s >= 0].tolist()) == list(range(13))


def test_block_rest_is_the_segments_and_roots_of_each_lane():
    rng = np.random.default_rng(0)
    rest = rng.normal(size=(5, 6, 3))
    strand = np.array([[3, 0, -1], [4, 1, 2]])
    seg, roots = turn.block_rest(rest, strand)
    assert seg.dtype == np.float32 and seg.shape == (2, 6 * 3 * 3)
    slab = seg.reshape(2, 6, 3, 3)
    np.testing.assert_allclose(slab[1, :5, :, 2], np.diff(rest[2], axis=0), rtol=1e-6)
    np.testing.assert_array_equal(slab[0, :, :, 2], 0.0)              # idle lane
    np.testing.assert_array_equal(roots[1, :, :, 0], rest[4, :2])
    assert (roots[0, :, 2, 2] == turn.IDLE_AT).all()


@pytest.mark.parametrize('a,b', [((0, 0, 1), (0, 1, 0)), ((1, 0, 0), (1, 0, 0)),
                                 ((0.6, 0.8, 0), (-0.6, -0.8, 0)), ((1, 0, 0), (-1, 0, 0)),
                                 ((0.3, -0.4, 0.866), (0.9, 0.1, -0.2))])
def test_turn_matrix_is_the_rotation_taking_a_to_b(a, b):
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    t = turn.turn_matrix(a, b)
    np.testing.assert_allclose(t @ a, b, atol=1e-12)
    np.testing.assert_allclose(t @ t.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(t) == pytest.approx(1.0)


def _random_case(seed, guides=7, nodes=12, guide_nodes=12, scale=0.01):
    rng = np.random.default_rng(seed)
    sim = HairSimulator(small_scene(groom__guides=guides, groom__ghosts_per_guide=5,
                                    groom__ghost_nodes=nodes, groom__guide_nodes=guide_nodes))
    tr = sim.ghost_tracker
    h = head()
    gx = h.to_world(sim.guides.rest) + rng.normal(scale=scale, size=sim.guides.rest.shape)
    gx[:, :2] = h.to_world(sim.guides.rest[:, :2])
    return sim, tr, h, gx


def _kernel(tr, h, gx, collide=True):
    rot, pos = np.ascontiguousarray(h.rotation), np.ascontiguousarray(h.position)
    gcol = np.empty((gx.shape[0], 3, tr.seg.shape[0]))
    stateless.guide_columns(gx, tr.seg, tr.t, gcol)
    turns = np.empty((gx.shape[0], 9, tr.seg.shape[0] - 1))
    out = np.full(tr.ghosts.rest.shape, np.nan)  # float64 records of stride 3: x as computed
    contacts, finite = turn.turn_strands(
        tuple(stateless.Placement(out, np.eye(3), np.zeros(3), False, True)), tr.model,
        tuple(stateless.GuidePose(gcol, rot, pos)),
        tuple(turn.TurnParams(collide, tr.center, tr.axes)), turns)
    assert finite == bool(np.isfinite(out).all())
    return out, contacts


@pytest.mark.parametrize('collide', [True, False])
def test_kernel_matches_the_numpy_reference_with_exact_lengths(collide):
    sim, tr, h, gx = _random_case(3)
    assert isinstance(tr, turn.TurnTracker) and (tr.block_strand < 0).any()   # idle lanes
    out, contacts = _kernel(tr, h, gx, collide)
    ref = turn.reference_turn(gx, sim.guides.rest, sim.ghosts.rest, tr.guide_of, h,
                              tr.axes if collide else None, tr.center, tr.guide_index)
    assert np.isfinite(out).all()                       # every strand of every block written
    # the kernel keeps the rest segments in float32 (about 1e-9 m)
    np.testing.assert_allclose(out, ref, atol=1e-8)
    seg = np.linalg.norm(np.diff(out, axis=1), axis=2)
    exact = np.abs(seg / sim.ghosts.rest_length - 1.0)
    assert np.median(exact) < 1e-6
    if not collide:
        assert contacts == 0 and exact.max() < 1e-6


def test_nodes_turned_into_the_head_slide_along_it():
    sim, tr, h, gx = _random_case(6)
    center = h.to_world(tr.center[None])[0]
    gx = center + 0.3 * (gx - center)                   # every guide pulled through the head
    gx[:, :2] = h.to_world(sim.guides.rest[:, :2])
    out, contacts = _kernel(tr, h, gx)
    ref = turn.reference_turn(gx, sim.guides.rest, sim.ghosts.rest, tr.guide_of, h,
                              tr.axes, tr.center, tr.guide_index)
    assert contacts > 0
    np.testing.assert_allclose(out, ref, atol=1e-7)
    free = np.ones(len(out), bool)
    free[tr.guide_index] = False
    inside = ((h.to_head(out[free][:, 2:]) - tr.center) / tr.axes) ** 2
    assert inside.sum(axis=-1).min() >= 1.0 - 1e-9


def test_half_turns_and_other_node_counts_match_the_reference():
    sim, tr, h, gx = _random_case(4, nodes=9, guide_nodes=17)
    assert sim.guides.rest.shape[1] == 9            # the guides are strands: the ghosts' count
    # one guide's segment reversed against its rest direction: a half turn
    g0 = h.to_world(sim.guides.rest[0])
    gx[0, 5:] = gx[0, 4] - (g0[5:] - g0[4])
    out, _ = _kernel(tr, h, gx, collide=False)
    ref = turn.reference_turn(gx, sim.guides.rest, sim.ghosts.rest, tr.guide_of, h)
    np.testing.assert_allclose(out, ref, atol=1e-8)
    # the guide strand is its guide's segment directions at its rest lengths
    d, want = np.diff(out[tr.guide_index[0]], axis=0), np.diff(gx[0], axis=0)
    cos = np.sum(d * want, axis=1) / np.linalg.norm(d, axis=1) / np.linalg.norm(want, axis=1)
    np.testing.assert_allclose(cos[1:], 1.0, atol=1e-12)
    assert np.dot(want[5] / np.linalg.norm(want[5]), g0[5] - g0[4]) < 0      # it did turn


def test_a_mode_change_rebuilds_and_guides_must_be_strands():
    sim = HairSimulator(small_scene(tracking__mode='blend'))
    assert sim.update_scene(small_scene()) is True
    assert isinstance(sim.ghost_tracker, turn.TurnTracker)
    other = sim.guides.__class__.from_rest(sim.ghosts.rest[:3] + 0.01)
    with pytest.raises(ValueError, match='must be some of the ghost strands'):
        turn.TurnTracker(sim.ghosts, other, np.arange(3), sim.scene)
