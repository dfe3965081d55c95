"""Equation (1) assignment (pruned kernel vs brute force) and arc-length node correspondence."""
import numpy as np
import pytest

from hair_tracking.ghosts.correspondence import (assign_guides, equation1_kernel, nearest_roots,
                                                 node_correspondence)


def random_strands(rng, count, nodes, spread=0.1, seg=0.015):
    roots = rng.normal(scale=spread, size=(count, 1, 3))
    steps = rng.normal(scale=0.5, size=(count, nodes - 1, 3)) + np.array([0.0, 0.0, -1.0])
    steps *= seg / np.linalg.norm(steps, axis=2, keepdims=True)
    return np.concatenate([roots, roots + np.cumsum(steps, axis=1)], axis=1)


def equation1_reference(ghosts, guides):
    """Cost matrix (S, G) of equation (1) by brute force (numpy broadcasting)."""
    d2 = ((ghosts[:, None, :, None, :] - guides[None, :, None, :, :]) ** 2).sum(axis=-1)
    return d2.min(axis=3).sum(axis=2)


def knn_reference(queries, points, k):
    d2 = ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    idx = np.broadcast_to(np.arange(points.shape[0]), d2.shape)
    order = np.lexsort((idx, d2), axis=1)            # by distance, then index
    return order[:, :k]


# ------------------------------------------------------------------ nearest roots
@pytest.mark.parametrize('k', [1, 3, 8, 40])
def test_grid_knn_equals_brute_force(k):
    rng = np.random.default_rng(k)
    # roots on a sphere cap (like a scalp), with duplicates, queries also off the surface
    u = rng.normal(size=(600, 3))
    u[:, 2] = np.abs(u[:, 2])
    points = 0.1 * u / np.linalg.norm(u, axis=1, keepdims=True)
    points[500:520] = points[100]                    # exact ties: broken by lower index
    near = points[rng.choice(600, 300)] + rng.normal(scale=0.004, size=(300, 3))
    far = rng.normal(scale=0.3, size=(100, 3))         # far away, outside the grid
    queries = np.concatenate([near, far, points[95:105]])
    got = nearest_roots(queries, points, k)
    np.testing.assert_array_equal(got, knn_reference(queries, points, min(k, 600)))


def test_knn_with_degenerate_point_sets():
    pts = np.zeros((5, 3))                            # all at one point
    q = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]])
    np.testing.assert_array_equal(nearest_roots(q, pts, 3), [[0, 1, 2], [0, 1, 2]])
    line = np.stack([np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)], axis=1)
    q = np.array([[0.5, 0.3, 0.0], [-1.0, 0.0, 0.0], [3.0, 0.0, 1.0]])
    np.testing.assert_array_equal(nearest_roots(q, line, 4), knn_reference(q, line, 4))
    with pytest.raises(ValueError, match='candidates'):
        nearest_roots(q, line, 0)
    with pytest.raises(ValueError, match='at least one guide'):
        nearest_roots(q, np.zeros((0, 3)), 2)
    with pytest.raises(ValueError, match='NaN'):
        nearest_roots(np.full((1, 3), np.nan), line, 2)


# ------------------------------------------------------------------ equation (1)
def test_equation1_kernel_matches_numpy_on_random_candidates():
    rng = np.random.default_rng(0)
    guides = random_strands(rng, 30, 7)
    ghosts = random_strands(rng, 80, 11)
    cand = np.stack([rng.choice(30, 6, replace=False) for _ in range(80)]).astype(np.int64)
    guide_of = np.empty(80, dtype=np.int64)
    cost = np.empty(80)
    equation1_kernel(ghosts, guides, cand, guide_of, cost)
    full = equation1_reference(ghosts, guides)
    sub = np.take_along_axis(full, cand, axis=1)
    want = cand[np.arange(80), sub.argmin(axis=1)]
    np.testing.assert_array_equal(guide_of, want)
    np.testing.assert_allclose(cost, sub.min(axis=1), rtol=1e-12)


def test_pruned_assignment_equals_brute_force_when_all_guides_are_candidates():
    rng = np.random.default_rng(1)
    guides = random_strands(rng, 25, 9)
    ghosts = random_strands(rng, 120, 6)
    guide_of, cost = assign_guides(ghosts, guides, candidates=25)
    full = equation1_reference(ghosts, guides)
    np.testing.assert_array_equal(guide_of, full.argmin(axis=1))
    np.testing.assert_allclose(cost, full.min(axis=1), rtol=1e-12)
    # with fewer candidates the cost can only be higher or equal, never lower
    pruned, pruned_cost = assign_guides(ghosts, guides, candidates=3)
    assert np.all(pruned_cost >= cost - 1e-15)
    assert np.mean(pruned == guide_of) > 0.5


def test_obvious_guide_is_chosen():
    z = -np.linspace(0.0, 0.2, 8)
    guides = np.array([np.stack([np.full(8, x0), np.zeros(8), z], axis=1)
                       for x0 in (0.0, 0.02, 0.04, 0.06)])
    ghosts = guides[[2, 0, 3, 1]] + np.array([0.004, 0.003, 0.0])
    guide_of, cost = assign_guides(ghosts, guides, candidates=2)
    np.testing.assert_array_equal(guide_of, [2, 0, 3, 1])
    np.testing.assert_allclose(cost, 8 * (0.004 ** 2 + 0.003 ** 2), rtol=1e-12)


def test_shape_beats_root_distance():
    """Equation (1) compares whole strands: a ghost whose root is nearest to guide A but that
    runs along guide B is assigned to B (when B is among the candidates)."""
    s = np.linspace(0.0, 0.2, 10)
    guide_a = np.stack([np.zeros(10), np.zeros(10), -s], axis=1)           # straight down
    guide_b = np.stack([0.004 + s, np.zeros(10), -0.2 * s], axis=1)        # sideways
    ghost = guide_b + np.array([-0.003, 0.001, 0.0])                      # root nearer to A
    assert np.linalg.norm(ghost[0] - guide_a[0]) < np.linalg.norm(ghost[0] - guide_b[0])
    guides = np.array([guide_a, guide_b])
    assert assign_guides(ghost[None], guides, candidates=2)[0].tolist() == [1]
    assert assign_guides(ghost[None], guides, candidates=1)[0].tolist() == [0]   # pruned


def test_assignment_rejects_bad_input():
    good = np.zeros((2, 4, 3))
    with pytest.raises(ValueError, match='ghost rest'):
        assign_guides(np.zeros((2, 4)), good, 2)
    with pytest.raises(ValueError, match='at least one guide'):
        assign_guides(good, np.zeros((0, 4, 3)), 2)
    bad = good.copy()
    bad[0, 1, 1] = np.inf
    with pytest.raises(ValueError, match='NaN or infinite'):
        assign_guides(good, bad, 2)


# ------------------------------------------------------------------ node correspondence
def lengths(counts, total=1.0):
    return np.full((1, counts - 1), total / (counts - 1))


def test_equal_node_counts_map_node_to_node():
    seg, t = node_correspondence(lengths(16, 0.23), lengths(16, 0.27), np.array([0]))
    np.testing.assert_array_equal(seg[0], list(range(15)) + [14])
    np.testing.assert_array_equal(t[0], [0.0] * 15 + [1.0])


def test_differing_node_counts_map_by_arc_length():
    # 4 ghost nodes on a 7-node guide: ghost node j sits on guide node 2 j
    seg, t = node_correspondence(lengths(4), lengths(7), np.array([0]))
    np.testing.assert_array_equal(seg[0], [0, 2, 4, 5])
    np.testing.assert_array_equal(t[0], [0.0, 0.0, 0.0, 1.0])
    # 5 ghost nodes on a 3-node guide: odd ghost nodes fall halfway along a guide segment
    seg, t = node_correspondence(lengths(5), lengths(3), np.array([0]))
    np.testing.assert_array_equal(seg[0], [0, 0, 1, 1, 1])
    np.testing.assert_allclose(t[0], [0.0, 0.5, 0.0, 0.5, 1.0])


def test_uneven_segments_match_arc_length_fractions():
    rng = np.random.default_rng(4)
    ghost_len = rng.uniform(0.005, 0.03, size=(20, 12))
    guide_len = rng.uniform(0.0, 0.03, size=(3, 6))
    guide_len[1, 2] = 0.0                             # a zero-length guide segment
    ghost_len[5] = 0.0                                # a zero-length ghost: even fractions
    guide_of = rng.integers(0, 3, size=20)
    seg, t = node_correspondence(ghost_len, guide_len, guide_of)
    assert seg.min() >= 0 and seg.max() <= 5 and t.min() >= 0 and t.max() <= 1
    gcum = np.concatenate([np.zeros((3, 1)), np.cumsum(guide_len, axis=1)], axis=1)
    gtot = gcum[:, -1]
    point_arc = (gcum[guide_of[:, None], seg] + t * guide_len[guide_of[:, None], seg])
    frac = point_arc / gtot[guide_of][:, None]
    cum = np.concatenate([np.zeros((20, 1)), np.cumsum(ghost_len, axis=1)], axis=1)
    with np.errstate(invalid='ignore'):
        want = cum / cum[:, -1:]
    want[5] = np.linspace(0, 1, 13)
    np.testing.assert_allclose(frac, want, atol=1e-12)
    with pytest.raises(ValueError, match='guide_of'):
        node_correspondence(ghost_len, guide_len, np.full(20, 3))
