"""The hair_sim node over real DDS, in-process: inputs, outputs, time handling, reset, CLI.

Every test gets its own rclpy Context on its own domain id (20-34 here; test_node_params.py
uses 35-49), discovery limited to localhost (conftest.py), and every wait is bounded.
"""
import itertools
import os
import subprocess
import sys
import time
from types import SimpleNamespace

import numpy as np
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, TransformStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.output.strand_colors import strand_colors
from hair_tracking.ros import health as health_module
from hair_tracking.ros.node import HairSimNode
from hair_tracking.simulator import HairSimulator
from msg_adapters.pointcloud import pointcloud2_to_strands
from msg_adapters.pose import pose_stamped_msg, transform_stamped_msg
from msg_adapters.stamps import time_msg, time_to_ns

from node_process import until_ready_then_ctrl_c

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_DOMAINS = itertools.cycle(range(20, 35))

# A small scene so the suite stays quick: 4 guides x 3 ghosts, 6 nodes.
SMALL = {
    'groom.guides': 4, 'groom.ghosts_per_guide': 3, 'groom.guide_nodes': 6,
    'groom.ghost_nodes': 6, 'solver.settle_time': 0.05, 'publish_rate_hz': 50.0,
    'stale_timeout': 30.0,       # no idle stepping unless a test asks for it
}


def yaw_quat(angle):
    return [0.0, 0.0, float(np.sin(angle / 2)), float(np.cos(angle / 2))]


class Harness:
    """A hair_sim node and a probe node in one context, spun by one executor."""

    def __init__(self, overrides=None, domain_id=None, work_clock=None):
        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=next(_DOMAINS) if domain_id is None
                   else domain_id)
        values = dict(SMALL)
        values.update(overrides or {})
        clock = {} if work_clock is None else {'work_clock': work_clock}
        self.node = HairSimNode(context=self.ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()], **clock)
        self.probe = Node('probe', context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        self.clouds, self.markers = [], []

    def listen(self, points=True, markers=True):
        if points:
            self.probe.create_subscription(PointCloud2, 'hair/points', self.clouds.append, 10)
        if markers:
            self.probe.create_subscription(MarkerArray, 'hair/markers', self.markers.append, 10)
        outs = self.node.outputs
        self.spin_until(lambda: (not points or outs['points'].wanted())
                        and (not markers or outs['markers'].wanted()), what='subscriptions')

    def spin_until(self, cond, timeout=10.0, what='condition'):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.005)
            if cond():
                return
        raise AssertionError(f'timed out after {timeout} s waiting for {what}')

    def spin_for(self, seconds):
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.005)

    def pose_publisher(self, msg_type=PoseStamped, topic='head_pose', qos=None):
        pub = self.probe.create_publisher(msg_type, topic, qos or 10)
        self.spin_until(lambda: pub.get_subscription_count() > 0, what=f'{topic} match')
        return pub

    def send(self, pub, msg, expect_accepted=True):
        """Publish a pose and spin until the node has taken it (or dropped it)."""
        track = self.node.sim.track.counters
        before = (track['accepted'] + track['reset_backwards'] + track['reset_teleport'],
                  self.node.rejected)

        def taken():
            now = (track['accepted'] + track['reset_backwards'] + track['reset_teleport'],
                   self.node.rejected)
            return now[0] > before[0] if expect_accepted else now[1] > before[1]
        pub.publish(msg)
        self.spin_until(taken, what='the pose to be processed')

    def cloud_at(self, t_ns):
        """Spin until a cloud stamped ``t_ns`` arrives; returns it."""
        def find():
            return next((c for c in reversed(self.clouds)
                         if time_to_ns(c.header.stamp) == t_ns), None)
        self.spin_until(lambda: find() is not None, what=f'a cloud stamped {t_ns}')
        return find()

    def markers_at(self, t_ns):
        def find():
            return next((m for m in reversed(self.markers) if m.markers and
                         time_to_ns(m.markers[-1].header.stamp) == t_ns), None)
        self.spin_until(lambda: find() is not None, what=f'markers stamped {t_ns}')
        return find()

    def close(self):
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def harness(request):
    made = []

    def make(work_clock=None, **overrides):
        h = Harness(overrides, work_clock=work_clock)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


def grid_times(h, count, start_s=1.0, step_substeps=4):
    """Stamps on the simulator's dt grid, so each frame lands exactly on its pose."""
    dt_ns = h.node.sim.dt_ns
    t0 = int(start_s * 1e9)
    return [t0 + k * step_substeps * dt_ns for k in range(count)]


def roots_in_head(points, position, quaternion):
    """Root points (S, 3) of an (S, N, 3) cloud expressed in the head frame."""
    R = quat_to_matrix(np.asarray(quaternion, dtype=float))
    return (points[:, 0] - np.asarray(position)) @ R


# ====================================================================== outputs
def test_poses_give_clouds_and_markers_whose_roots_follow_the_head(harness):
    h = harness()
    h.listen()
    pub = h.pose_publisher()
    times = grid_times(h, 12)
    head_roots = []
    for k, t in enumerate(times):
        p = [0.02 * k, -0.01 * k, 0.005 * k]
        q = yaw_quat(0.1 * k)
        h.send(pub, pose_stamped_msg(t, p, q, 'odom'))
        cloud = h.cloud_at(t)
        assert cloud.header.frame_id == 'odom'
        assert cloud.height == 12 and cloud.width == 6         # one row per ghost strand
        assert [f.name for f in cloud.fields] == ['x', 'y', 'z', 'strand', 'rgb']
        pts, ids = pointcloud2_to_strands(cloud)
        assert ids.tolist() == list(range(12))
        head_roots.append(roots_in_head(pts, p, q))
        arr = h.markers_at(t)
        lines = [m for m in arr.markers if m.action == Marker.ADD]
        assert len(lines) == 1 and lines[0].type == Marker.LINE_LIST
        assert lines[0].header.frame_id == 'odom'
        seg = np.array([[pt.x, pt.y, pt.z] for pt in lines[0].points]).reshape(12, 5, 2, 3)
        np.testing.assert_allclose(seg[:, 0, 0], pts[:, 0], atol=1e-5)   # same roots
        np.testing.assert_allclose(seg[:, 1:, 0], seg[:, :-1, 1])          # strands unbroken
    # The roots ride with the head: in the head frame they never move, in the world they do.
    head_roots = np.array(head_roots)
    np.testing.assert_allclose(head_roots, head_roots[:1].repeat(len(times), 0), atol=2e-5)
    assert np.ptp(head_roots[0], axis=0).max() > 0.02          # distinct roots on the scalp
    np.testing.assert_allclose(head_roots[0], h.node.sim.ghosts.rest[:, 0], atol=2e-5)


def test_first_markers_clear_old_ones_and_colours_reach_the_cloud(harness):
    h = harness()
    h.listen()
    pub = h.pose_publisher()
    t = grid_times(h, 1)[0]
    h.send(pub, pose_stamped_msg(t, [0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0], 'world'))
    h.markers_at(t)
    first = h.markers[0].markers
    assert first[0].action == Marker.DELETEALL and first[0].header.frame_id == 'world'
    assert all(m.action != Marker.DELETEALL for a in h.markers[1:] for m in a.markers)
    lifetime = first[1].lifetime.sec + first[1].lifetime.nanosec * 1e-9
    assert lifetime == pytest.approx(3 / 50.0, abs=1e-6)       # 3 publishing periods
    cloud = h.cloud_at(t)
    raw = np.frombuffer(bytes(cloud.data), dtype=np.uint8)
    raw = raw.reshape(cloud.height, cloud.width, cloud.point_step)
    rgb = raw[:, :, 16:20].copy().view('<u4')[..., 0]
    want = np.rint(strand_colors(12, h.node.settings.marker_color)[:, :3] * 255).astype(int)
    got = np.stack([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255], axis=-1)
    assert (got == got[:, :1]).all()                           # one colour per strand
    np.testing.assert_array_equal(got[:, 0], want)


@pytest.mark.parametrize('reliability', [ReliabilityPolicy.BEST_EFFORT,
                                         ReliabilityPolicy.RELIABLE])
def test_best_effort_and_reliable_pose_publishers_both_connect(harness, reliability):
    h = harness()
    h.listen(markers=False)
    qos = QoSProfile(depth=5, reliability=reliability)
    pose_pub = h.pose_publisher(PoseStamped, 'head_pose', qos)
    tf_pub = h.pose_publisher(TransformStamped, 'head_transform', qos)
    t0, t1 = grid_times(h, 2)
    h.send(pose_pub, pose_stamped_msg(t0, [0.1, 0.0, 0.0], yaw_quat(0.0), 'map'))
    assert h.cloud_at(t0).header.frame_id == 'map'
    h.send(tf_pub, transform_stamped_msg(t1, [0.1, 0.0, 0.0], yaw_quat(0.0), 'odom', 'face_7'))
    assert h.cloud_at(t1).header.frame_id == 'odom'


@pytest.mark.parametrize('output_frame', ['fixed', 'head'])
def test_clouds_carry_the_simulated_ghosts_through_rcl_or_rclpy_alike(harness, output_frame):
    """The cloud is written from the tracker's own layout into a buffer the node keeps, and
    published through rclpy (the default) or rcl (publish_through_rcl, opt-in): either way it holds
    exactly the ghosts of the simulator's frame, as float32."""
    h = harness(output_frame=output_frame, publish_guides=True)
    h.listen(markers=False)
    guides = []
    h.probe.create_subscription(PointCloud2, 'hair/guides/points', guides.append, 10)
    h.spin_until(lambda: h.node.outputs['guide_points'].wanted(), what='the guide cloud match')
    pub = h.pose_publisher()
    buffers = set()
    for k, t in enumerate(grid_times(h, 6)):
        through_rcl = k % 2 == 0
        assert h.node.set_parameters([Parameter('publish_through_rcl',
                                                value=through_rcl)])[0].successful
        h.send(pub, pose_stamped_msg(t, [0.03 * k, 0.01, 0.0], yaw_quat(0.4 * k), 'odom'))
        cloud = h.cloud_at(t)
        assert h.node.outputs['points'].raw.direct == through_rcl
        frame = h.node.sim.frame(head_frame=output_frame == 'head')
        pts, ids = pointcloud2_to_strands(cloud, dtype=np.float32)
        if output_frame == 'fixed':
            np.testing.assert_array_equal(pts, frame.strands.astype(np.float32))
        else:          # R^T (x - p) against numpy's (x - p) @ R: rounding apart
            np.testing.assert_allclose(pts, frame.strands, rtol=1e-6, atol=1e-7)
        assert ids.tolist() == list(range(12)) and cloud.is_dense
        h.spin_until(lambda: any(time_to_ns(g.header.stamp) == t for g in guides),
                     what='the guide cloud')
        g = next(g for g in guides if time_to_ns(g.header.stamp) == t)
        np.testing.assert_allclose(pointcloud2_to_strands(g)[0], frame.guides, atol=1e-6)
        buffers.add(h.node.outputs['points'].cached.ctypes.data)
    assert len(buffers) == 1                     # one buffer, rewritten frame after frame
    assert h.node.frames_built == 0              # no markers wanted: no frame was built


def test_cloud_fields_change_live_and_the_rows_still_give_the_strands(harness):
    """cloud_fields leaves strand and rgb out of both clouds from the next frame on; the
    coordinates are the simulator's either way, and an unknown value is refused."""
    h = harness(publish_guides=True)
    h.listen(markers=False)
    guides = []
    h.probe.create_subscription(PointCloud2, 'hair/guides/points', guides.append, 10)
    h.spin_until(lambda: h.node.outputs['guide_points'].wanted(), what='the guide cloud match')
    pub = h.pose_publisher()
    refused = h.node.set_parameters([Parameter('cloud_fields', value='xyz_colour')])[0]
    assert not refused.successful and 'xyz_strand_rgb' in refused.reason
    expect = {'xyz_strand_rgb': (['x', 'y', 'z', 'strand', 'rgb'], 20),
              'xyz': (['x', 'y', 'z'], 12), 'xyz_rgb': (['x', 'y', 'z', 'rgb'], 16),
              'xyz_strand': (['x', 'y', 'z', 'strand'], 16)}
    for k, (value, t) in enumerate(zip(expect, grid_times(h, len(expect)))):
        assert h.node.set_parameters([Parameter('cloud_fields', value=value)])[0].successful
        h.send(pub, pose_stamped_msg(t, [0.02 * k, 0.0, 0.01], yaw_quat(0.3 * k), 'odom'))
        cloud = h.cloud_at(t)
        names, step = expect[value]
        assert [f.name for f in cloud.fields] == names and cloud.point_step == step
        pts, ids = pointcloud2_to_strands(cloud, dtype=np.float32)
        frame = h.node.sim.frame()
        np.testing.assert_array_equal(pts, frame.strands.astype(np.float32))
        assert ids.tolist() == list(range(12))
        h.spin_until(lambda: any(time_to_ns(g.header.stamp) == t for g in guides),
                     what='the guide cloud')
        g = next(g for g in guides if time_to_ns(g.header.stamp) == t)
        assert [f.name for f in g.fields] == names
        np.testing.assert_allclose(pointcloud2_to_strands(g)[0], frame.guides, atol=1e-6)


@pytest.mark.parametrize('overrides, shape', [
    ({'groom.ghosts_per_guide': 0}, (4, 6)),                    # the guides are the hair
    ({'output.curve': 'catmull_rom', 'output.points_per_strand': 9}, (12, 9)),   # curves
])
def test_clouds_without_the_tracker_layout_are_written_from_the_frame(harness, overrides,
                                                                      shape):
    h = harness(output_frame='head', **overrides)
    h.listen(markers=False)
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 3)):
        h.send(pub, pose_stamped_msg(t, [0.02 * k, 0.0, 0.01], yaw_quat(0.3 * k), 'odom'))
        cloud = h.cloud_at(t)
        assert (cloud.height, cloud.width) == shape
        pts, ids = pointcloud2_to_strands(cloud)
        np.testing.assert_allclose(pts, h.node.sim.frame(head_frame=True).strands,
                                   rtol=1e-6, atol=1e-6)
        assert ids.tolist() == list(range(shape[0]))


def test_head_output_frame_uses_the_child_frame_and_keeps_roots_still(harness):
    h = harness(output_frame='head')
    h.listen(markers=False)
    pub = h.pose_publisher(TransformStamped, 'head_transform')
    clouds = []
    for k, t in enumerate(grid_times(h, 4)):
        h.send(pub, transform_stamped_msg(t, [0.05 * k, 0.0, 0.0], yaw_quat(0.3 * k), 'odom',
                                          'head_link'))
        clouds.append(h.cloud_at(t))
    assert {c.header.frame_id for c in clouds} == {'head_link'}
    roots = [pointcloud2_to_strands(c)[0][:, 0] for c in clouds]
    for r in roots:
        np.testing.assert_allclose(r, h.node.sim.ghosts.rest[:, 0], atol=2e-5)


def test_nobody_subscribed_nothing_is_encoded(harness):
    h = harness(publish_guides=True)
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 6)):
        h.send(pub, pose_stamped_msg(t, [0.01 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))
    h.spin_for(0.2)                                  # ten publishing periods
    assert h.node.sim.counters.substeps > 0
    assert h.node.frames_built == 0
    assert {k: o.encoded for k, o in h.node.outputs.items()} == {
        'points': 0, 'markers': 0, 'guide_points': 0, 'guide_markers': 0}
    # one subscriber: only its output is built
    guides = []
    h.probe.create_subscription(PointCloud2, 'hair/guides/points', guides.append, 10)
    h.spin_until(lambda: guides, what='a guide cloud')
    assert h.node.outputs['guide_points'].encoded > 0
    assert guides[-1].height == 4 and guides[-1].width == 6     # the guides, one row each
    assert {k: o.encoded for k, o in h.node.outputs.items()
            if k != 'guide_points'} == {'points': 0, 'markers': 0, 'guide_markers': 0}


def test_publishing_has_its_own_rate_and_resends_an_unchanged_frame(harness):
    h = harness(publish_rate_hz=40.0)
    h.listen(markers=False)
    pub = h.pose_publisher()
    t = grid_times(h, 1)[0]
    h.send(pub, pose_stamped_msg(t, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    h.cloud_at(t)
    n0, enc0 = len(h.clouds), h.node.outputs['points'].encoded
    h.spin_until(lambda: len(h.clouds) >= n0 + 4, what='clouds without new poses')
    # the stream is not stale yet (0.25 s): same frame resent from the cache, not rebuilt
    assert h.node.outputs['points'].encoded == enc0
    assert bytes(h.clouds[-1].data) == bytes(h.clouds[n0 - 1].data)


# ====================================================================== time
def test_publish_on_pose_counts_stream_time_not_the_wall_clock(harness):
    """``publish_on_pose`` sends a pose's frame once 0.9 publishing periods of *stamps* have
    passed, however close together the poses were handled (a burst from DDS must not lose a
    frame, as a wall-clock cap did); time going back makes the next frame due."""
    h = harness(**{'publish_on_pose': True, 'publish_rate_hz': 100.0})
    sim = h.node.sim
    due = []
    for step_ms in (0, 5, 5, 9, 1, 20, -100):       # handled back to back, microseconds apart
        sim.time_ns = (sim.time_ns or 10 ** 9) + step_ms * 1_000_000
        due.append(h.node.intake.pose_frame_due())
    # 9 ms of stamps is the 0.9-period threshold at 100 Hz
    assert due == [True, False, True, True, False, True, True]


def test_publish_on_pose_timer_does_not_repeat_the_poses_frames(harness):
    """With ``publish_on_pose``, the publishing timer stays quiet while the poses' own frames
    keep its rate (a resend would only repeat them) and takes over once they stop."""
    h = harness(**{'publish_on_pose': True, 'publish_rate_hz': 20.0})
    h.listen(markers=False)
    pub = h.pose_publisher()
    t = grid_times(h, 1)[0]
    h.send(pub, pose_stamped_msg(t, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    h.cloud_at(t)
    node, out = h.node, h.node.outputs['points']
    publishing = node.publishing
    period = node.settings.publish_period
    sent = out.published
    # the timer's tick 0.6 periods after the pose's frame: not repeated
    publishing.last_publish = publishing.pose_publish_at = time.monotonic() - 0.6 * period
    publishing.on_timer()
    assert out.published == sent
    # no pose frame for 1.1 periods: the timer resends the frame (from the cache)
    publishing.last_publish = publishing.pose_publish_at = time.monotonic() - 1.1 * period
    publishing.on_timer()
    assert out.published == sent + 1 and out.encoded == 1
    # without publish_on_pose the timer keeps the rate itself, 0.6 periods after a frame
    node.set_parameters([Parameter('publish_on_pose', value=False)])
    publishing.last_publish = publishing.pose_publish_at = time.monotonic() - 0.6 * period
    publishing.on_timer()
    assert out.published == sent + 2


def test_nan_poses_are_dropped_and_counted(harness):
    h = harness()
    pub = h.pose_publisher()
    t0, t1, t2 = grid_times(h, 3)
    h.send(pub, pose_stamped_msg(t0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    head = h.node.sim.head.position.copy()
    x = h.node.sim.frame().ghosts
    h.send(pub, pose_stamped_msg(t1, [np.nan, 0.0, 0.0], yaw_quat(0.0), 'world', check=False),
           expect_accepted=False)
    h.send(pub, pose_stamped_msg(t2, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], 'world',
                                 check=False), expect_accepted=False)
    assert h.node.rejected == 2
    assert h.node.sim.time_ns == t0 and h.node.sim.track.last_time == t0
    np.testing.assert_array_equal(h.node.sim.head.position, head)
    np.testing.assert_array_equal(h.node.sim.frame().ghosts, x)
    status = h.node.diagnostics()
    values = {kv.key: kv.value for kv in status.values}
    assert values['poses_rejected'] == '2'
    assert status.level == DiagnosticStatus.WARN and 'rejected' in status.message


def test_stamp_zero_means_now_and_time_going_backwards_resets(harness):
    h = harness()
    h.listen(markers=False)
    pub = h.pose_publisher()
    before = time.time_ns()
    h.send(pub, pose_stamped_msg(0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    after = time.time_ns()
    assert before <= h.node.sim.track.last_time <= after        # stamped with the node clock
    resets = h.node.sim.counters.resets
    back = 5 * 10**9
    h.send(pub, pose_stamped_msg(back, [0.2, 0.0, 0.0], yaw_quat(0.5), 'world'))
    assert h.node.sim.counters.resets == resets + 1
    assert h.node.sim.time_ns == back
    pts, _ = pointcloud2_to_strands(h.cloud_at(back))
    np.testing.assert_allclose(roots_in_head(pts, [0.2, 0.0, 0.0], yaw_quat(0.5)),
                               h.node.sim.ghosts.rest[:, 0], atol=2e-5)
    h.send(pub, pose_stamped_msg(back, [0.2, 0.0, 0.0], yaw_quat(0.5), 'world'))  # repeated
    assert h.node.sim.time_ns == back and h.node.intake.clock.offset_ns == 0


def test_stale_stream_holds_the_last_pose_and_the_hair_settles(harness):
    h = harness(stale_timeout=0.05)
    h.listen(markers=False)
    pub = h.pose_publisher()
    t0, t1 = grid_times(h, 2, step_substeps=12)
    h.send(pub, pose_stamped_msg(t0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    h.send(pub, pose_stamped_msg(t1, [0.3, 0.0, 0.0], yaw_quat(0.0), 'world'))   # a fast move
    h.cloud_at(t1)
    tips_then = h.node.sim.frame().ghosts[:, -1]
    h.spin_until(lambda: time_to_ns(h.clouds[-1].header.stamp) > t1 + 3 * 10**8,
                 what='clouds of the settling hair')
    stamps = [time_to_ns(c.header.stamp) for c in h.clouds]
    assert sorted(stamps) == stamps                           # stamps move on without poses
    assert h.node.sim.track.last_time == t1                   # ... and without new poses
    pts, _ = pointcloud2_to_strands(h.clouds[-1])
    np.testing.assert_allclose(roots_in_head(pts, [0.3, 0.0, 0.0], yaw_quat(0.0)),
                               h.node.sim.ghosts.rest[:, 0], atol=2e-5)   # head held
    assert np.abs(h.node.sim.frame().ghosts[:, -1] - tips_then).max() > 1e-4   # the hair moved on
    status = h.node.diagnostics()
    assert status.level == DiagnosticStatus.WARN and 'stale' in status.message


def test_a_stream_resuming_behind_the_settled_hair_goes_on(harness):
    # stamps far slower than the node clock: the idle stepping runs ahead of them
    h = harness(stale_timeout=0.05)
    h.listen(markers=False)
    pub = h.pose_publisher()
    t0, t1, t2 = grid_times(h, 3)
    h.send(pub, pose_stamped_msg(t0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    h.spin_until(lambda: h.node.sim.time_ns > t1 + 10**8, what='idle stepping')
    h.send(pub, pose_stamped_msg(t1, [0.01, 0.0, 0.0], yaw_quat(0.0), 'world'))
    pts, _ = pointcloud2_to_strands(h.cloud_at(t1))            # stamped as the pose was
    np.testing.assert_allclose(roots_in_head(pts, [0.01, 0.0, 0.0], yaw_quat(0.0)),
                               h.node.sim.ghosts.rest[:, 0], atol=2e-5)
    before = h.node.sim.counters.substeps
    h.send(pub, pose_stamped_msg(t2, [0.02, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert h.node.sim.counters.substeps > before                # not frozen
    h.cloud_at(t2)


def test_use_sim_time_follows_the_clock(harness):
    h = harness(use_sim_time=True)
    h.listen(markers=False)
    clock_pub = h.probe.create_publisher(Clock, '/clock', 10)
    sim_now = [100 * 10**9]

    def tick():
        sim_now[0] += 10**7
        clock_pub.publish(Clock(clock=time_msg(sim_now[0])))
    h.probe.create_timer(0.01, tick)
    h.spin_until(lambda: h.node.get_clock().now().nanoseconds >= 100 * 10**9,
                 what='the node clock to follow /clock')
    pub = h.pose_publisher()
    h.send(pub, pose_stamped_msg(0, [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    first = h.node.sim.track.last_time
    assert 100 * 10**9 <= first <= sim_now[0]                  # "now" is the simulated clock
    h.spin_until(lambda: h.clouds, what='a cloud')             # timers run on /clock too
    stamp = time_to_ns(h.clouds[-1].header.stamp)
    assert 100 * 10**9 <= stamp <= sim_now[0]
    h.spin_until(lambda: h.node.get_clock().now().nanoseconds > first, what='/clock to move')
    h.send(pub, pose_stamped_msg(0, [0.01, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert first < h.node.sim.track.last_time <= sim_now[0]


# ====================================================================== service, tf
def test_reset_service_puts_the_hair_back_at_rest_at_the_current_head(harness):
    h = harness()
    pub = h.pose_publisher()
    times = grid_times(h, 8)
    for k, t in enumerate(times):                    # shake the head: the hair swings
        h.send(pub, pose_stamped_msg(t, [0.05 * (k % 2), 0.0, 0.0], yaw_quat(0.0), 'world'))
    final = [0.05 * ((len(times) - 1) % 2), 0.0, 0.0]
    fresh = HairSimulator(h.node.sim.scene)
    fresh.push_pose(times[-1], final, yaw_quat(0.0))  # rest shape, settled, carried there
    assert np.abs(h.node.sim.frame().ghosts - fresh.frame().ghosts).max() > 1e-6
    client = h.probe.create_client(Trigger, '/hair_sim/reset')
    h.spin_until(client.service_is_ready, what='the reset service')
    resets = h.node.sim.counters.resets
    future = client.call_async(Trigger.Request())
    h.spin_until(future.done, what='the reset response')
    assert future.result().success
    assert h.node.sim.counters.resets == resets + 1
    # 1e-8: the blend tracker keeps its rest offsets in float32
    np.testing.assert_allclose(h.node.sim.frame().ghosts, fresh.frame().ghosts, atol=1e-8)
    np.testing.assert_allclose(h.node.sim.guides.x, fresh.guides.x, atol=1e-9)
    assert not h.node.sim.ghost_tracker.velocities().any()


def test_tf_input_selects_the_head_by_name_or_prefix(harness):
    h = harness(use_tf=True)
    t0, t1, t2, t3 = grid_times(h, 4)

    def tf(t, child, x):
        return transform_stamped_msg(t, [x, 0.0, 0.0], yaw_quat(0.0), 'camera', child)
    node = h.node
    node.frames.on_tf(SimpleNamespace(transforms=[tf(t0, 'torso', 9.0), tf(t0, 'head', 0.1)]))
    assert node.sim.track.last_time == t0 and node.sim.head.position[0] == pytest.approx(0.1)
    node.set_parameters([Parameter('head_frame_prefix', value='face_')])
    node.frames.on_tf(SimpleNamespace(transforms=[tf(t1, 'head', 5.0), tf(t1, 'face_42', 0.12)]))
    assert node.intake.tf_child == 'face_42'
    assert node.sim.head.position[0] == pytest.approx(0.12)
    node.frames.on_tf(SimpleNamespace(transforms=[tf(t2, 'face_7', 3.0), tf(t2, 'face_42', 0.14)]))
    assert node.intake.tf_child == 'face_42'                   # locked on while it is fresh
    assert node.sim.head.position[0] == pytest.approx(0.14)
    node.intake.tf_seen_ns -= 10**11                            # face_42 went stale
    node.frames.on_tf(SimpleNamespace(transforms=[tf(t3, 'face_7', 0.16)]))
    assert node.intake.tf_child == 'face_7'
    assert node.sim.head.position[0] == pytest.approx(0.16)
    assert node.output_frame_id() == 'camera'
    node.set_parameters([Parameter('head_frame_prefix', value='person_')])
    t4 = t3 + 4 * node.sim.dt_ns
    node.frames.on_tf(SimpleNamespace(transforms=[tf(t4, 'face_7', 3.0),
                                                  tf(t4, 'person_1', 0.18)]))
    assert node.intake.tf_child == 'person_1'                  # a new prefix chooses again
    assert node.sim.head.position[0] == pytest.approx(0.18)


class TickClock:
    """An injected work clock: every read is ``tick`` seconds after the previous one, so the
    work the node measures depends on what it does, not on how fast the machine is."""

    def __init__(self, tick):
        self.tick = tick
        self.now = 0.0

    def __call__(self):
        self.now += self.tick
        return self.now


def test_load_shedding_tracks_once_per_pose_while_the_steps_do_not_fit(harness):
    """Poses one substep (4.2 ms) apart and a work clock on which every measured step takes
    milliseconds: no step fits 5 % of the period, so after two poses over a whole period the
    ghosts are tracked once per pose and the diagnostics say so (WARN).  When the work becomes
    tiny the full schedule comes back after a window of poses; switching the parameter off
    goes back to the scene's schedule on the next pose."""
    clock = TickClock(2e-3)
    # load shedding changes the paper tracker's schedule (the blend runs once per frame anyway)
    h = harness(work_clock=clock, **{'groom.guides': 4, 'groom.ghosts_per_guide': 2,
                                     'tracking.mode': 'paper', 'load_shedding_budget': 0.05})
    pub = h.pose_publisher()
    times = grid_times(h, 30, step_substeps=1)
    for k, t in enumerate(times[:4]):
        h.send(pub, pose_stamped_msg(t, [0.001 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert h.node.sim.track_once_per_call and h.node.shedder.switches == 1
    status = h.node.diagnostics()
    values = {kv.key: kv.value for kv in status.values}
    assert values['load_shedding'] == 'active' and status.level == DiagnosticStatus.WARN
    assert 'load shedding' in status.message
    clock.tick = 1e-9                       # now every step fits easily
    for k, t in enumerate(times[4:28]):
        h.send(pub, pose_stamped_msg(t, [0.001 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert not h.node.sim.track_once_per_call and h.node.shedder.switches == 2
    clock.tick = 2e-3
    h.send(pub, pose_stamped_msg(times[28], [0.0, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert h.node.set_parameters([Parameter('load_shedding', value=False)])[0].successful
    h.send(pub, pose_stamped_msg(times[29], [0.012, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert not h.node.sim.track_once_per_call
    values = {kv.key: kv.value for kv in h.node.diagnostics().values}
    assert values['load_shedding'] == 'off'


def test_load_shedding_stays_off_when_the_scene_already_tracks_once_per_pose(harness):
    """Nothing to shed (the scene tracks once per pose): however slow the steps, the flag stays
    off and the diagnostics do not warn about shedding."""
    h = harness(**{'groom.guides': 64, 'groom.ghosts_per_guide': 16,
                   'tracking.every_substep': False, 'load_shedding_budget': 0.05})
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 12, step_substeps=1)):
        h.send(pub, pose_stamped_msg(t, [0.001 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert not h.node.sim.track_once_per_call and h.node.shedder.switches == 0
    assert 'load shedding' not in h.node.diagnostics().message


def test_load_shedding_stays_off_with_the_blend_tracker(harness):
    """The blend tracker runs once per pose already: however slow the steps, nothing is shed."""
    h = harness(work_clock=TickClock(2e-3), **{'groom.guides': 4, 'groom.ghosts_per_guide': 2,
                                               'tracking.mode': 'blend',
                                               'load_shedding_budget': 0.05})
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 8, step_substeps=1)):
        h.send(pub, pose_stamped_msg(t, [0.001 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))
    assert not h.node.sim.track_once_per_call and h.node.shedder.switches == 0
    assert h.node.sim.ghost_tracker.stats['steps'] > 0


def test_diagnostics_are_published_with_the_step_numbers(harness):
    h = harness(diagnostics_rate_hz=20.0)
    got = []
    h.probe.create_subscription(DiagnosticArray, '/diagnostics', got.append, 10)
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 3)):
        h.send(pub, pose_stamped_msg(t, [0.01 * k, 0.0, 0.0], yaw_quat(0.0), 'world'))

    def current():
        for a in reversed(got):
            for s in a.status:
                values = {kv.key: kv.value for kv in s.values}
                if s.level == DiagnosticStatus.OK and \
                        values['substeps'] == str(h.node.sim.counters.substeps):
                    return values
    h.spin_until(lambda: current() is not None, what='an OK diagnostics message')
    values = current()
    for key in ('step_ms_last', 'publish_ms_last', 'substeps', 'substeps_dropped',
                'max_stretch', 'poses_rejected'):
        assert key in values
    assert int(values['substeps']) > 0
    assert float(values['step_ms_last']) > 0.0
    tracker = h.node.sim.ghost_tracker
    assert values['ghost_kernel'] == ('parallel' if tracker.stats['parallel'] else 'serial')
    assert 'cpu_steal_recent' not in values


def test_diagnostics_check_a_large_hair_a_part_per_report_in_turn(harness, monkeypatch):
    """Each report checks the stretch and head penetration of at most DIAG_AUDIT_STRANDS ghosts,
    the next part in turn, so reports stay cheap at any hair size and every ghost is checked
    once per round; the worst value of a round is the whole hair's."""
    monkeypatch.setattr(health_module, 'DIAG_AUDIT_STRANDS', 5)
    h = harness(**{'groom.guides': 4, 'groom.ghosts_per_guide': 3})
    pub = h.pose_publisher()
    for k, t in enumerate(grid_times(h, 3)):
        h.send(pub, pose_stamped_msg(t, [0.01 * k, 0.0, 0.0], yaw_quat(0.3 * k), 'world'))
    sim = h.node.sim
    ghosts = sim.ghosts.count
    assert ghosts == 12
    checked, stretch = [], []
    for _ in range(4):                      # 12 ghosts in parts of at most 5: 3 parts
        values = {kv.key: kv.value for kv in h.node.diagnostics().values}
        first, last = (int(v) for v in values['checked_ghosts'].split('-'))
        assert last - first + 1 <= 5
        checked.append((first, last))
        stretch.append(float(values['max_stretch']))
    assert checked[:3] == [(0, 3), (4, 7), (8, 11)] and checked[3] == checked[0]
    assert max(stretch[:3]) == pytest.approx(sim.max_stretch(), abs=2e-6)


# ====================================================================== executable
def _run_node(args, domain_id, options=()):
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED='1', PYTHONPATH=path)
    return subprocess.Popen([sys.executable, '-m', 'hair_tracking.ros.node', *options,
                             '--ros-args'] + args,
                            env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def test_executable_reads_the_params_file_and_overrides_and_exits_cleanly_on_ctrl_c():
    proc = _run_node(['--params-file', os.path.join(ROOT, 'config', 'hair_sim.yaml'),
                      '-p', 'groom.guides:=3', '-p', 'groom.ghosts_per_guide:=2',
                      '-p', 'solver.settle_time:=0.0', '-p', 'damping:=2'], 34)
    text = until_ready_then_ctrl_c(proc)
    assert any('ready: 3 guides' in ln and '6 ghosts' in ln for ln in text.splitlines()), text
    assert proc.returncode == 0, text
    assert 'Traceback' not in text
    # --omp-wait-policy (default passive) is applied before numba starts its threads
    wanted = os.environ.get('OMP_WAIT_POLICY')
    assert (f'OMP_WAIT_POLICY={wanted} from the environment kept' if wanted else
            'OpenMP worker threads wait passive (numba threading layer omp, '
            'OMP_WAIT_POLICY=PASSIVE)') in text, text


def test_executable_takes_its_process_settings_from_its_own_options():
    env_policy = os.environ.get('OMP_WAIT_POLICY')
    proc = _run_node(['-p', 'groom.guides:=2', '-p', 'groom.ghosts_per_guide:=1',
                      '-p', 'solver.settle_time:=0.0'], 56,
                     options=['--omp-wait-policy', 'active', '--malloc-retain-mb', '0',
                              '--no-gc-freeze'])
    text = until_ready_then_ctrl_c(proc)
    assert proc.returncode == 0, text
    assert 'malloc retention 0: glibc malloc defaults kept' in text, text
    assert (f'OMP_WAIT_POLICY={env_policy} from the environment kept' if env_policy else
            'OpenMP worker threads wait active (numba threading layer omp, '
            'OMP_WAIT_POLICY=ACTIVE)') in text, text


def test_executable_rejects_a_bad_process_setting_before_starting():
    proc = _run_node([], 57, options=['--malloc-retain-mb', '5000'])
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 2, out
    assert '--malloc-retain-mb must be in [0, 2047], got 5000' in out
    assert 'ready:' not in out and 'Traceback' not in out


def test_executable_rejects_a_bad_parameter_with_its_name():
    code, out = _exit_of(['-p', 'solver.type:=rk4', '-p', 'warmup:=false'], 33)
    assert code == 2, out
    assert 'solver.type' in out and 'ftl' in out
    assert 'Traceback' not in out


def _exit_of(args, domain_id):
    proc = _run_node(args, domain_id)
    try:
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, out


def test_executable_refuses_an_out_of_range_parameter_in_the_readme_form():
    code, out = _exit_of(['-p', 'groom.guides:=0', '-p', 'warmup:=false'], 58)
    assert code == 2, out
    assert out.splitlines()[-1] == ('[hair_sim] invalid parameters: groom.guides: 0 is outside '
                                    'the allowed range [1, 100000]'), out
    assert 'Traceback' not in out and 'ready:' not in out


@pytest.mark.parametrize('text, reason', [
    (None, 'params file not found'),
    ('hair_sim:\n  ros__parameters: {groom: [\n', 'not valid YAML: line 3, column 1: '),
    ('hair_sim:\n  groom:\n    guides: 4\n',
     'hair_sim.groom.guides: a value where "ros__parameters:" should be'),
    ('hair_sim:\n  ros__parameters:\n    gravity: [0, 0, -9.81]\n',
     'hair_sim.ros__parameters.gravity: the list mixes double and integer values'),
])
def test_executable_refuses_an_unusable_params_file_in_one_line(tmp_path, text, reason):
    path = tmp_path / 'p.yaml'
    if text is not None:
        path.write_text(text)
    code, out = _exit_of(['--params-file', str(path)], 59)
    assert code == 2, out
    assert len(out.splitlines()) == 1 and out.startswith(f'[hair_sim] {path}: {reason}'), out


def test_a_params_file_only_rcl_refuses_is_still_a_short_message(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('3d:\n  ros__parameters: {a: 1}\n')      # rcl: no node name starts with 3
    code, out = _exit_of(['--params-file', str(path)], 59)
    assert code == 2, out
    assert out.splitlines()[-1] == (f'[hair_sim] {path}: not a valid params file: node name '
                                    'must not start with a number'), out
    assert 'Traceback' not in out
