"""The blend tracker (hair_tracking.ghosts.blend): the compiled kernels against the plain-numpy
reference, guides chosen among the strands, and the simulator running it once per frame (1:1
and rigid motion: test_stateless)."""
import numpy as np
import pytest

from hair_tracking.core.model import StrandSet
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.core.transforms import quat_from_axis_angle
from hair_tracking.ghosts import blend, stateless
from hair_tracking.simulator import HairSimulator
from test_stateless import head, scene


def small_scene(**changes):
    return scene('blend', **changes)


def test_choose_guides_spreads_them_deterministically():
    rng = np.random.default_rng(1)
    roots = rng.normal(size=(200, 3))
    a = stateless.choose_guides(roots, 20)
    assert np.array_equal(a, stateless.choose_guides(roots, 20)) and len(set(a.tolist())) == 20
    assert np.array_equal(stateless.choose_guides(roots, 200), np.arange(200))
    # farthest-point sampling: every strand is closer to some guide than a random pick allows
    d = np.sqrt(((roots[:, None] - roots[a][None]) ** 2).sum(-1)).min(1).max()
    r = np.sqrt(((roots[:, None] - roots[:20][None]) ** 2).sum(-1)).min(1).max()
    assert d < r
    with pytest.raises(ValueError, match='need 1..200 guides'):
        stateless.choose_guides(roots, 0)


def test_weights_are_shepard_and_a_guide_follows_only_itself():
    roots = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.25, 0.0, 0.0], [0.0, 2.0, 0.0]])
    guides = roots[:2]
    g, w = blend.blend_weights(roots, guides, k=2)
    assert g.dtype == np.int32 and w.dtype == np.float32
    assert g[0].tolist() == [0, 1] and w[0].tolist() == [1.0, 0.0]
    assert g[1].tolist() == [1, 0] and w[1].tolist() == [1.0, 0.0]
    # 1/d^2 weights: d = 0.25 and 0.75 -> 16 and 16/9 -> 0.9 and 0.1
    np.testing.assert_allclose(w[2], [0.9, 0.1], rtol=1e-6)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=1e-6)


def test_weights_are_computed_in_chunks_of_strands_with_the_same_result(monkeypatch):
    rng = np.random.default_rng(4)
    roots = rng.normal(size=(300, 3))
    guides = roots[rng.choice(300, 40, replace=False)]
    whole = blend.blend_weights(roots, guides, k=3)
    monkeypatch.setattr(blend, 'WEIGHT_CHUNK', 40 * 7)         # 7 strands at a time
    chunked = blend.blend_weights(roots, guides, k=3)
    assert np.array_equal(whole[0], chunked[0]) and np.array_equal(whole[1], chunked[1])
    # against the distances written out in full
    d = np.sqrt(((roots[:, None] - guides[None]) ** 2).sum(-1))
    np.testing.assert_array_equal(chunked[0], np.argsort(d, axis=1, kind='stable')[:, :3])


def test_nearest_guides_break_ties_to_the_lower_index_as_a_stable_sort():
    rng = np.random.default_rng(6)
    d2 = rng.integers(0, 6, size=(400, 30)).astype(float)        # many ties
    for k in (1, 3, 5, 30):
        np.testing.assert_array_equal(blend._nearest(d2, k),
                                      np.argsort(d2, axis=1, kind='stable')[:, :k])


def test_node_map_is_node_to_node_for_equal_counts():
    seg, t = stateless.node_map(16, 16)
    assert seg.tolist() == list(range(15)) + [14] and t.tolist() == [0.0] * 15 + [1.0]
    seg, t = stateless.node_map(3, 5)
    assert seg.tolist() == [0, 2, 3] and np.allclose(t, [0.0, 0.0, 1.0])


def model(tr):
    """The blend tracker's kernel model with its fields named."""
    return blend.BlendModel(*tr.model)


def _random_case(seed, guides=7, nodes=12, guide_nodes=12, k=3):
    rng = np.random.default_rng(seed)
    sim = HairSimulator(small_scene(groom__guides=guides, groom__ghosts_per_guide=5,
                                    groom__ghost_nodes=nodes, groom__guide_nodes=guide_nodes,
                                    tracking__blend_guides=k))
    tr = sim.ghost_tracker
    h = head()
    gx = h.to_world(sim.guides.rest) + rng.normal(scale=0.01, size=sim.guides.rest.shape)
    gx[:, :2] = h.to_world(sim.guides.rest[:, :2])
    return sim, tr, h, gx


def _kernel(sim, tr, h, gx, restore=True, collide=True):
    rot, pos = np.ascontiguousarray(h.rotation), np.ascontiguousarray(h.position)
    gcol = np.empty((gx.shape[0], 3, tr.seg.shape[0]))
    stateless.guide_columns(gx, tr.seg, tr.t, gcol)
    out = np.empty_like(sim.ghosts.rest)        # float64 records of stride 3: x as computed
    axes = tr.axes if collide else np.ones(3)
    contacts, finite = blend.blend_strands(
        tuple(stateless.Placement(out, np.eye(3), np.zeros(3), False, True)), tr.model,
        tuple(stateless.GuidePose(gcol, rot, pos)),
        tuple(blend.BlendParams(restore, collide, tr.center, axes)))
    assert finite == bool(np.isfinite(out).all())
    return out, contacts


@pytest.mark.parametrize('restore,collide', [(True, True), (False, False), (True, False),
                                             (False, True)])
def test_kernel_matches_the_numpy_reference(restore, collide):
    sim, tr, h, gx = _random_case(3)
    out, contacts = _kernel(sim, tr, h, gx, restore, collide)
    ref = blend.reference_blend(gx, sim.guides.rest, sim.ghosts.rest, model(tr).rest_length,
                                tr.guide_of, tr.weight, h, restore, tr.axes if collide else None,
                                tr.center, tr.is_guide, model(tr).guide_length)
    assert (tr.is_guide >= 0).sum() == gx.shape[0]
    # the kernel keeps the rest offsets in float32 (a few cm, so ~1e-9 m)
    np.testing.assert_allclose(out, ref, atol=1e-8)
    if not collide:
        assert contacts == 0


@pytest.mark.parametrize('k', [1, 2, 4, 7])
def test_any_number_of_guides_a_ghost_matches_the_reference(k):
    sim, tr, h, gx = _random_case(7, k=k)
    assert tr.guide_of.shape[1] == k
    # padded to whole groups of three, but one guide runs its own pass (the follow-hair case)
    assert model(tr).guide.shape[1] == (1 if k == 1 else -(-k // blend.GUIDE_GROUP) *
                                        blend.GUIDE_GROUP)
    out, _ = _kernel(sim, tr, h, gx)
    ref = blend.reference_blend(gx, sim.guides.rest, sim.ghosts.rest, model(tr).rest_length,
                                tr.guide_of, tr.weight, h, True, tr.axes, tr.center, tr.is_guide,
                                model(tr).guide_length)
    np.testing.assert_allclose(out, ref, atol=1e-7)


def test_every_lane_of_a_block_is_placed_and_guides_keep_their_points_or_lengths():
    # 35 strands: four full blocks of 8 and a partial one, guides among them
    sim, tr, h, gx = _random_case(5)
    out, _ = _kernel(sim, tr, h, gx)
    assert np.isfinite(out).all()
    # every strand, guides included (their points here are noisy), at its rest lengths
    seg = np.linalg.norm(np.diff(out, axis=1), axis=2)
    np.testing.assert_allclose(seg[:, 1:], model(tr).rest_length[:, 1:], rtol=1e-6)
    # without the length pass and contacts a guide strand is its guide, exactly
    raw, _ = _kernel(sim, tr, h, gx, restore=False, collide=False)
    for s, g in enumerate(tr.is_guide):
        if g >= 0:
            np.testing.assert_array_equal(raw[s], gx[g])


def test_nodes_pushed_into_the_head_slide_along_it():
    sim, tr, h, gx = _random_case(6)
    # every guide swung through the head: the blend would put ghosts inside it
    center = h.to_world(tr.center[None])[0]
    gx = center + 0.3 * (gx - center)
    gx[:, :2] = h.to_world(sim.guides.rest[:, :2])
    out, contacts = _kernel(sim, tr, h, gx)
    ref = blend.reference_blend(gx, sim.guides.rest, sim.ghosts.rest, model(tr).rest_length,
                                tr.guide_of, tr.weight, h, True, tr.axes, tr.center, tr.is_guide,
                                model(tr).guide_length)
    assert contacts > 0
    # the float32 offsets' rounding, turned by the slide's geometry
    np.testing.assert_allclose(out, ref, atol=1e-7)
    free = tr.is_guide < 0
    inside = ((h.to_head(out[free][:, 2:]) - tr.center) / tr.axes) ** 2
    assert inside.sum(axis=-1).min() >= 1.0 - 1e-9


def test_different_node_counts_match_the_reference():
    sim, tr, h, gx = _random_case(4, nodes=9, guide_nodes=17)
    # the blend's guides are ghost strands, so their node count is the ghosts' own
    assert sim.guides.rest.shape[1] == 9
    out, _ = _kernel(sim, tr, h, gx, True, False)
    ref = blend.reference_blend(gx, sim.guides.rest, sim.ghosts.rest, model(tr).rest_length,
                                tr.guide_of, tr.weight, h, True, is_guide=tr.is_guide,
                                guide_length=model(tr).guide_length)
    np.testing.assert_allclose(out, ref, atol=1e-8)


def test_guides_at_other_node_counts_are_read_at_the_node_fractions():
    rng = np.random.default_rng(2)
    gx = rng.normal(size=(3, 7, 3))
    seg, t = stateless.node_map(13, 7)
    out = np.empty((3, 3, 13))
    stateless.guide_columns(gx, seg, t, out)
    np.testing.assert_allclose(out.transpose(0, 2, 1), stateless.at_fractions(gx, seg, t))
    np.testing.assert_array_equal(out.transpose(0, 2, 1)[:, ::2], gx)
    same = np.empty((3, 3, 7))
    stateless.guide_columns(gx, *stateless.node_map(7, 7), same)
    np.testing.assert_array_equal(same.transpose(0, 2, 1), gx)
    assert stateless.at_fractions(gx, *stateless.node_map(7, 7)) is gx


def test_the_blend_runs_when_the_hair_is_read_from_the_guides_of_its_step():
    sim, eager = (HairSimulator(small_scene(groom__guides=8, groom__ghosts_per_guide=8))
                  for _ in range(2))
    tr = sim.ghost_tracker
    evaluated = tr.stats['evaluations']
    assert evaluated <= 1                                 # the settling step at most
    t0 = 1_000_000_000
    for k in range(8):
        t = t0 + k * 8_333_333
        q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 0.2 * k)
        for s in (sim, eager):
            s.push_pose(t, [0.01 * k, 0.0, 0.0], q)
            s.advance_to(t)
        eager.ghost_tracker.positions()                   # read after every pose
        if k == 3:
            assert tr.stats['steps'] == 3 and tr.stats['evaluations'] == evaluated
            first = sim.frame().ghosts
            assert tr.stats['evaluations'] == evaluated + 1   # one blend for the frame
            sim.frame()
            sim.max_stretch()
            assert tr.stats['evaluations'] == evaluated + 1   # the same hair: not again
    # a step takes the guides and head of its own time: moving the guides later changes nothing
    want = eager.frame().ghosts
    saved = sim.guides.x.copy()
    sim.guides.x[...] += 0.5
    np.testing.assert_array_equal(sim.frame().ghosts, want)
    assert not np.array_equal(first, want)
    sim.guides.x[...] = saved
    # a pose reset carries the hair of the last step rigidly, as an evaluated one would be
    for s in (sim, eager):
        s.push_pose(t + 8_333_333, [0.07, 0.0, 0.0], q)
        s.advance_to(t + 8_333_333)
    eager.ghost_tracker.positions()
    for s in (sim, eager):
        assert s.push_pose(t + 60_000_000_000, [1.0, 0.0, 0.0], q).is_reset
    np.testing.assert_allclose(sim.frame().ghosts, eager.frame().ghosts, atol=1e-12)


def test_the_mode_is_validated_and_a_change_rebuilds():
    with pytest.raises(SceneError, match='tracking.mode'):
        Scene().with_changes(tracking__mode='skin')
    sim = HairSimulator(small_scene(tracking__mode='paper'))
    assert sim.guide_index is None
    assert sim.update_scene(small_scene()) is True
    assert isinstance(sim.ghost_tracker, blend.BlendTracker)


def test_guides_must_be_ghost_strands():
    sim = HairSimulator(small_scene())
    other = StrandSet.from_rest(sim.ghosts.rest[:3] + 0.01)
    with pytest.raises(ValueError, match='must be some of the ghost strands'):
        blend.BlendTracker(sim.ghosts, other, np.arange(3), sim.scene)


def test_stretching_guides_are_shown_at_their_rest_lengths():
    sim = HairSimulator(small_scene(solver__type='pbd', solver__iterations=1,
                                    groom__guides=8, groom__ghosts_per_guide=4,
                                    tracking__collide=False))
    t0 = 1_000_000_000
    for k in range(20):
        q = quat_from_axis_angle(np.array([0.0, 0.0, 1.0]), 1.5 * np.sin(0.6 * k))
        sim.push_pose(t0 + k * 16_666_667, [0.05 * np.sin(k), 0.0, 0.0], q)
        sim.advance_to(t0 + k * 16_666_667)
    guide_len = np.linalg.norm(np.diff(sim.guides.x, axis=1), axis=2)
    assert np.abs(guide_len / sim.guides.rest_length - 1).max() > 1e-3     # PBD stretches
    ghost_len = np.linalg.norm(np.diff(sim.frame().ghosts, axis=1), axis=2)
    np.testing.assert_allclose(ghost_len, sim.ghosts.rest_length, rtol=2e-6)
