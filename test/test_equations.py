"""Each equation of Park & Kim as its one function, against the formula written in numpy."""
import numpy as np
import pytest

from hair_tracking.core.curves import bernstein
from hair_tracking.ghosts.correspondence import correspondence_distance
from hair_tracking.ghosts.spread import group_variance, spread_factor, spread_penalty
from hair_tracking.ghosts.weights import weighted_position


def test_equation1_sums_squared_distances_to_the_nearest_guide_nodes():
    rng = np.random.default_rng(3)
    ghosts, guides = rng.normal(size=(2, 7, 3)), rng.normal(size=(3, 5, 3))
    for s in range(2):
        for g in range(3):
            d2 = ((ghosts[s][:, None, :] - guides[g][None, :, :]) ** 2).sum(axis=2)
            want = d2.min(axis=1).sum()
            assert correspondence_distance(ghosts, s, guides, g, np.inf) == pytest.approx(want)
            # with a bound the sum stops once it is exceeded (the candidate cannot win)
            assert correspondence_distance(ghosts, s, guides, g, 0.5 * want) > 0.5 * want


def test_equations_2_and_3_and_the_spread_step():
    rng = np.random.default_rng(4)
    p = rng.normal(size=(3, 9))
    m = p.mean(axis=1)
    var = group_variance(p[None], 0, 0, 9, tuple(m))
    assert var == pytest.approx(((p - m[:, None]) ** 2).sum())
    assert spread_penalty(var, 2.0 * var, 3.0) == pytest.approx(3.0 * var ** 2)
    # full strength: one step scales the offsets so that (2) is zero
    f = spread_factor(var, 1.5 * var, 1.0)
    q = m[:, None] + f * (p - m[:, None])
    assert spread_penalty(group_variance(q[None], 0, 0, 9, tuple(m)), 1.5 * var, 1.0) < 1e-20
    assert spread_factor(var, 100.0 * var, 1.0) == 2.0          # ratio clipped to [0.5, 2]
    assert spread_factor(var, 0.0, 0.5) == 0.75
    assert spread_factor(0.0, 1.0, 1.0) == 1.0                  # no spread to scale


def test_equation5_moves_by_the_weighted_displacement_with_the_sum_clamped():
    x, d = np.array([0.1, -0.2, 0.3]), np.array([0.01, 0.02, -0.005])
    y = weighted_position(*x, *d, 0.4, 0.2, 0.1, 1.5)
    assert np.allclose(y[:3], x + d * (1.0 + 0.7), rtol=0, atol=1e-15) and y[3] == 0
    y = weighted_position(*x, *d, 0.9, 0.5, 0.4, 1.5)
    assert np.allclose(y[:3], x + d * 2.5, rtol=0, atol=1e-15) and y[3] == 1


def test_equation6_uses_the_cubic_bernstein_coefficients():
    for t in np.linspace(0.0, 1.0, 7):
        w = [bernstein(3, i, t) for i in range(4)]
        want = [(1 - t) ** 3, 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2, t ** 3]
        assert np.allclose(w, want, rtol=0, atol=1e-15)
        assert sum(w) == pytest.approx(1.0)
