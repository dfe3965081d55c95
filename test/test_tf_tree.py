"""TfTree: chains of parent -> child transforms composed like tf2 (no DDS here; the node's
use of it over DDS is in test_node_ros.py)."""
import numpy as np
import pytest

from hair_tracking.core.transforms import quat_from_axis_angle, quat_to_matrix
from msg_adapters.tf_tree import TfTree


def _apply(t, q, p):
    return np.asarray(t) + quat_to_matrix(q) @ np.asarray(p)


def test_to_root_composes_the_chain_and_lookup_relates_two_branches():
    tree = TfTree()
    q1 = quat_from_axis_angle([0, 0, 1], 0.7)
    q2 = quat_from_axis_angle([1, 0, 0], -0.4)
    q3 = quat_from_axis_angle([0, 1, 0], 1.1)
    assert tree.set('world', 'camera', [1.0, 2.0, 0.5], q1, static=True)
    assert tree.set('/camera', 'optical', [0.0, 0.1, 0.0], q2, static=True)
    assert tree.set('world', 'table', [3.0, 0.0, 0.0], q3, stamp_ns=5)
    p = np.array([0.2, -0.3, 0.9])
    root, t, q = tree.to_root('optical')
    assert root == 'world'
    want = _apply([1.0, 2.0, 0.5], q1, _apply([0.0, 0.1, 0.0], q2, p))
    np.testing.assert_allclose(_apply(t, q, p), want, atol=1e-12)
    # lookup(target, source): points of source in target
    t2, q2_ = tree.lookup('table', 'optical')
    in_table = _apply(t2, q2_, p)
    np.testing.assert_allclose(_apply([3.0, 0.0, 0.0], q3, in_table), want, atol=1e-12)
    # stop at an intermediate frame; an unknown frame is its own root
    assert tree.to_root('optical', stop='camera')[0] == 'camera'
    assert tree.to_root('elsewhere')[0] == 'elsewhere'
    assert tree.lookup('elsewhere', 'optical') is None


def test_bad_stale_and_looping_transforms():
    tree = TfTree()
    assert not tree.set('a', 'a', [0, 0, 0], [0, 0, 0, 1])
    assert not tree.set('a', 'b', [np.nan, 0, 0], [0, 0, 0, 1])
    assert not tree.set('a', 'b', [0, 0, 0], [0, 0, 0, 0])
    assert tree.set('a', 'b', [1, 0, 0], [0, 0, 0, 2], stamp_ns=10)   # normalised
    assert not tree.set('a', 'b', [2, 0, 0], [0, 0, 0, 1], stamp_ns=9)   # older: kept
    assert tree.to_root('b')[1][0] == 1.0
    np.testing.assert_allclose(tree.to_root('b')[2], [0, 0, 0, 1])
    tree.set('b', 'c', [0, 0, 0], [0, 0, 0, 1])
    tree.set('c', 'a', [0, 0, 0], [0, 0, 0, 1])
    with pytest.raises(ValueError, match='TF loop'):
        tree.to_root('c')


def test_add_message_takes_rclpy_and_rosbags_tf_messages():
    """The node's TFMessages (rclpy) and a bag's (rosbags) fill the tree the same way."""
    from hair_tracking.bags.io import head_pose_message
    from msg_adapters.tf import transform_message
    q = quat_from_axis_angle([0, 0, 1], 0.3)
    trees = [TfTree(), TfTree()]
    trees[0].add_message(transform_message(7, 'world', 'cam', [1.0, 0, 0], q), static=True)
    trees[1].add_message(head_pose_message('tf', 7, [1.0, 0, 0], q, '/world', 'cam')[1],
                         static=True)
    for tree in trees:
        assert tree.frames() == ['cam'] and tree.parent('cam') == 'world'
        root, t, r = tree.to_root('cam')
        assert root == 'world' and np.array_equal(t, [1.0, 0, 0])
        np.testing.assert_allclose(r, q, atol=1e-15)
