"""Groom generation: counts, scalp region, rest lengths, determinism."""
import numpy as np

from hair_tracking.core.groom import in_scalp, make_groom, scalp_order
from hair_tracking.core.scene import GroomSpec


def test_counts_shapes_and_lengths():
    spec = GroomSpec(guides=50, ghosts_per_guide=4, guide_nodes=10, ghost_nodes=13,
                     length=0.3, length_variation=0.2)
    g = make_groom(spec)
    assert g.guide_rest.shape == (50, 10, 3)
    assert g.ghost_rest.shape == (200, 13, 3)
    for rest in (g.guide_rest, g.ghost_rest):
        lengths = np.linalg.norm(np.diff(rest, axis=1), axis=2).sum(axis=1)
        assert lengths.min() >= 0.3 * 0.8 - 1e-9 and lengths.max() <= 0.3 * 1.2 + 1e-9
        seg = np.linalg.norm(np.diff(rest, axis=1), axis=2)
        assert np.allclose(seg, seg[:, :1])           # uniform segments per strand


def test_roots_on_scalp_and_outside_head():
    spec = GroomSpec(guides=200, ghosts_per_guide=2)
    g = make_groom(spec)
    radii = np.array(spec.scalp.radii)
    for rest in (g.guide_rest, g.ghost_rest):
        u = rest[:, 0] / radii
        assert np.allclose(np.linalg.norm(u, axis=1), 1.0)
        assert in_scalp(u / np.linalg.norm(u, axis=1, keepdims=True), spec.scalp).all()
        # no face hair: forward roots stay above the hairline
        un = u / np.linalg.norm(u, axis=1, keepdims=True)
        front = un[:, 0] / np.hypot(un[:, 0], un[:, 1]) > 0.95
        limit = spec.scalp.max_polar_deg - 0.95 * (spec.scalp.max_polar_deg
                                                   - spec.scalp.front_max_polar_deg)
        assert front.any()
        assert np.all(un[front, 2] >= np.cos(np.radians(limit)) - 1e-9)
        inner = np.linalg.norm(rest[:, 2:] / radii, axis=2)
        assert inner.min() >= 1.0


def test_guides_are_spread_evenly():
    g = make_groom(GroomSpec(guides=100, ghosts_per_guide=0))
    roots = g.guide_rest[:, 0]
    d = np.linalg.norm(roots[:, None] - roots[None], axis=2) + np.eye(100)
    nearest = d.min(axis=1)
    assert nearest.min() > 0.3 * nearest.mean()


def test_deterministic_by_seed():
    a = make_groom(GroomSpec(seed=3))
    b = make_groom(GroomSpec(seed=3))
    c = make_groom(GroomSpec(seed=4))
    assert np.array_equal(a.ghost_rest, b.ghost_rest)
    assert not np.array_equal(a.ghost_rest, c.ghost_rest)


def _morton_code(q):
    """The Z-order code of integer coordinates ``q`` (3,), one bit at a time."""
    return sum(((int(q[axis]) >> b) & 1) << (3 * b + axis) for b in range(21) for axis in range(3))


def test_scalp_order_sorts_along_the_z_order_curve():
    rng = np.random.default_rng(4)
    p = rng.normal(size=(300, 3))
    p[10] = p[20]                                    # a tie keeps its order
    order = scalp_order(p)
    assert sorted(order) == list(range(300))
    q = np.floor((p - p.min(0)) / (p.max(0) - p.min(0)) * ((1 << 21) - 1)).astype(np.int64)
    codes = [_morton_code(q[i]) for i in order]
    assert codes == sorted(codes)
    assert list(order).index(10) < list(order).index(20)
    assert scalp_order(np.zeros((0, 3))).shape == (0,)


def test_ghost_strands_are_stored_in_scalp_order():
    """Strands near on the scalp are near in memory: consecutive roots lie far closer together
    than the same roots in a random order."""
    g = make_groom(GroomSpec(guides=64, ghosts_per_guide=16))
    roots = g.ghost_rest[:, 0]
    np.testing.assert_array_equal(scalp_order(roots), np.arange(roots.shape[0]))
    step = np.linalg.norm(np.diff(roots, axis=0), axis=1).mean()
    shuffled = roots[np.random.default_rng(0).permutation(roots.shape[0])]
    assert step < 0.2 * np.linalg.norm(np.diff(shuffled, axis=0), axis=1).mean()
