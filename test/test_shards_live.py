"""The guides node and two ghost shards as processes over DDS: the shards' rows, concatenated,
are the node's cloud of all strands (bitwise, same stamp); a shard killed leaves the other's
rows flowing; a shard started late catches up; out-of-order guides are dropped (injected)."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

pytest.importorskip('hair_tracking_msgs.msg')

import rclpy  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from sensor_msgs.msg import PointCloud2  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402

from loopback import spin_until  # noqa: E402
from msg_adapters.guide_state import guide_state_from_cdr  # noqa: E402
from msg_adapters.pose import pose_stamped_msg  # noqa: E402

from hair_tracking.output.settings import make_settings  # noqa: E402
from hair_tracking.output.shards import fingerprint, guide_state_bytes, \
    settings_text, shard_rows  # noqa: E402
from hair_tracking.ros.ghosts import GhostShardNode, shard_topic  # noqa: E402
from hair_tracking.ros.topics import latched_qos, output_qos, SCENE_TOPIC  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 97
DOMAIN_INJECT = 98
GROOM = ['groom.guides:=12', 'groom.ghosts_per_guide:=7', 'groom.ghost_nodes:=8',
         'groom.guide_nodes:=8']
SMALL = {'groom.guides': 12, 'groom.ghosts_per_guide': 7, 'groom.ghost_nodes': 8,
         'groom.guide_nodes': 8}
START_S = 240.0                          # a process's start-up, kernels compiled or loaded
FLOW_S = 60.0


def _env(domain):
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1',
                PYTHONPATH=os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')])))


def _start(module, params, domain):
    args = [sys.executable, '-m', module, '--ros-args']
    for p in params:
        args += ['-p', p]
    return subprocess.Popen(args, env=_env(domain), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def _stamp(cdr) -> int:
    sec, nanosec = np.frombuffer(bytes(cdr[4:12]), dtype='<i4,<u4')[0]
    return int(sec) * 1_000_000_000 + int(nanosec)


def _rows(cdr) -> bytes:
    """The point records of a serialized cloud."""
    return bytes(deserialize_message(cdr, PointCloud2).data)


class Listener:
    """The test's node: publishes head poses, keeps every cloud by stamp (raw bytes)."""

    def __init__(self, ctx):
        self.node = rclpy.create_node('shard_test', context=ctx)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.node)
        self.clouds = {'all': {}, 0: {}, 1: {}}
        for key, topic in (('all', 'hair/points'), (0, shard_topic(0, 'points')),
                           (1, shard_topic(1, 'points'))):
            self.node.create_subscription(
                PointCloud2, topic, lambda data, key=key: self.clouds[key].__setitem__(
                    _stamp(data), data), output_qos(50), raw=True)
        self.poses = self.node.create_publisher(PoseStamped, 'head_pose', 10)
        self.k = 0

    def spin_until(self, predicate, timeout_s):
        return spin_until(self.executor, predicate, timeout_s)

    def send(self):
        """One head pose of a nodding walk, 50 ms after the last."""
        k = self.k = self.k + 1
        a = 0.3 * np.sin(0.4 * k)
        self.poses.publish(pose_stamped_msg(
            50_000_000 * k, [0.01 * k, 0.0, 0.002 * k], [0.0, np.sin(a / 2), 0.0, np.cos(a / 2)],
            'world'))
        self.spin_until(lambda: False, 0.05)


def test_two_shards_give_the_node_rows_and_one_killed_leaves_the_other(tmp_path):
    node = _start('hair_tracking.ros.node', GROOM + ['publish_guide_state:=true',
                                                     'publish_rate_hz:=20.0'], DOMAIN)
    shards = [_start('hair_tracking.ros.ghosts', [f'shard:={k}', 'shards:=2'], DOMAIN)
              for k in range(2)]
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    try:
        lis = Listener(ctx)
        strands, nodes = 84, 8
        rows0 = shard_rows(strands, 0, 2).stop
        deadline = time.monotonic() + START_S
        while time.monotonic() < deadline and not all(lis.clouds[k] for k in (0, 1)):
            lis.send()
        assert all(lis.clouds[k] for k in (0, 1)), 'the shards never published'
        for _ in range(30):
            lis.send()
        lis.spin_until(lambda: False, 1.0)
        common = set(lis.clouds['all']) & set(lis.clouds[0]) & set(lis.clouds[1])
        assert len(common) >= 10, (len(lis.clouds['all']), len(lis.clouds[0]))
        for t in sorted(common):
            joined = _rows(lis.clouds[0][t]) + _rows(lis.clouds[1][t])
            assert len(_rows(lis.clouds[0][t])) == rows0 * nodes * 20
            assert joined == _rows(lis.clouds['all'][t]), t

        shards[1].send_signal(signal.SIGKILL)
        shards[1].wait(timeout=30)
        lis.spin_until(lambda: False, 1.0)       # what it sent before it died
        before = {k: max(lis.clouds[k]) for k in (0, 1)}
        for _ in range(20):
            lis.send()
        lis.spin_until(lambda: max(lis.clouds[0]) > before[0] + 500_000_000, FLOW_S)
        assert max(lis.clouds[0]) > before[0] + 500_000_000       # shard 0 keeps publishing
        assert max(lis.clouds[1]) == before[1]

        late = _start('hair_tracking.ros.ghosts', ['shard:=1', 'shards:=2'], DOMAIN)
        shards.append(late)
        deadline = time.monotonic() + START_S
        while time.monotonic() < deadline and max(lis.clouds[1]) == before[1]:
            lis.send()
        t = max(lis.clouds[1])
        assert t > before[1], 'the shard started late never published'
        lis.spin_until(lambda: t in lis.clouds['all'], 10.0)
        assert _rows(lis.clouds[1][t]) == _rows(lis.clouds['all'][t])[rows0 * nodes * 20:]
        lis.node.destroy_node()
        lis.executor.shutdown()
    finally:
        rclpy.try_shutdown(context=ctx)
        for p in shards + [node]:
            _stop(p)


def test_a_shard_drops_late_and_out_of_order_guides_and_counts_them():
    """Injected guides messages: the shard places the newest and never goes back."""
    text = settings_text(make_settings(SMALL))
    sim = HairSimulator(make_settings(SMALL).scene)
    sim.push_pose(1, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN_INJECT)
    try:
        node = GhostShardNode(context=ctx, parameter_overrides=[
            Parameter('shard', value=0), Parameter('shards', value=2)])
        pub = node.create_publisher(String, SCENE_TOPIC, latched_qos())
        pub.publish(String(data=text))
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        assert spin_until(executor, lambda: node.shard is not None, 60.0)

        def sample(seq, t):
            return guide_state_from_cdr(guide_state_bytes(sim, 'world', t, fingerprint(text),
                                                          seq))
        assert node.receive(sample(10, 100))
        assert not node.receive(sample(9, 90))           # out of order
        assert not node.receive(sample(10, 100))         # repeated
        assert node.receive(sample(12, 120))
        assert not node.receive(sample(11, 110))         # late
        assert node.shard.stamp_ns == 120
        values = {kv.key: kv.value for kv in node.diagnostics().values}
        assert values['guides_dropped_late'] == '3' and values['guides_applied'] == '2'
        node.destroy_node()
        executor.shutdown()
    finally:
        rclpy.try_shutdown(context=ctx)
