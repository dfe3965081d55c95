"""Output curves: Bezier (equation (6)) and centripetal Catmull-Rom against numpy references."""
from math import comb

import numpy as np
import pytest

from hair_tracking.core.curves import bezier, bezier_stencil, catmull_rom, resample


def random_strands(rng, count, nodes):
    steps = rng.normal(size=(count, nodes - 1, 3)) * 0.01 + np.array([0.0, 0.0, -0.015])
    roots = rng.normal(scale=0.1, size=(count, 1, 3))
    return np.concatenate([roots, roots + np.cumsum(steps, axis=1)], axis=1)


def bezier_reference(x, points):
    """Equation (6) (and lower-degree tails) evaluated directly, span by span."""
    n = x.shape[1]
    spans, first = [], 0
    while first < n - 1:
        spans.append((first, min(3, n - 1 - first)))
        first += spans[-1][1]
    out = np.empty((x.shape[0], points, 3))
    for p in range(points):
        u = p * (n - 1) / (points - 1)
        c = min(int(u // 3), len(spans) - 1)
        first, deg = spans[c]
        t = (u - first) / deg
        ctrl = x[:, first:first + deg + 1]
        if deg == 3:      # equation (6), with the corrected coefficient 3
            out[:, p] = ((1 - t) ** 3 * ctrl[:, 0] + 3 * (1 - t) ** 2 * t * ctrl[:, 1] +
                         3 * (1 - t) * t ** 2 * ctrl[:, 2] + t ** 3 * ctrl[:, 3])
        else:
            out[:, p] = sum(comb(deg, i) * (1 - t) ** (deg - i) * t ** i * ctrl[:, i]
                            for i in range(deg + 1))
    return out


def catmull_rom_reference(x, points, alpha=0.5):
    """Centripetal Catmull-Rom in Hermite form (tangents from the non-uniform knots)."""
    s_count, n = x.shape[:2]
    ext = np.concatenate([2 * x[:, :1] - x[:, 1:2], x, 2 * x[:, -1:] - x[:, -2:-1]], axis=1)
    out = np.empty((s_count, points, 3))
    for p in range(points):
        u = p * (n - 1) / (points - 1)
        i = min(int(np.floor(u)), n - 2)
        s = u - i
        for k in range(s_count):
            p0, p1, p2, p3 = ext[k, i], ext[k, i + 1], ext[k, i + 2], ext[k, i + 3]
            d01, d12, d23 = (np.linalg.norm(b - a) ** alpha for a, b in
                             ((p0, p1), (p1, p2), (p2, p3)))
            m1 = (p1 - p0) / d01 - (p2 - p0) / (d01 + d12) + (p2 - p1) / d12
            m2 = (p2 - p1) / d12 - (p3 - p1) / (d12 + d23) + (p3 - p2) / d23
            m1, m2 = m1 * d12, m2 * d12
            h00, h10 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s
            h01, h11 = -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
            out[k, p] = h00 * p1 + h10 * m1 + h01 * p2 + h11 * m2
    return out


# ------------------------------------------------------------------ Bezier
@pytest.mark.parametrize('nodes', [2, 3, 4, 5, 6, 7, 10, 11, 12, 16])
def test_bezier_matches_reference(nodes):
    x = random_strands(np.random.default_rng(nodes), 6, nodes)
    for points in (2, 7, 23, nodes):
        np.testing.assert_allclose(bezier(x, points), bezier_reference(x, points), atol=1e-14)


@pytest.mark.parametrize('nodes', [10, 11, 12, 16])
def test_bezier_passes_through_group_end_nodes(nodes):
    x = random_strands(np.random.default_rng(1), 5, nodes)
    ends = list(range(0, nodes, 3)) + [nodes - 1]
    for m in (1, 2, 4):                       # P - 1 = m (N - 1): point m k sits on node k
        out = bezier(x, m * (nodes - 1) + 1)
        for k in ends:
            np.testing.assert_array_equal(out[:, m * k], x[:, k])
    # ... and it is a smoothing curve, not an interpolant: interior control nodes are missed
    out = bezier(x, nodes)
    assert np.abs(out[:, 1] - x[:, 1]).max() > 1e-6


def test_bezier_groups_share_end_nodes_and_weights_sum_to_one():
    idx, w = bezier_stencil(10, 37)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-15)
    assert idx.max() == 9 and idx.min() == 0
    # a straight, evenly spaced polyline stays a straight evenly spaced line
    x = np.zeros((1, 10, 3))
    x[0, :, 2] = -0.01 * np.arange(10)
    out = bezier(x, 19)
    np.testing.assert_allclose(out[0, :, 2], -0.005 * np.arange(19), atol=1e-15)


# ------------------------------------------------------------------ Catmull-Rom
@pytest.mark.parametrize('nodes', [2, 3, 5, 16])
def test_catmull_rom_matches_hermite_reference(nodes):
    x = random_strands(np.random.default_rng(10 + nodes), 4, nodes)
    for points in (2, 9, 31):
        np.testing.assert_allclose(catmull_rom(x, points), catmull_rom_reference(x, points),
                                   atol=1e-13)


@pytest.mark.parametrize('nodes', [2, 3, 7, 16])
def test_catmull_rom_passes_through_every_node(nodes):
    x = random_strands(np.random.default_rng(2), 5, nodes)
    for m in (1, 3):
        out = catmull_rom(x, m * (nodes - 1) + 1)
        np.testing.assert_array_equal(out[:, ::m], x)


def test_catmull_rom_straight_line_and_any_point_count():
    x = np.zeros((2, 5, 3))
    x[:, :, 0] = np.array([0.0, 0.01, 0.03, 0.06, 0.1])       # uneven spacing on a line
    out = catmull_rom(x, 50)
    np.testing.assert_allclose(out[..., 1:], 0.0, atol=1e-16)
    assert np.all(np.diff(out[0, :, 0]) > 0)                  # monotone, no overshoot loops
    assert out.shape == (2, 50, 3)


# ------------------------------------------------------------------ robustness
@pytest.mark.parametrize('curve', ['bezier', 'catmull_rom'])
def test_degenerate_strands_give_no_nan(curve):
    x = np.zeros((4, 7, 3))                       # strand 0: every node at the same point
    x[1] = np.linspace(0.0, 1.0, 7)[:, None]      # a plain line
    x[2, :4] = 0.3                                # first half collapsed
    x[2, 4:] = np.linspace(0.3, 0.5, 3)[:, None]
    x[3] = np.linspace(0.0, 1.0, 7)[:, None]
    x[3, 6] = x[3, 5]                             # collapsed tip segment
    out = resample(x, 25, curve)
    assert np.all(np.isfinite(out))
    np.testing.assert_array_equal(out[0], 0.0)
    two = resample(np.array([[[0.0, 0, 0], [0, 0, 0]], [[0.0, 0, 0], [1, 1, 1]]]), 5, curve)
    assert np.all(np.isfinite(two))
    np.testing.assert_allclose(two[1, :, 0], np.linspace(0, 1, 5), atol=1e-15)
    assert resample(np.zeros((0, 4, 3)), 6, curve).shape == (0, 6, 3)


def test_bad_input_is_rejected():
    x = np.zeros((2, 5, 3))
    with pytest.raises(ValueError, match='output.curve'):
        resample(x, 10, 'none')
    with pytest.raises(ValueError, match='points_per_strand'):
        resample(x, 1, 'bezier')
    with pytest.raises(ValueError, match='points_per_strand'):
        resample(x, 2.5, 'catmull_rom')
    with pytest.raises(ValueError, match=r'\(S, N, 3\)'):
        resample(np.zeros((5, 3)), 10, 'bezier')
    with pytest.raises(ValueError, match='at least 2 nodes'):
        resample(np.zeros((2, 1, 3)), 10, 'catmull_rom')
