"""The fused ghost-tracking kernel and its helpers against plain-numpy references."""
import numpy as np
import pytest

from hair_tracking.core.model import HeadPose, StrandSet
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_normalize, quat_to_matrix, rotation_between
from hair_tracking.ghosts.interface import TrackStep
from hair_tracking.ghosts.kernels import GhostModel, guide_frames
from hair_tracking.ghosts.reference import ghost_step
from hair_tracking.ghosts.tracker import GhostTracker
from hair_tracking.ghosts.weights import (arc_fractions, clamp_weight, com_weight, ELASTIC_CHANGED,
                                          elastic_code, ELASTIC_KEPT, ELASTIC_OFF, elastic_weight,
                                          tip_weights)


# ------------------------------------------------------------------ helpers
def random_strands(rng, count, nodes, seg=0.02, spread=0.1, even=False):
    """Random-walk strands (count, nodes, 3) [m] hanging roughly along -z.  With ``even`` every
    segment is one of four steps of exactly the same length on a dyadic grid (no rounding), so
    that every ghost has the same arc-length layout and the kernel takes its shared-layout path
    (:func:`tracking_kernels._predict_group`)."""
    if even:
        roots = np.round(rng.normal(scale=spread, size=(count, 1, 3)) * 1024.0) / 1024.0
        a, b = 2.0 ** -7, 2.0 ** -6
        choices = np.array([[a, 0.0, -b], [-a, 0.0, -b], [0.0, a, -b], [0.0, -a, -b]])
        steps = choices[rng.integers(0, 4, size=(count, nodes - 1))]
        return np.concatenate([roots, roots + np.cumsum(steps, axis=1)], axis=1)
    roots = rng.normal(scale=spread, size=(count, 1, 3))
    steps = rng.normal(scale=0.3, size=(count, nodes - 1, 3)) + np.array([0.0, 0.0, -1.0])
    steps *= seg / np.linalg.norm(steps, axis=2, keepdims=True)
    steps *= rng.uniform(0.7, 1.3, size=(count, nodes - 1, 1))
    return np.concatenate([roots, roots + np.cumsum(steps, axis=1)], axis=1)


def head_pose(rng, angle_scale=0.3, shift=0.05):
    q = quat_normalize(np.concatenate([rng.normal(scale=angle_scale, size=3), [1.0]]))
    return HeadPose(rng.normal(scale=shift, size=3), q, quat_to_matrix(q))


def scene_with(**tracking):
    return Scene().with_changes(**{f'tracking__{k}': v for k, v in tracking.items()})


OPTION_SETS = [
    {},                                                           # defaults
    dict(elastic_mode='changed', spread=0.7, spread_target=2.0, com_weight=8.0, tip_weight=1.0,
         max_weight=1.2),
    dict(elastic_weight=False, tip_weight=0.0, com_weight=0.0, length_restore=False,
         com_strength=0.0, offset_strength=0.0),
    dict(length_restore=False, offset_strength=0.0, spread=0.5, spread_target=0.5),
    dict(com_strength=0.0, spread=0.0, offset_strength=0.3),      # no group-level stage
    dict(com_strength=1.0, offset_strength=1.0, max_weight=0.0),
]


@pytest.mark.parametrize('options', OPTION_SETS)
@pytest.mark.parametrize('regroup, even', [(True, False), (False, False), (True, True)])
def test_kernel_matches_numpy_reference(options, regroup, even):
    rng = np.random.default_rng(7)
    guides = StrandSet.from_rest(random_strands(rng, 4, 6))
    ghost_rest = random_strands(rng, 17, 9, seg=0.013, even=even)
    ghosts = StrandSet.from_rest(ghost_rest)
    scene = scene_with(**options)
    tracker = GhostTracker(ghosts, guides, scene, regroup=regroup)
    # both paths of the kernel: groups sharing one arc-length layout, and mixed groups
    shared = GhostModel(*tracker.model).group_row >= 0
    assert shared.all() if even else not shared.all()
    dt = 1.0 / 240.0
    head = head_pose(rng)
    guides.place_at(head)
    ghosts.place_at(head)
    ghosts.v[...] = rng.normal(scale=0.2, size=ghosts.v.shape)
    ghosts.x[...] += rng.normal(scale=0.003, size=ghosts.x.shape)
    tracker.set_state(ghosts.x, ghosts.v)
    for _ in range(4):
        old = guides.x.copy()
        head = head_pose(rng)
        guides.x[...] = head.to_world(guides.rest) + rng.normal(scale=0.004, size=old.shape)
        want_x, want_v = ghost_step(
            tracker.positions(), tracker.velocities(), ghosts.rest, ghosts.rest_length,
            tracker.guide_of, tracker.seg, tracker.t, guides.rest, guides.x, old, head, dt,
            scene.tracking)
        tracker.step(TrackStep(dt, 1, old, guides.x, head))
        np.testing.assert_allclose(tracker.positions(), want_x, rtol=0, atol=1e-11)
        np.testing.assert_allclose(tracker.velocities(), want_v, rtol=1e-9, atol=1e-8)
    assert tracker.stats['steps'] == 4


def _steps_match_reference(rng, tracker, guides, ghosts, scene, collider, steps):
    """``steps`` substeps of small random head and guide motion, each checked against
    :func:`reference_step` with the collider; returns the contacts counted."""
    dt = 1.0 / 240.0
    head = head_pose(rng, angle_scale=0.05, shift=0.005)
    guides.place_at(head)
    tracker.reset(head)
    contacts = 0
    for _ in range(steps):
        old = guides.x.copy()
        head = head_pose(rng, angle_scale=0.05, shift=0.005)
        guides.x[...] = head.to_world(guides.rest) + rng.normal(scale=0.004, size=old.shape)
        want_x, want_v = ghost_step(
            tracker.positions(), tracker.velocities(), ghosts.rest, ghosts.rest_length,
            tracker.guide_of, tracker.seg, tracker.t, guides.rest, guides.x, old, head, dt,
            scene.tracking, collider)
        tracker.step(TrackStep(dt, 1, old, guides.x, head))
        contacts += tracker.stats['contacts']
        np.testing.assert_allclose(tracker.positions(), want_x, rtol=0, atol=1e-10)
        np.testing.assert_allclose(tracker.velocities(), want_v, rtol=1e-8, atol=1e-7)
    return contacts


@pytest.mark.parametrize('shape', ['sphere', 'ellipsoid'])
@pytest.mark.parametrize('length_restore', [True, False])
def test_kernel_collision_matches_scalar_reference(shape, length_restore):
    """(h) inside the kernel (lane-parallel, all lanes of a group at once) against the scalar
    one-node functions applied node by node: a collider placed where the ghosts hang, so that
    many nodes are pushed each substep."""
    from hair_tracking.colliders.head import HeadCollider
    rng = np.random.default_rng(11)
    guides = StrandSet.from_rest(random_strands(rng, 4, 6))
    ghosts = StrandSet.from_rest(random_strands(rng, 37, 9, seg=0.013))
    scene = scene_with(collide=True, length_restore=length_restore)
    radii = (0.06,) * 3 if shape == 'sphere' else (0.06, 0.05, 0.07)
    collider = HeadCollider(shape, (0.0, 0.0, -0.09), radii, 0.004, 0.3)
    tracker = GhostTracker(ghosts, guides, scene, collider)
    assert _steps_match_reference(rng, tracker, guides, ghosts, scene, collider, 4) > 50


def test_guide_frames_match_rotation_between():
    rng = np.random.default_rng(3)
    rest = random_strands(rng, 5, 7)
    gx = random_strands(rng, 5, 7)
    gx[2, 3] = gx[2, 2]                           # degenerate current segment -> head rotation
    head = head_pose(rng, angle_scale=1.0)
    tan = np.diff(rest, axis=1)
    tan /= np.linalg.norm(tan, axis=2, keepdims=True)
    frames = guide_frames(gx, tan, head.rotation)
    for g in range(5):
        for s in range(6):
            b = gx[g, s + 1] - gx[g, s]
            if np.linalg.norm(b) == 0:
                want = head.rotation
            else:
                want = rotation_between(head.rotation @ tan[g, s], b / np.linalg.norm(b)) @ \
                    head.rotation
            np.testing.assert_allclose(frames[g, s], want, atol=1e-12)
            np.testing.assert_allclose(frames[g, s] @ frames[g, s].T, np.eye(3), atol=1e-12)
            if np.linalg.norm(b) > 0:     # the frame carries the rest tangent onto the tangent
                np.testing.assert_allclose(frames[g, s] @ tan[g, s], b / np.linalg.norm(b),
                                           atol=1e-12)


def test_guide_frame_half_turn_is_a_rotation():
    gx = np.array([[[0.0, 0, 0], [0, 0, 0.1]]])            # tangent reversed exactly
    tan = np.array([[[0.0, 0.0, -1.0]]])
    q = guide_frames(gx, tan, np.eye(3))[0, 0]
    np.testing.assert_allclose(q @ q.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(q) == pytest.approx(1.0)
    np.testing.assert_allclose(q @ tan[0, 0], [0, 0, 1], atol=1e-12)
    assert np.all(np.isfinite(q))


# ------------------------------------------------------------------ weights
def test_elastic_weight_both_readings():
    v = (1.0, 0.0, 0.0)
    cases = {(1.0, 0.0, 0.0): 1.0, (-2.0, 0.0, 0.0): 0.0, (0.0, 3.0, 0.0): 0.5,
             (0.0, 0.0, 0.0): 0.5}
    for v0, kept in cases.items():
        assert elastic_weight(*v, *v0, ELASTIC_KEPT) == pytest.approx(kept)
        assert elastic_weight(*v, *v0, ELASTIC_CHANGED) == pytest.approx(1.0 - kept)
        assert elastic_weight(*v, *v0, ELASTIC_OFF) == 0.0
    # equation (4) on random directions: 0.5 cos + 0.5, whatever the magnitudes
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        cos = a @ b / np.linalg.norm(a) / np.linalg.norm(b)
        assert elastic_weight(*(a * 7.0), *b, ELASTIC_KEPT) == pytest.approx(0.5 * cos + 0.5)
    assert elastic_weight(np.nan, 0.0, 0.0, 1.0, 0.0, 0.0, ELASTIC_KEPT) == 0.5


def test_elastic_code_and_small_weights():
    assert elastic_code(scene_with(elastic_weight=False).tracking) == ELASTIC_OFF
    assert elastic_code(scene_with(elastic_mode='kept').tracking) == ELASTIC_KEPT
    assert elastic_code(scene_with(elastic_mode='changed').tracking) == ELASTIC_CHANGED
    assert clamp_weight(2.5, 1.5) == 1.5
    assert clamp_weight(-1.0, 1.5) == 0.0
    assert clamp_weight(0.7, 1.5) == 0.7
    assert com_weight(0.01, 4.0, 0.3) == pytest.approx(0.012)


def test_tip_weights_follow_arc_length():
    lengths = np.array([[1.0, 1.0, 2.0], [0.0, 0.0, 0.0]])
    w = tip_weights(lengths, 0.8)
    np.testing.assert_allclose(w[0], [0.0, 0.2, 0.4, 0.8])
    np.testing.assert_allclose(w[1], [0.0, 0.8 / 3, 1.6 / 3, 0.8])   # zero length: even spacing
    with pytest.raises(ValueError, match='tip_weight'):
        tip_weights(lengths, -1.0)
    with pytest.raises(ValueError, match='rest_length'):
        arc_fractions(np.zeros(3))


def test_parallel_and_serial_kernels_agree():
    """Below PARALLEL_MIN_NODES the tracker calls the serial kernel; asking for the parallel one
    gives the same contacts and the same hair, with the fused collider on.  The two variants are
    separately compiled functions and the kernels may fuse multiply-adds
    (``core.kernels.FASTMATH``), so they agree to rounding, not necessarily bit for bit."""
    from hair_tracking.colliders.head import head_collider
    scene = scene_with(spread=0.5, spread_target=1.5)
    collider = head_collider(scene.collider)
    runs = []
    for parallel in (None, True):
        rng = np.random.default_rng(5)
        guides = StrandSet.from_rest(random_strands(rng, 6, 8) + [0.0, 0.0, 0.12])
        ghosts = StrandSet.from_rest(random_strands(rng, 70, 8, seg=0.015) + [0.0, 0.0, 0.12])
        tracker = GhostTracker(ghosts, guides, scene, collider, parallel=parallel)
        assert tracker.stats['parallel'] == (parallel is True)
        for _ in range(5):
            old = guides.x.copy()
            guides.x[:, 2:] += rng.normal(scale=0.01, size=guides.x[:, 2:].shape)
            tracker.step(TrackStep(1.0 / 240.0, 1, old, guides.x, head_pose(rng)))
        runs.append((tracker.positions().copy(), tracker.velocities().copy(),
                     tracker.stats['contacts']))
    assert runs[0][2] == runs[1][2] and runs[0][2] > 0
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0, atol=1e-9)      # x / dt


def test_blocks_of_groups_large_small_and_single():
    """Blocks pack consecutive groups up to BLOCK_LANES ghosts: a group larger than a block, a
    group of one ghost and a mid-sized one beside it, with the collider on, all agree with the
    plain-numpy reference."""
    from hair_tracking.ghosts.kernels import block_groups, BLOCK_LANES
    from hair_tracking.colliders.head import HeadCollider
    rng = np.random.default_rng(23)
    roots = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0]])[:, None]
    guide_rest = random_strands(rng, 3, 7, spread=0.0) + roots
    sizes = (BLOCK_LANES + 37, 1, 30)
    ghost_rest = np.concatenate([random_strands(rng, k, 7, seg=0.012, spread=0.005) +
                                 guide_rest[g, :1] for g, k in enumerate(sizes)])
    ghost_rest = ghost_rest[rng.permutation(ghost_rest.shape[0])]      # groups interleaved
    guides = StrandSet.from_rest(guide_rest)
    ghosts = StrandSet.from_rest(ghost_rest)
    scene = scene_with(collide=True, spread=0.3, spread_target=1.3)
    collider = HeadCollider('sphere', (0.0, 0.0, -0.08), (0.05,) * 3, 0.004, 0.3)
    tracker = GhostTracker(ghosts, guides, scene, collider)
    assert sorted(np.diff(tracker.group_start)) == sorted(sizes)
    blocks = block_groups(tracker.group_start)
    lanes = np.diff(tracker.group_start[blocks])
    assert lanes.max() == BLOCK_LANES + 37 and blocks.size - 1 == 2
    assert np.array_equal(block_groups(np.array([0])), [0, 0])            # no ghosts
    assert _steps_match_reference(rng, tracker, guides, ghosts, scene, collider, 3) > 20
