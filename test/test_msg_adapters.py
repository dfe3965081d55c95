"""Pose reading/writing, stamps, input validation and the object-path MarkerArray."""
import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import (Pose, PoseStamped, PoseWithCovarianceStamped, Transform,
                               TransformStamped)
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
from rclpy.serialization import serialize_message
from visualization_msgs.msg import Marker

from msg_adapters.arrays import as_colors, as_strands
from msg_adapters.marker_spec import ADD, DELETEALL, LINE_LIST, LINE_STRIP
from msg_adapters.markers import delete_all_marker, strands_to_marker_array
from msg_adapters.pose import (pose_from_msg, pose_msg, pose_stamped_msg, PoseError,
                               transform_stamped_msg)
from msg_adapters.stamps import duration_msg, split_ns, time_msg, time_to_ns


def test_field_checks_are_on():
    """The suite must run with ROS_PYTHON_CHECK_FIELDS=1, or rclpy skips type checks."""
    assert Marker()._check_fields


def assert_exact_types(msg):
    """Every field of ``msg`` (recursively) holds the exact Python type its slot wants."""
    for name, ftype in msg.get_fields_and_field_types().items():
        value = getattr(msg, name)
        if ftype in ('double', 'float'):
            assert type(value) is float, (name, type(value))
        elif ftype in ('int32', 'uint32', 'int8', 'uint8', 'int64', 'uint64'):
            assert type(value) is int, (name, type(value))
        elif ftype == 'boolean':
            assert type(value) is bool, (name, type(value))
        elif ftype == 'string':
            assert type(value) is str, name
        elif ftype.startswith('sequence<') and '/' in ftype:
            for item in value:
                assert_exact_types(item)
        elif '/' in ftype:
            assert_exact_types(value)


# --- stamps -----------------------------------------------------------------------------------

def test_stamps_round_trip_exact_ints():
    for t in (0, 1, 999_999_999, 1_000_000_000, 1_700_000_000_123_456_789,
              (2 ** 31 - 1) * 10 ** 9 + 999_999_999):
        msg = time_msg(np.int64(t))
        assert type(msg.sec) is int and type(msg.nanosec) is int
        assert time_to_ns(msg) == t
    assert split_ns(1_500_000_000) == (1, 500_000_000)
    assert duration_msg(2_000_000_001).sec == 2


def test_stamp_errors():
    with pytest.raises(ValueError, match='>= 0'):
        time_msg(-1)
    with pytest.raises(ValueError, match='int32'):
        time_msg(2 ** 31 * 10 ** 9)
    with pytest.raises(TypeError, match='integer'):
        time_msg(1.5)
    with pytest.raises(TypeError, match='bool'):
        time_msg(True)
    with pytest.raises(ValueError, match=r'header\.stamp\.nanosec'):
        time_to_ns(Time(sec=1, nanosec=1_000_000_000))
    with pytest.raises(ValueError, match=r'header\.stamp\.sec'):
        time_to_ns(Time(sec=-1, nanosec=0))


# --- poses ------------------------------------------------------------------------------------

P = [0.1, -0.2, 1.5]
Q = [0.0, 0.0, math.sin(0.3), math.cos(0.3)]


def test_pose_stamped_round_trip():
    msg = pose_stamped_msg(np.int64(1_234_567_890_123), np.array(P), np.array(Q), 'camera')
    assert_exact_types(msg)
    s = pose_from_msg(msg)
    assert s.t_ns == 1_234_567_890_123 and type(s.t_ns) is int
    np.testing.assert_array_equal(s.position, P)
    np.testing.assert_array_equal(s.quaternion, Q)
    assert s.position.dtype == np.float64 and s.quaternion.shape == (4,)
    assert (s.frame_id, s.child_frame_id) == ('camera', '')
    assert not s.position.flags.writeable


def test_transform_stamped_round_trip():
    msg = transform_stamped_msg(5, P, Q, 'world', 'face_7')
    assert_exact_types(msg)
    s = pose_from_msg(msg)
    assert (s.t_ns, s.frame_id, s.child_frame_id) == (5, 'world', 'face_7')
    np.testing.assert_array_equal(s.position, P)
    np.testing.assert_array_equal(s.quaternion, Q)


def test_other_pose_types_and_unnormalised_quaternion():
    q = [0.0, 0.0, 0.0, 2.0]                       # returned as received, not normalised
    pose = pose_msg(P, q)
    cov = PoseWithCovarianceStamped()
    cov.header.frame_id = 'map'
    cov.pose.pose = pose
    cov_stamped = PoseWithCovarianceStamped()
    cov_stamped.header.stamp.sec = 3
    cov_stamped.pose.pose = pose
    tf = Transform()
    tf.translation.x, tf.rotation.w = 1.0, 1.0
    for msg, t, frame, child in ((pose, 0, '', ''), (cov, 0, 'map', ''),
                                 (cov_stamped, 3 * 10 ** 9, '', '')):
        s = pose_from_msg(msg)
        assert (s.t_ns, s.frame_id, s.child_frame_id) == (t, frame, child)
        np.testing.assert_array_equal(s.quaternion, q)
    np.testing.assert_array_equal(pose_from_msg(tf).position, [1.0, 0.0, 0.0])


def test_stamp_zero_is_returned_as_zero():
    assert pose_from_msg(pose_stamped_msg(0, P, Q, 'c')).t_ns == 0


def test_rosbags_messages_are_read_too():
    ts = get_typestore(Stores.ROS2_JAZZY)
    raw = serialize_message(transform_stamped_msg(17, P, Q, 'w', 'head'))
    s = pose_from_msg(ts.deserialize_cdr(raw, 'geometry_msgs/msg/TransformStamped'))
    assert (s.t_ns, s.child_frame_id) == (17, 'head')
    np.testing.assert_array_equal(s.quaternion, Q)


@pytest.mark.parametrize('field,index,value', [
    ('pose.position.y', 1, float('nan')), ('pose.position.z', 2, float('inf')),
    ('pose.orientation.w', 3, float('nan')), ('pose.orientation.x', 0, float('-inf'))])
def test_pose_errors_name_the_field(field, index, value):
    p, q = list(P), list(Q)
    (p if 'position' in field else q)[index] = value
    msg = pose_stamped_msg(1, p, q, 'c', check=False)
    with pytest.raises(PoseError, match=field.replace('.', r'\.')):
        pose_from_msg(msg)


def test_zero_quaternion_and_bad_stamp():
    msg = transform_stamped_msg(1, P, [0.0, 0.0, 0.0, 0.0], 'w', 'h', check=False)
    with pytest.raises(PoseError, match=r'transform\.rotation has norm 0'):
        pose_from_msg(msg)
    msg = pose_stamped_msg(1, P, Q, 'c')
    msg.header.stamp.nanosec = 2_000_000_000
    with pytest.raises(PoseError, match='nanosec'):
        pose_from_msg(msg)
    assert issubclass(PoseError, ValueError)
    with pytest.raises(TypeError, match='cannot read a pose'):
        pose_from_msg(Time())


def test_pose_builders_validate():
    with pytest.raises(ValueError, match=r'shape \(3,\)'):
        pose_stamped_msg(0, [1.0, 2.0], Q, 'c')
    with pytest.raises(ValueError, match=r'shape \(4,\)'):
        transform_stamped_msg(0, P, Q[:3], 'w', 'h')
    with pytest.raises(PoseError):
        pose_stamped_msg(0, [np.nan, 0, 0], Q, 'c')
    with pytest.raises(PoseError):
        pose_msg(P, [0, 0, 0, 0])
    assert isinstance(pose_stamped_msg(0, P, Q, 'c'), PoseStamped)
    assert isinstance(transform_stamped_msg(0, P, Q, 'w', 'h'), TransformStamped)
    assert isinstance(pose_msg(np.float32([1, 2, 3]), Q), Pose)


# --- array validation -------------------------------------------------------------------------

def test_as_strands():
    a = as_strands(np.ones((2, 3, 3), dtype=np.float32))
    assert a.dtype == np.float64 and a.flags.c_contiguous
    with pytest.raises(ValueError, match=r'\(S, N, 3\)'):
        as_strands(np.ones((2, 3)))
    with pytest.raises(ValueError, match=r'\(S, N, 3\)'):
        as_strands(np.ones((2, 3, 2)))
    with pytest.raises(ValueError, match='at least 2 points'):
        as_strands(np.ones((2, 1, 3)), min_points=2)
    with pytest.raises(ValueError, match='dtype'):
        as_strands(np.array([[['a', 'b', 'c']]]))
    x = np.ones((2, 3, 3))
    x[0, 1, 2] = np.inf
    with pytest.raises(ValueError, match=r'strands\[0, 1, 2\] is inf'):
        as_strands(x)
    assert np.isinf(as_strands(x, finite=False)).sum() == 1


def test_as_colors():
    assert as_colors(None, 2, 3) is None
    c = as_colors(np.full((2, 3), 0.5), 2, 3)
    assert c.shape == (2, 1, 4) and c.dtype == np.float32 and (c[..., 3] == 1).all()
    assert as_colors(np.zeros((2, 3, 4)), 2, 3).shape == (2, 3, 4)
    with pytest.raises(ValueError, match='shaped'):
        as_colors(np.zeros((3, 4)), 2, 3)
    with pytest.raises(ValueError, match=r'colors\[1, 2\] is 1.5'):
        as_colors(np.array([[0, 0, 0], [0, 0, 1.5]]), 2, 3)
    c = np.zeros((2, 3, 4))
    c[1, 1, 3] = np.nan
    with pytest.raises(ValueError, match=r'colors\[1, 1, 3\] is nan'):
        as_colors(c, 2, 3)
    c[1, 1, 3] = -0.1
    with pytest.raises(ValueError, match=r'colors\[1, 1, 3\] is -0.1'):
        as_colors(c, 2, 3)


# --- MarkerArray, object path -----------------------------------------------------------------

def reference_segments(x):
    """Plain-loop reference of the LINE_LIST point order."""
    out = []
    for s in range(x.shape[0]):
        for i in range(x.shape[1] - 1):
            out += [x[s, i], x[s, i + 1]]
    return np.array(out).reshape(-1, x.shape[-1])


def xyz(points):
    return np.array([[p.x, p.y, p.z] for p in points]).reshape(-1, 3)


def rgba(colors):
    return np.array([[c.r, c.g, c.b, c.a] for c in colors], dtype=np.float32).reshape(-1, 4)


def test_constants_match_message():
    assert (LINE_LIST, LINE_STRIP, ADD, DELETEALL) == (
        Marker.LINE_LIST, Marker.LINE_STRIP, Marker.ADD, Marker.DELETEALL)


def test_line_list_marker():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 4, 3))
    cols = rng.random((3, 4))
    arr = strands_to_marker_array(x, frame_id='head', stamp_ns=2_500_000_000, ns='hair',
                                  width=0.002, colors=cols, lifetime_ns=100_000_000,
                                  first_id=9, color=(1.0, 0.5, 0.25))
    assert_exact_types(arr.markers[0])
    (m,) = arr.markers
    assert (m.type, m.action, m.id, m.ns) == (Marker.LINE_LIST, Marker.ADD, 9, 'hair')
    stamp = m.header.stamp
    assert (m.header.frame_id, stamp.sec, stamp.nanosec) == ('head', 2, 500_000_000)
    assert (m.lifetime.sec, m.lifetime.nanosec) == (0, 100_000_000)
    assert m.scale.x == 0.002 and m.pose.orientation.w == 1.0
    assert (m.color.r, m.color.g, m.color.b, m.color.a) == (1.0, 0.5, 0.25, 1.0)
    np.testing.assert_array_equal(xyz(m.points), reference_segments(x))
    expected = np.array([cols[s] for s in range(3) for _ in range(6)], dtype=np.float32)
    np.testing.assert_array_equal(rgba(m.colors), expected)
    # Per-point colours follow the segment endpoints.
    cols = rng.random((3, 4, 4))
    (m,) = strands_to_marker_array(x, frame_id='head', colors=cols).markers
    np.testing.assert_array_equal(rgba(m.colors), reference_segments(cols).astype(np.float32))


def test_line_strips_markers():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(5, 3, 3))
    cols = rng.random((5, 3, 3))
    arr = strands_to_marker_array(x, frame_id='w', style='line_strips', colors=cols,
                                  first_id=100, delete_all_first=True)
    for m in arr.markers:
        assert_exact_types(m)
    assert arr.markers[0] == delete_all_marker('w', 0, 'strands')
    strips = arr.markers[1:]
    assert [m.id for m in strips] == list(range(100, 105))
    for s, m in enumerate(strips):
        assert m.type == Marker.LINE_STRIP and m.action == Marker.ADD
        np.testing.assert_array_equal(xyz(m.points), x[s])
        np.testing.assert_array_equal(rgba(m.colors)[:, :3], cols[s].astype(np.float32))
        assert (rgba(m.colors)[:, 3] == 1).all()


def test_no_colors_gives_empty_colors():
    arr = strands_to_marker_array(np.zeros((2, 2, 3)), frame_id='w', style='line_strips')
    assert all(len(m.colors) == 0 and len(m.points) == 2 for m in arr.markers)
    assert all(m.color.a == 1.0 for m in arr.markers)      # visible by default


def test_empty_inputs():
    assert len(strands_to_marker_array(np.zeros((0, 4, 3)), frame_id='w',
                                       style='line_strips').markers) == 0
    (m,) = strands_to_marker_array(np.zeros((0, 4, 3)), frame_id='w').markers
    assert len(m.points) == 0


def test_delete_all_marker():
    m = delete_all_marker('map', 5, 'ns')
    assert (m.action, m.header.frame_id, m.ns, m.header.stamp.nanosec) == (
        Marker.DELETEALL, 'map', 'ns', 5)
    with pytest.raises(ValueError, match='frame_id'):
        delete_all_marker('')


@pytest.mark.parametrize('kwargs,match', [
    (dict(frame_id=''), 'frame_id'), (dict(frame_id=3), 'frame_id'),
    (dict(frame_id='w', width=0.0), 'width'), (dict(frame_id='w', width=float('nan')), 'width'),
    (dict(frame_id='w', stamp_ns=-5), 'stamp_ns'), (dict(frame_id='w', stamp_ns=1.0), 'stamp_ns'),
    (dict(frame_id='w', lifetime_ns=-1), 'lifetime_ns'),
    (dict(frame_id='w', color=(1, 1)), 'color'), (dict(frame_id='w', color=(2, 0, 0)), 'color'),
    (dict(frame_id='w', colors=np.zeros((3, 3))), 'colors'),
    (dict(frame_id='w', style='line_strips', first_id=2 ** 31 - 1), 'int32'),
    (dict(frame_id='w', style='strips'), 'style')])
def test_marker_errors(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        strands_to_marker_array(np.zeros((2, 3, 3)), **kwargs)


def test_marker_rejects_nan_and_short_strands():
    x = np.zeros((2, 3, 3))
    x[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match=r'strands\[1, 0, 1\] is nan'):
        strands_to_marker_array(x, frame_id='w')
    with pytest.raises(ValueError, match='at least 2 points'):
        strands_to_marker_array(np.zeros((2, 1, 3)), frame_id='w')
