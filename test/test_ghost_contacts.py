"""The ghost kernel's head-contact stage (pushed nodes side by side) against the scalar
one-node functions it reorganises."""
import numpy as np
import pytest

from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from hair_tracking.ghosts import contacts as ghost_contacts
from hair_tracking.colliders.contact import ellipsoid_contact
from hair_tracking.guides.ftl import restore_node


def lanes(rng, n, axes):
    """Nodes of one node index: outside, just inside, deep inside, at the centre, and
    predecessors outside the surface (so the restore has something to do)."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u / axes, axis=1)[:, None]          # on the surface
    depth = rng.choice([1.3, 1.05, 0.999, 0.98, 0.6, 0.2], size=n)
    q = u * depth[:, None]
    q[::17] = 0.0                                            # the degenerate centre point
    start = q + rng.normal(scale=0.003, size=q.shape)
    prev = u * 1.12 + rng.normal(scale=0.004, size=q.shape)
    prev[5] = q[5]                                           # a collapsed segment
    return q, start, prev


@pytest.mark.parametrize('refine', [0, 1, 2, 4])
@pytest.mark.parametrize('ftl', [True, False])
@pytest.mark.parametrize('friction', [0.0, 0.3])
@pytest.mark.parametrize('axes', [(0.099, 0.084, 0.109), (0.08, 0.1, 0.11), (0.11, 0.1, 0.09)])
def test_contact_lanes_match_node_by_node(refine, ftl, friction, axes):
    """Same positions as ellipsoid_contact + restore_node node by node: radial projection and
    refinements, friction, a node at the centre (pushed along the shortest semi-axis, each axis
    shortest once), collapsed and zero rest segments, placements that need more than one
    restore iteration, and more refinements than the vectorised pass unrolls."""
    rng = np.random.default_rng(refine * 10 + ftl * 2 + int(friction > 0))
    n, j = 70, 3
    ax, ay, az = axes
    R = quat_to_matrix(quat_from_axis_angle([0.3, 1.0, 0.2], 0.7))
    c = np.array([0.01, -0.02, 0.03])
    q, start, prev = lanes(rng, n, np.array([ax, ay, az]))
    world = lambda p: p @ R.T + c                          # noqa: E731
    P = np.ascontiguousarray(world(q).T)
    X0 = np.ascontiguousarray(world(start).T)
    B = np.ascontiguousarray(world(prev).T)
    order = rng.permutation(n + 5)[:n].astype(np.int64)
    rest = rng.normal(scale=0.01, size=(n + 5, 6, 3))
    rest[order[7], j] = rest[order[7], j - 1]                # a zero rest segment
    seg_len = rng.uniform(0.005, 0.03, size=n)
    seg_len[5] = 0.0 if ftl else seg_len[5]
    want = P.copy()
    pushed = 0
    for kk in range(n):
        contact = (tuple(R.reshape(-1)), *c, ax, ay, az, friction, refine)
        moved, y0, y1, y2 = ellipsoid_contact(*P[:, kk], *X0[:, kk], contact)
        pushed += moved
        if moved and ftl:
            s = order[kk]
            y0, y1, y2 = restore_node((y0, y1, y2), tuple(B[:, kk]), seg_len[kk],
                                      tuple(rest[s, j] - rest[s, j - 1]), R,
                                      (*c, ax, ay, az, refine), 0)
        want[:, kk] = (y0, y1, y2)
    # the block's nodes (N, 3, n): node j - 1 final, node j the one pushed
    got = np.full((j + 1, 3, n), np.nan)
    got[j - 1], got[j] = B, P
    start_nodes = np.full((j + 1, 3, n), np.nan)
    start_nodes[j] = X0
    lengths = np.full((j, n), np.nan)
    lengths[j - 1] = seg_len
    W = np.full((ghost_contacts.CONTACT_ROWS, n), np.nan)
    m = ghost_contacts.collide_lanes(start_nodes, got, W, j, (n, 0), (order, lengths, rest), ftl,
                                     contact, R)
    assert m == pushed > n // 3
    np.testing.assert_array_equal(got[j - 1], B)
    got = got[j]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    assert np.isfinite(got).all()


def test_no_contact_changes_nothing():
    rng = np.random.default_rng(3)
    n = 20
    P = rng.normal(size=(3, n)) + 1.0                        # far outside
    before = P.copy()
    W = np.zeros((ghost_contacts.CONTACT_ROWS, n))
    contact = (tuple(np.eye(3).reshape(-1)), 0.0, 0.0, 0.0, 0.1, 0.1, 0.1, 0.3, 2)
    nodes = np.stack([P, P, P])
    m = ghost_contacts.collide_lanes(nodes, nodes, W, 2, (n, 0),
                                     (np.arange(n), np.ones((2, n)), np.zeros((n, 4, 3))), True,
                                     contact, np.eye(3))
    assert m == 0 and np.array_equal(nodes[2], before)
