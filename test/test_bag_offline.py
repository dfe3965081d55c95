"""hair_sim_bag run: import -> run -> read back (MCAP and sqlite3), the hair in the bag equals
the simulator driven directly, determinism, settings files, TF input, and every bad input."""
import os
import re
from pathlib import Path
import subprocess
import sys

import numpy as np
import pytest

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import main
from hair_tracking.bags.offline import load_settings, Progress, run_bag, RunOptions, Schedule
from hair_tracking.simulator import HairSimulator
from msg_adapters.pointcloud import pointcloud2_to_strands

from recordings import write_walk_bag

ROOT = Path(__file__).resolve().parents[1]
SMALL = ['groom.guides=6', 'groom.ghosts_per_guide=3', 'groom.guide_nodes=8',
         'groom.ghost_nodes=8', 'solver.settle_time=0.1']


def _small_args():
    out = []
    for s in SMALL:
        out += ['--set', s]
    return out


def _settings(**extra):
    from hair_tracking.bags.offline import parse_overrides
    values = parse_overrides(SMALL)
    values.update(extra)
    return load_settings(overrides=values)


def _messages(path, topic):
    """[(log_ns, raw bytes)] of ``topic``, read with the plain rosbags Reader (independent of
    bag_io) and the ROS 2 Jazzy typestore."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    with AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        conns = [c for c in r.connections if c.topic == topic]
        if not conns:                    # (an empty filter would mean every topic)
            return []
        return [(t, bytes(raw)) for _, t, raw in r.messages(connections=conns)]


def _decode(path, topic):
    from rosbags.typesys import get_typestore, Stores
    ts = get_typestore(Stores.ROS2_JAZZY)
    msgtype = {'/hair/points': 'sensor_msgs/msg/PointCloud2',
               '/hair/markers': 'visualization_msgs/msg/MarkerArray',
               '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
               '/head_pose': 'geometry_msgs/msg/PoseStamped'}[topic]
    return [(t, ts.deserialize_cdr(raw, msgtype)) for t, raw in _messages(path, topic)]


def _cloud_strands(msg):
    """Strands of a rosbags PointCloud2, decoded by hand from its declared fields."""
    assert [f.name for f in msg.fields][:3] == ['x', 'y', 'z']
    assert all(f.datatype == 7 for f in msg.fields[:3])          # FLOAT32
    raw = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.row_step)
    rows = raw[:, :msg.width * msg.point_step].reshape(msg.height, msg.width, msg.point_step)
    out = np.empty((msg.height, msg.width, 3))
    for k, f in enumerate(msg.fields[:3]):
        out[:, :, k] = np.ascontiguousarray(rows[:, :, f.offset:f.offset + 4]).view('<f4')[..., 0]
    return out


@pytest.fixture(autouse=True, scope='module')
def one_numba_thread():
    """Tiny test scenes run serially: on a busy 2-core machine a parallel kernel call can wait
    milliseconds at its barrier.  Results do not depend on it (deterministic kernels)."""
    import numba
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)


@pytest.fixture(scope='module')
def walk_bag(tmp_path_factory):
    """The first 1.5 s of the bundled CMU walk bag."""
    return write_walk_bag(tmp_path_factory.mktemp('walk') / 'walk.mcap', 1.5)


def _reference(bag, settings, every_pose=False):
    """Drive HairSimulator directly at the bag's stamps; frames where the run publishes."""
    hp = bag_io.read_head_poses(bag)
    sim = HairSimulator(settings.scene)
    period = int(round(1e9 / settings.publish_rate_hz))
    nxt = None
    frames = []
    for t, p, q in zip(hp.t_ns, hp.position, hp.quaternion):
        sim.push_pose(int(t), p, q)
        sim.advance_to(int(t))
        due = every_pose or nxt is None or t >= nxt
        if nxt is None:
            nxt = int(t) + period
        elif t >= nxt:
            nxt += ((int(t) - nxt) // period + 1) * period
        if due:
            f = sim.frame()
            frames.append((f.t_ns, f.strands.copy()))
    return hp, frames


@pytest.mark.parametrize('name', ['out.mcap', 'out_sqlite'])
def test_import_run_read_back(walk_bag, tmp_path, name, capsys):
    out = tmp_path / name
    extra = [] if name.endswith('.mcap') else ['--storage', 'sqlite3']
    assert main(['run', str(walk_bag), '-o', str(out), '-q'] + _small_args() + extra) == 0
    text = capsys.readouterr().out
    assert 'real-time factor' in text and 'max stretch' in text and 'poses rejected: 0' in text
    assert re.search(r'frames written: [1-9]\d* \([0-9.]+ ms of the loop per frame\)', text)
    assert re.search(r'= [0-9.]+ ms per pose', text)
    if name.endswith('_sqlite'):
        assert any(p.suffix == '.db3' for p in out.iterdir())
    settings = _settings()
    hp, ref = _reference(walk_bag, settings)
    assert 40 <= len(ref) <= 50                     # 1.5 s at publish_rate_hz = 30
    clouds = _decode(out, '/hair/points')
    markers = _decode(out, '/hair/markers')
    assert len(clouds) == len(markers) == len(ref)
    for (log_t, msg), (t_ref, strands) in zip(clouds, ref):
        stamp = msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
        assert stamp == t_ref and msg.header.frame_id == 'world'
        assert msg.height == 18 and msg.width == 8              # 6 guides x 3 ghosts, 8 nodes
        got = _cloud_strands(msg)
        np.testing.assert_array_equal(got, strands.astype(np.float32).astype(np.float64))
        np.testing.assert_array_equal(pointcloud2_to_strands(msg)[0], got)
        assert log_t in set(hp.log_ns.tolist())                 # logged at the pose's time
    # markers: one LINE_LIST of all segments, float64 exact, DELETEALL first only once
    first = markers[0][1].markers
    assert [m.action for m in first] == [3, 0]
    assert all([m.action for m in mk.markers] == [0] for _, mk in markers[1:])
    last = markers[-1][1].markers[-1]
    pts = np.array([[p.x, p.y, p.z] for p in last.points])
    seg = np.stack([ref[-1][1][:, :-1], ref[-1][1][:, 1:]], axis=2).reshape(-1, 3)
    np.testing.assert_array_equal(pts, seg)
    # diagnostics and the head pose used
    diags = _decode(out, '/diagnostics')
    assert diags and diags[0][1].status[0].name == 'hair_sim: hair simulation'
    keys = {kv.key for kv in diags[-1][1].status[0].values}
    assert {'max_stretch', 'penetration_m', 'substeps', 'poses_rejected'} <= keys
    poses = _decode(out, '/head_pose')
    assert len(poses) == len(hp)
    np.testing.assert_array_equal([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                                   for _, m in poses], hp.position)


def test_deterministic_output(walk_bag, tmp_path):
    settings = _settings()
    a, b = tmp_path / 'a.mcap', tmp_path / 'b'
    sa = run_bag(walk_bag, a, settings, RunOptions(duration_s=0.8))
    sb = run_bag(walk_bag, b, settings, RunOptions(duration_s=0.8, storage='sqlite3'))
    assert sa.frames == sb.frames > 0
    for topic in ('/hair/points', '/hair/markers', '/diagnostics', '/head_pose'):
        ma, mb = _messages(a, topic), _messages(b, topic)
        assert len(ma) == len(mb) > 0
        assert ma == mb, topic                      # same log times, identical bytes


def test_every_pose_params_file_and_head_frame_output(walk_bag, tmp_path):
    params = tmp_path / 'hair_sim.yaml'
    params.write_text('hair_sim:\n  ros__parameters:\n    publish_rate_hz: 10.0\n'
                      '    marker_style: line_strips\n    output_frame: head\n'
                      '    cloud_fields: xyz_rgb\n'
                      '    groom:\n      guides: 4\n      ghosts_per_guide: 0\n'
                      '      guide_nodes: 6\n    solver:\n      settle_time: 0.0\n')
    out = tmp_path / 'ten_hz.mcap'
    assert main(['run', str(walk_bag), '-o', str(out), '--params', str(params), '-q',
                 '--duration', '1.0', '--no-diagnostics']) == 0
    clouds = _decode(out, '/hair/points')
    assert 9 <= len(clouds) <= 11                    # 10 Hz over 1 s
    assert clouds[0][1].header.frame_id == 'head' and clouds[0][1].height == 4
    assert [f.name for f in clouds[0][1].fields] == ['x', 'y', 'z', 'rgb']
    assert clouds[0][1].point_step == 16
    mk = _decode(out, '/hair/markers')[-1][1]
    assert [m.type for m in mk.markers] == [4] * 4   # one LINE_STRIP per guide
    assert not _messages(out, '/diagnostics')
    every = tmp_path / 'every.mcap'
    s = run_bag(walk_bag, every, _settings(), RunOptions(duration_s=0.5, every_pose=True,
                                                         markers=False, head_pose=False))
    assert s.frames == s.poses == len(_messages(every, '/hair/points'))
    assert not _messages(every, '/hair/markers')


def test_tf_input_with_head_frame(tmp_path):
    t = 10 ** 9 + np.arange(40) * 10 ** 7
    p = np.zeros((40, 3)) + [0.0, 0.0, 1.6]
    p[:, 0] = np.linspace(0, 0.3, 40)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (40, 1))
    src = tmp_path / 'tf.mcap'
    bag_io.write_head_pose_bag(src, t, p, q, kind='tf', frame_id='map', child_frame_id='face_3')
    out = tmp_path / 'out.mcap'
    s = run_bag(src, out, _settings(), RunOptions(head_frame='face_3'))
    assert s.poses == 40 and s.frames > 5
    assert _decode(out, '/hair/points')[0][1].header.frame_id == 'map'


def test_schedule_skips_missed_ticks_and_restarts_on_backwards_time():
    s = Schedule(100)
    due = [t for t in (0, 50, 99, 100, 150, 420, 450, 500, 510, 20, 60, 120) if s.due(t)]
    assert due == [0, 100, 420, 500, 20, 120]


def test_progress_bar_only_on_a_terminal():
    class Tty:
        def __init__(self, tty):
            self.text, self.tty = '', tty

        def isatty(self):
            return self.tty

        def write(self, s):
            self.text += s

        def flush(self):
            pass
    on, off = Tty(True), Tty(False)
    for stream in (on, off):
        bar = Progress(10, stream=stream)
        for i in range(1, 11):
            bar.update(i, force=True)
        bar.close()
    assert '\r' in on.text and '100.0%' in on.text and '10/10' in on.text
    assert off.text == ''


# ------------------------------------------------------------------ bad input
def _tree(path):
    return sorted(os.listdir(path))


def test_run_bad_inputs_give_message_and_code(walk_bag, tmp_path, capsys):
    chatter = tmp_path / 'chatter.mcap'
    ts = bag_io.typestore()
    with bag_io.BagWriter(chatter) as w:
        w.add_topic('/chatter', 'std_msgs/msg/String')
        w.write('/chatter', 1, ts.serialize_cdr(ts.types['std_msgs/msg/String'](data='x'),
                                                'std_msgs/msg/String'))
    tf = tmp_path / 'tf.mcap'
    bag_io.write_head_pose_bag(tf, [10 ** 9, 2 * 10 ** 9], np.zeros((2, 3)),
                               [[0, 0, 0, 1.0]] * 2, kind='tf', child_frame_id='face_1')
    corrupt = tmp_path / 'corrupt.mcap'
    corrupt.write_bytes(Path(walk_bag).read_bytes()[:100])     # cut before any message
    text = tmp_path / 'notes.txt'
    text.write_text('not a bag\n')
    exists = tmp_path / 'exists.mcap'
    exists.write_bytes(b'keep me')
    cases = [
        ([str(tmp_path / 'missing.mcap')], 3, 'no such file'),
        ([str(text)], 3, 'not a bag'),
        ([str(corrupt)], 3, 'corrupt'),
        ([str(chatter)], 4, '/chatter'),
        ([str(tf), '--head-frame', 'face_9'], 4, 'face_1'),
        ([str(walk_bag), '--topic', '/tf'], 4, '/head_pose'),
        ([str(walk_bag), '--set', 'groom.guides=-3'], 2, 'groom.guides'),
        ([str(walk_bag), '--scene', 'no_such_preset'], 2, 'no_such_preset'),
    ]
    before = _tree(tmp_path)
    for k, (args, code, words) in enumerate(cases):
        out = tmp_path / f'out{k}.mcap'
        assert main(['run'] + args + ['-o', str(out), '-q']) == code, args
        err = capsys.readouterr().err
        assert words in err and 'Traceback' not in err, (args, err)
        assert err.startswith('hair_sim_bag run: error: ')
        assert _tree(tmp_path) == before                         # nothing left behind
    assert main(['run', str(walk_bag), '-o', str(exists), '-q']) == 5
    assert 'already exists' in capsys.readouterr().err
    assert exists.read_bytes() == b'keep me'


def test_console_errors_have_no_traceback(tmp_path):
    """As a separate process (what a user sees): one line on stderr, the exit code."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for args, code in ((['run', str(tmp_path / 'nope.mcap'), '-o', str(tmp_path / 'o')], 3),
                       (['import', str(tmp_path / 'nope.bvh'), '-o', str(tmp_path / 'o')], 3),
                       (['run', '-o'], 2)):
        proc = subprocess.run([sys.executable, '-m', 'hair_tracking.ros.bag_cli'] + args,
                              capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
        assert proc.returncode == code, proc.stderr
        assert 'Traceback' not in proc.stderr and 'error' in proc.stderr
    assert not any(tmp_path.iterdir())


def test_offline_runs_need_no_rclpy():
    """`hair_sim_bag run` works without a ROS installation: its modules, and the executable's
    module with play and record in its parser, never import rclpy."""
    code = ('import sys, hair_tracking.bags.offline, hair_tracking.output.strand_colors, '
            'hair_tracking.ros.bag_cli; sys.exit(1 if "rclpy" in sys.modules else 0)')
    assert subprocess.run([sys.executable, '-c', code], timeout=120).returncode == 0


@pytest.mark.parametrize('frame_id', ['w' * k for k in range(9)] + ['map_frame_1', 'ünïcode'])
def test_pose_stamped_bytes_match_the_rosbags_serializer(frame_id):
    """The direct CDR writer of the head-pose copies gives the bytes rosbags' own serializer
    gives (every frame-name length mod 8, so each padding case is covered), and they read
    back to the same pose."""
    from hair_tracking.bags.offline import pose_stamped_bytes
    rng = np.random.default_rng(len(frame_id))
    t = 1_700_000_123_456_789_012 // 1000
    p, q = rng.normal(size=3), rng.normal(size=4)
    mt, msg = bag_io.head_pose_message('pose', t, p, q, frame_id, '')
    want = bytes(bag_io.typestore().serialize_cdr(msg, mt))
    got = pose_stamped_bytes(t, p, q, frame_id)
    assert got == want
    back = bag_io.typestore().deserialize_cdr(got, mt)
    assert back.header.frame_id == frame_id and back.pose.orientation.w == q[3]
    with pytest.raises(bag_io.BagError, match='int32'):
        pose_stamped_bytes(-1, p, q, frame_id)


def test_a_run_stopped_early_counts_only_the_recording_it_ran(walk_bag, tmp_path):
    calls = [0]

    def stop_at_pose_30():
        calls[0] += 1
        return calls[0] > 30
    summary = run_bag(str(walk_bag), str(tmp_path / 'stopped.mcap'), _settings(),
                      should_stop=stop_at_pose_30)
    hp = bag_io.read_head_poses(walk_bag)
    assert summary.stopped_after == 30 and summary.bag_duration_s == pytest.approx(1.5, abs=0.02)
    assert summary.run_duration_s == pytest.approx((hp.t_ns[29] - hp.t_ns[0]) * 1e-9)
    assert f'({summary.run_duration_s:.2f} s of recording in' in summary.text()
    full = run_bag(str(walk_bag), str(tmp_path / 'full.mcap'), _settings())
    assert full.run_duration_s == pytest.approx(full.bag_duration_s)
