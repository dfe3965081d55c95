"""Bag reading/writing without ROS: import of real recordings, head-pose extraction (PoseStamped,
TransformStamped, TF with static chains, ROS 1), atomic writing, PointCloud2 decoding."""
import math
import os

import numpy as np
import pytest

from hair_tracking.bags import io as bag_io

from hair_tracking.bags.cli import DEFAULT_START_TIME_S, main
from hair_tracking.core.transforms import matrices_to_quats, quat_multiply, quat_to_matrix
from hair_tracking.motion import bvh as mocap, pose_table as tables

from recordings import VR_TRACE as VR360, WALK_BVH as BVH

T0 = int(DEFAULT_START_TIME_S * 1e9)


def _same_rotation(q1, q2):
    """Largest distance between two unit-quaternion streams, q ~ -q (about half the angle
    between the rotations [rad] when small)."""
    a = q1 / np.linalg.norm(q1, axis=1, keepdims=True)
    b = q2 / np.linalg.norm(q2, axis=1, keepdims=True)
    return float(np.max(np.minimum(np.linalg.norm(a - b, axis=1),
                                   np.linalg.norm(a + b, axis=1))))


# ------------------------------------------------------------------ import of the recordings
@pytest.mark.parametrize('suffix', ['.mcap', '.db3'])
def test_import_bvh_walk_matches_forward_kinematics(tmp_path, suffix, capsys):
    out = tmp_path / ('walk' + suffix)
    assert main(['import', str(BVH), '-o', str(out)]) == 0
    assert 'cmu' in capsys.readouterr().out          # units recognised from the skeleton
    ref = mocap.load_bvh_head_motion(str(BVH))           # metres, REP-103, Head joint
    hp = bag_io.read_head_poses(out)
    assert hp.topic == '/head_pose' and hp.msgtype == 'geometry_msgs/msg/PoseStamped'
    assert hp.frame_id == 'world'
    assert len(hp) == len(ref) == 360
    np.testing.assert_array_equal(hp.t_ns, ref.t_ns - ref.t_ns[0] + T0)
    np.testing.assert_array_equal(hp.log_ns, hp.t_ns)
    np.testing.assert_allclose(hp.position, ref.position, rtol=0, atol=1e-12)
    assert _same_rotation(hp.quaternion, ref.quaternion) < 1e-12
    # physically sensible: a walking adult's head, z up, moving a few metres in 3 s
    assert 1.3 < np.median(hp.position[:, 2]) < 1.9
    assert np.linalg.norm(hp.position[-1, :2] - hp.position[0, :2]) > 1.5
    up = quat_to_matrix(hp.quaternion)[:, :, 2]       # head z axis in the world
    assert np.median(up[:, 2]) > 0.9


def test_import_vr360_table_with_named_columns(tmp_path):
    out = tmp_path / 'vr'
    code = main(['import', str(VR360), '-o', str(out), '--storage', 'sqlite3',
                 '--time-column', 'timestamp', '--quat-columns', 'w,x,y,z',
                 '--quat-order', 'wxyz', '--position-columns', 'none',
                 '--neck-offset', '0,0,0.1', '--pivot', '0,0,1.6', '--message', 'transform'])
    assert code == 0
    assert (out / 'metadata.yaml').is_file()
    assert any(p.suffix == '.db3' for p in out.iterdir())
    ref = tables.read_vr360(str(VR360), neck_offset=[0, 0, 0.1], pivot=[0, 0, 1.6])
    hp = bag_io.read_head_poses(out)
    assert hp.msgtype == 'geometry_msgs/msg/TransformStamped'
    assert hp.child_frame_id == 'head'
    assert len(hp) == len(ref) > 600                    # 12 s at 59 Hz
    np.testing.assert_array_equal(hp.t_ns, ref.t_ns - ref.t_ns[0] + T0)
    np.testing.assert_allclose(hp.position, ref.position, atol=1e-12)
    assert _same_rotation(hp.quaternion, ref.quaternion) < 1e-12
    # orientation only: the head origin stays 0.1 m from the pivot
    np.testing.assert_allclose(np.linalg.norm(hp.position - [0, 0, 1.6], axis=1), 0.1,
                               atol=1e-9)


def test_import_slice_tf_and_keep_times(tmp_path):
    out = tmp_path / 'tf.mcap'
    assert main(['import', str(BVH), '-o', str(out), '--start', '1.0', '--duration', '0.5',
                 '--message', 'tf', '--child-frame-id', 'face_7', '--start-time', '50']) == 0
    hp = bag_io.read_head_poses(out, head_frame='face_7')
    assert hp.topic == '/tf' and hp.child_frame_id == 'face_7'
    assert len(hp) == 60                                  # 0.5 s at 120 Hz
    assert hp.t_ns[0] == 50 * 10 ** 9
    ref = mocap.load_bvh_head_motion(str(BVH))
    t = ref.t_ns - ref.t_ns[0]
    keep = (t >= 10 ** 9) & (t < 15 * 10 ** 8)          # Frame Time .0083333: not 1/120 s
    np.testing.assert_allclose(hp.position, ref.position[keep], atol=1e-12)


def test_import_rejects_bad_columns_and_ranges(tmp_path, capsys):
    table = tmp_path / 'poses.csv'
    table.write_text('time,a,b\n0.0,1,2\n')
    assert main(['import', str(table), '-o', str(tmp_path / 'x.mcap')]) == 3
    err = capsys.readouterr().err
    assert 'no quaternion columns recognised' in err and "'time'" in err
    assert 'Traceback' not in err
    good = tmp_path / 'good.csv'
    good.write_text('t_s,px,py,pz,qx,qy,qz,qw\n0.0,0,0,1.6,0,0,0,1\n0.1,0,0,1.6,0,0,0,1\n')
    assert main(['import', str(good), '-o', str(tmp_path / 'y.mcap'), '--start', '5']) == 4
    assert 'no samples' in capsys.readouterr().err
    assert main(['import', str(good), '-o', str(tmp_path / 'z.mcap'), '--keep-times']) == 2
    assert 'time 0' in capsys.readouterr().err
    assert not any(p.name.startswith(('x.', 'y.', 'z.')) for p in tmp_path.iterdir())


# ------------------------------------------------------------------ TF and static chains
def _tf_bag(path):
    """/tf_static world->camera (rotated, shifted), /tf camera->face_1 and camera->hand."""
    ts = bag_io.typestore()
    rng = np.random.default_rng(3)
    q_cam = matrices_to_quats(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0],
                                       [0.0, -1.0, 0.0]]))
    p_cam = np.array([1.0, 0.5, 1.2])
    t = 10 ** 9 + np.arange(20) * 10 ** 7
    p_face = rng.normal(size=(20, 3)) * 0.1 + [0, 0, 1.0]
    q_face = rng.normal(size=(20, 4))
    q_face /= np.linalg.norm(q_face, axis=1, keepdims=True)
    with bag_io.BagWriter(path) as w:
        w.add_topic('/tf_static', 'tf2_msgs/msg/TFMessage',
                    bag_io.qos_profile(transient_local=True, depth=1))
        w.add_topic('/tf', 'tf2_msgs/msg/TFMessage')
        _, st = bag_io.head_pose_message('tf', 10 ** 9, p_cam, q_cam, 'world', 'camera')
        w.write('/tf_static', 10 ** 9 - 1, ts.serialize_cdr(st, 'tf2_msgs/msg/TFMessage'))
        for k in range(20):
            _, a = bag_io.head_pose_message('tf', int(t[k]), p_face[k], q_face[k], 'camera',
                                            'face_1')
            _, b = bag_io.head_pose_message('tf', int(t[k]), [0, 0, 0], [0, 0, 0, 1], 'camera',
                                            'hand')
            a.transforms.append(b.transforms[0])
            w.write('/tf', int(t[k]), ts.serialize_cdr(a, 'tf2_msgs/msg/TFMessage'))
    return t, p_cam, q_cam, p_face, q_face


def test_tf_head_frame_composed_with_static_chain(tmp_path):
    path = tmp_path / 'tf.mcap'
    t, p_cam, q_cam, p_face, q_face = _tf_bag(path)
    hp = bag_io.read_head_poses(path, head_frame='face_1', fixed_frame='world')
    assert hp.frame_id == 'world' and hp.child_frame_id == 'face_1' and len(hp) == 20
    r_cam = quat_to_matrix(q_cam)
    np.testing.assert_allclose(hp.position, p_cam + p_face @ r_cam.T, atol=1e-12)
    want_q = quat_multiply(q_cam, q_face)
    assert _same_rotation(hp.quaternion, want_q) < 1e-12
    np.testing.assert_array_equal(hp.t_ns, t)
    # without a fixed frame: the poses stay in the camera frame
    raw = bag_io.read_head_poses(path, head_frame='face_1')
    assert raw.frame_id == 'camera'
    np.testing.assert_allclose(raw.position, p_face, atol=1e-15)
    # the head frame found by name when none is given ('face' in it)
    auto = bag_io.read_head_poses(path)
    assert auto.child_frame_id == 'face_1'


def test_tf_unknown_frame_and_missing_chain(tmp_path):
    path = tmp_path / 'tf.mcap'
    _tf_bag(path)
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(path, head_frame='face_2')
    assert e.value.code == bag_io.EXIT_CONTENT
    assert 'face_2' in str(e.value) and 'face_1' in str(e.value) and 'hand' in str(e.value)
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(path, head_frame='face_1', fixed_frame='map')
    assert e.value.code == bag_io.EXIT_CONTENT and "'map'" in str(e.value)


def test_ros1_bag_through_anyreader(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import get_typestore, Stores
    ts1 = get_typestore(Stores.ROS1_NOETIC)
    t = ts1.types
    path = tmp_path / 'old.bag'
    rng = np.random.default_rng(5)
    pos = rng.normal(size=(15, 3))
    with Writer(path) as w:
        conn = w.add_connection('/head_pose', 'geometry_msgs/msg/PoseStamped', typestore=ts1)
        for k in range(15):
            stamp = 2 * 10 ** 9 + k * 10 ** 7
            msg = t['geometry_msgs/msg/PoseStamped'](
                header=t['std_msgs/msg/Header'](
                    seq=k, stamp=t['builtin_interfaces/msg/Time'](sec=2, nanosec=k * 10 ** 7),
                    frame_id='odom'),
                pose=t['geometry_msgs/msg/Pose'](
                    position=t['geometry_msgs/msg/Point'](x=pos[k, 0], y=pos[k, 1], z=pos[k, 2]),
                    orientation=t['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0)))
            w.write(conn, stamp, ts1.serialize_ros1(msg, 'geometry_msgs/msg/PoseStamped'))
    hp = bag_io.read_head_poses(path)
    assert hp.frame_id == 'odom' and len(hp) == 15
    np.testing.assert_allclose(hp.position, pos)
    assert hp.t_ns[3] == 2 * 10 ** 9 + 3 * 10 ** 7


def test_invalid_pose_messages_are_counted_not_fatal(tmp_path):
    t = 10 ** 9 + np.arange(6) * 10 ** 7
    p = np.zeros((6, 3))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (6, 1))
    p[2, 0] = math.nan
    q[4] = 0.0
    path = tmp_path / 'bad_values.mcap'
    bag_io.write_head_pose_bag(path, t, p, q)
    hp = bag_io.read_head_poses(path)
    assert len(hp) == 4 and hp.invalid == 2 and hp.messages == 6
    assert any('nan' in r.lower() for r in hp.invalid_reasons)


# ------------------------------------------------------------------ finding the stream
def test_topic_selection_rules(tmp_path):
    t = 10 ** 9 + np.arange(3) * 10 ** 7
    p = np.zeros((3, 3))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (3, 1))
    ts = bag_io.typestore()
    path = tmp_path / 'two.mcap'
    with bag_io.BagWriter(path) as w:
        for topic in ('/head_pose', '/other_pose'):
            w.add_topic(topic, 'geometry_msgs/msg/PoseStamped')
            for k in range(3):
                mt, m = bag_io.head_pose_message('pose', int(t[k]), p[k], q[k], 'w', '')
                w.write(topic, int(t[k]), ts.serialize_cdr(m, mt))
    assert bag_io.read_head_poses(path).topic == '/head_pose'       # preferred by name
    assert bag_io.read_head_poses(path, topic='other_pose').topic == '/other_pose'
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(path, topic='/nope')
    assert e.value.code == 4 and '/other_pose' in str(e.value)


def test_no_head_pose_topic_lists_topics(tmp_path):
    path = tmp_path / 'chat.mcap'
    ts = bag_io.typestore()
    with bag_io.BagWriter(path) as w:
        w.add_topic('/chatter', 'std_msgs/msg/String')
        m = ts.types['std_msgs/msg/String'](data='hi')
        w.write('/chatter', 5, ts.serialize_cdr(m, 'std_msgs/msg/String'))
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(path)
    assert e.value.code == bag_io.EXIT_CONTENT
    assert '/chatter' in str(e.value) and 'std_msgs/msg/String' in str(e.value)
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(path, topic='/chatter')
    assert 'not a head pose' in str(e.value)


# ------------------------------------------------------------------ opening bad inputs
def test_bag_kind_and_bad_inputs(tmp_path):
    good = tmp_path / 'g.mcap'
    bag_io.write_head_pose_bag(good, [10 ** 9, 2 * 10 ** 9], np.zeros((2, 3)),
                               [[0, 0, 0, 1.0]] * 2)
    assert bag_io.bag_kind(good)[0] == 'mcap'
    renamed = tmp_path / 'g.data'                 # content decides, not the name
    renamed.write_bytes(good.read_bytes())
    assert len(bag_io.read_head_poses(renamed)) == 2
    cases = {
        tmp_path / 'missing.mcap': 'no such file',
        tmp_path / 'text.mcap': 'not a bag',
        tmp_path / 'empty.db3': 'empty file',
        tmp_path: 'not a rosbag2 bag',
        tmp_path / 'trunc.mcap': 'corrupt',
    }
    (tmp_path / 'text.mcap').write_text('hello')
    (tmp_path / 'empty.db3').write_bytes(b'')
    (tmp_path / 'trunc.mcap').write_bytes(good.read_bytes()[:200])
    for path, words in cases.items():
        with pytest.raises(bag_io.BagError) as e:
            bag_io.read_head_poses(path)
        assert e.value.code == bag_io.EXIT_INPUT, path
        assert words in str(e.value), (path, str(e.value))


def test_corrupt_chunk_detected_by_count(tmp_path):
    src = tmp_path / 'ok.mcap'
    n = 400
    bag_io.write_head_pose_bag(src, 10 ** 9 + np.arange(n) * 10 ** 7, np.zeros((n, 3)),
                               np.tile([0, 0, 0, 1.0], (n, 1)))
    data = bytearray(src.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 400] = b'\x55' * 400
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(bytes(data))
    with pytest.raises(bag_io.BagError) as e:
        bag_io.read_head_poses(bad)
    assert e.value.code == bag_io.EXIT_INPUT and 'corrupt' in str(e.value)


# ------------------------------------------------------------------ writing
def test_writer_is_atomic_and_refuses_existing(tmp_path):
    out = tmp_path / 'out.mcap'
    with pytest.raises(RuntimeError):
        with bag_io.BagWriter(out) as w:
            w.add_topic('/head_pose', 'geometry_msgs/msg/PoseStamped')
            w.write('/head_pose', 1, b'\x00\x01\x00\x00' + bytes(60))
            assert not out.exists()
            raise RuntimeError('fail half-way')
    assert list(tmp_path.iterdir()) == []            # nothing left, not even temp files
    for name in ('dir_bag', 'one.db3', 'one.mcap'):
        p = tmp_path / name
        bag_io.write_head_pose_bag(p, [10 ** 9], [[0, 0, 0]], [[0, 0, 0, 1.0]])
        assert p.exists()
        with pytest.raises(bag_io.BagError) as e:
            bag_io.write_head_pose_bag(p, [10 ** 9], [[0, 0, 0]], [[0, 0, 0, 1.0]])
        assert e.value.code == bag_io.EXIT_OUTPUT and 'already exists' in str(e.value)
        bag_io.write_head_pose_bag(p, [2 * 10 ** 9], [[1, 0, 0]], [[0, 0, 0, 1.0]],
                                   overwrite=True)
        assert bag_io.read_head_poses(p).position[0, 0] == 1.0
    assert bag_io.bag_kind(tmp_path / 'dir_bag')[0] == 'dir'
    assert sorted(os.listdir(tmp_path)) == ['dir_bag', 'one.db3', 'one.mcap']
    with pytest.raises(bag_io.BagError) as e:
        bag_io.BagWriter(tmp_path / 'x.db3', storage='mcap')
    assert e.value.code == bag_io.EXIT_USAGE


def test_written_bag_read_by_plain_rosbags_reader(tmp_path):
    """An independent reader (rosbags Reader + Jazzy typestore) sees exactly what we wrote."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    out = tmp_path / 'b'
    t = 10 ** 9 + np.arange(5) * 10 ** 6
    p = np.arange(15.0).reshape(5, 3)
    bag_io.write_head_pose_bag(out, t, p, np.tile([0, 0, 0, 1.0], (5, 1)), storage='sqlite3')
    with Reader(out) as r:
        got = [(ts_, ts.deserialize_cdr(raw, c.msgtype)) for c, ts_, raw in r.messages()]
    assert [g[0] for g in got] == t.tolist()
    np.testing.assert_array_equal([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                   for _, m in got], p)


def test_cloud_messages_of_a_bag_in_log_time_order(tmp_path):
    from msg_adapters.pointcloud import pointcloud2_to_strands, strands_to_pointcloud2_cdr
    rng = np.random.default_rng(11)
    strands = rng.normal(size=(3, 7, 5, 3))
    with bag_io.BagWriter(tmp_path / 'c.mcap') as w:
        w.add_topic('/hair/points', 'sensor_msgs/msg/PointCloud2')
        w.add_topic('/other', 'sensor_msgs/msg/PointCloud2')
        for k in range(3):
            stamp = 10 ** 9 + 5 * k
            w.write('/hair/points', 100 + k, strands_to_pointcloud2_cdr(
                strands[k], frame_id='w', stamp_ns=stamp))
            w.write('/other', 100 + k, strands_to_pointcloud2_cdr(strands[k][:1], frame_id='w'))
    got = list(bag_io.cloud_messages(tmp_path / 'c.mcap'))
    assert [t for t, _ in got] == [10 ** 9, 10 ** 9 + 5, 10 ** 9 + 10]
    for k, (_, msg) in enumerate(got):
        np.testing.assert_array_equal(pointcloud2_to_strands(msg)[0],
                                      strands[k].astype(np.float32).astype(np.float64))
