"""Serialized publish through rcl itself (msg_adapters.rcl_serialized), and the benchmarks'
take through rcl (scripts/rcl_take.py), over DDS."""
import os
import sys
import threading
import time

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String

from msg_adapters import rcl_serialized as rs
from msg_adapters.pointcloud import strands_to_pointcloud2, strands_to_pointcloud2_cdr

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'scripts'))
from rcl_take import SerializedTaker, SerializedWaiter  # noqa: E402

DOMAIN = 73
QOS = QoSProfile(depth=20, reliability=ReliabilityPolicy.RELIABLE)


@pytest.fixture
def ros():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    node = rclpy.create_node('rcl_serialized_test', context=ctx)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    yield ctx, node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def spin_until(executor, cond, what, timeout=10.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.02)
        if cond():
            return
    raise AssertionError(f'timed out waiting for {what}')


def test_rcl_is_found_in_the_process_with_the_verified_rclpy():
    assert rs.rclpy_version() == rs.VERIFIED_RCLPY     # the release the Makefile installs
    assert rs.available() and rs.unusable_reason() is None


def test_another_rclpy_release_keeps_rclpys_publish_and_says_why(ros, monkeypatch):
    ctx, node, executor = ros
    got = []
    node.create_subscription(String, 'other', got.append, QOS)
    pub = node.create_publisher(String, 'other', QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, 'the match')
    monkeypatch.setattr(rs, 'VERIFIED_RCLPY', '0.0.0')
    plain = rs.SerializedPublisher(pub, direct=True)
    assert plain.direct is False
    assert 'is not 0.0.0, the release the direct rcl path was verified against' in plain.reason
    plain.direct = True
    assert plain.direct is False
    plain.publish(serialize_message(String(data='via rclpy')))
    spin_until(executor, lambda: got, 'the message')
    assert got[0].data == 'via rclpy'
    with pytest.raises(RuntimeError, match='verified against'):
        SerializedTaker(node.create_subscription(String, 'other', lambda m: None, QOS))


def test_rclpys_publish_is_the_default(ros):
    ctx, node, executor = ros
    pub = node.create_publisher(String, 'default', QOS)
    assert rs.SerializedPublisher(pub).direct is False
    assert rs.SerializedPublisher(pub, direct=True).direct is True


def test_published_bytes_reach_an_ordinary_subscriber_unchanged(ros):
    ctx, node, executor = ros
    rng = np.random.default_rng(3)
    x = rng.normal(size=(300, 16, 3))
    kw = dict(frame_id='head', stamp_ns=12_000_000_345, colors=rng.random((300, 3)))
    cloud = strands_to_pointcloud2_cdr(x, **kw)
    got = []
    node.create_subscription(PointCloud2, 'cloud', got.append, QOS)
    pub = node.create_publisher(PointCloud2, 'cloud', QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, 'the match')
    direct = rs.SerializedPublisher(pub, direct=True)
    assert direct.direct
    for data in (cloud, bytearray(cloud), np.frombuffer(cloud, np.uint8), memoryview(cloud)):
        direct.publish(data)
    rs.SerializedPublisher(pub, direct=False).publish(np.frombuffer(cloud, np.uint8))
    spin_until(executor, lambda: len(got) == 5, 'five clouds')
    expected = strands_to_pointcloud2(x, **kw)
    assert all(m == expected for m in got)
    with pytest.raises(TypeError, match='contiguous'):
        direct.publish(np.zeros((2, 8), np.uint8))
    with pytest.raises(TypeError, match='contiguous'):
        direct.publish(np.zeros(8, np.float32))


def test_taker_gets_each_message_once_in_order_and_grows_its_buffer(ros):
    ctx, node, executor = ros
    executor.remove_node(node)     # the taker reads this subscription, no executor
    sub = node.create_subscription(String, 'text', lambda m: None, QOS, raw=True)
    pub = node.create_publisher(String, 'text', QOS)
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    taker = SerializedTaker(sub, capacity=8)
    waiter = SerializedWaiter(ctx, [sub])
    assert taker.take() is None
    assert waiter.wait(0.01) == []
    texts = ['short', 'x' * 5000, 'mid' * 50]
    for t in texts:
        rs.SerializedPublisher(pub, direct=True).publish(serialize_message(String(data=t)))
    assert waiter.wait(5.0) == [sub]
    got = []
    while len(got) < len(texts):
        raw = taker.take()
        if raw is None:
            assert waiter.wait(5.0), 'a message went missing'
            continue
        assert raw.readonly
        got.append(deserialize_message(bytes(raw), String).data)
    assert got == texts
    assert taker.take() is None
    taker.close()
    with pytest.raises(RuntimeError, match='after close'):
        taker.take()


def test_a_reader_thread_gets_every_cloud_and_its_wait_lets_python_run(ros):
    ctx, node, executor = ros
    executor.remove_node(node)
    sub = node.create_subscription(PointCloud2, 'big', lambda m: None, QOS, raw=True)
    pub = node.create_publisher(PointCloud2, 'big', QOS)
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    taker, waiter = SerializedTaker(sub), SerializedWaiter(ctx, [sub])
    cloud = strands_to_pointcloud2_cdr(np.zeros((2000, 16, 3)), frame_id='w')
    sizes, stop, waiting = [], threading.Event(), threading.Event()

    first_wait = []

    def read():
        waiting.set()
        while not stop.is_set():
            ready = waiter.wait(30.0)
            if not first_wait:
                first_wait.append(ready)
            for _ in ready:
                while (raw := taker.take()) is not None:
                    sizes.append(len(raw))
    reader = threading.Thread(target=read)
    reader.start()
    try:
        waiting.wait(5.0)
        time.sleep(0.05)              # the reader is now (or soon) blocked in its 30 s wait
        # this thread publishes while the reader waits: were the GIL held in the wait, it
        # could not run before the wait timed out, and the first wait would come back empty
        for _ in range(5):
            rs.SerializedPublisher(pub, direct=True).publish(cloud)
        deadline = time.monotonic() + 20.0
        while len(sizes) < 5 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        stop.set()
        pub.publish(cloud)            # wakes the reader from its wait so that it sees stop
        reader.join(35.0)
    assert first_wait and first_wait[0] == [sub]
    assert sizes[:5] == [len(cloud)] * 5
    taker.close()


def test_a_destroyed_publisher_raises_instead_of_crashing(ros):
    ctx, node, executor = ros
    pub = node.create_publisher(String, 'gone', QOS)
    direct = rs.SerializedPublisher(pub, direct=True)
    node.destroy_publisher(pub)
    with pytest.raises(Exception):
        direct.publish(serialize_message(String(data='late')))


class _HandleWithoutPointer:
    """A real rclpy publisher seen through a handle that does not expose its rcl pointer (as
    an rclpy without it would): the direct path must not be taken."""

    def __init__(self, pub):
        self._pub = pub
        self.handle = object()
        self.topic_name = pub.topic_name

    def publish(self, data):
        self._pub.publish(data)


def test_without_the_rcl_pointer_publishing_stays_on_rclpy(ros):
    ctx, node, executor = ros
    got = []
    node.create_subscription(String, 'plain', got.append, QOS)
    pub = node.create_publisher(String, 'plain', QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, 'the match')
    plain = rs.SerializedPublisher(_HandleWithoutPointer(pub), direct=True)
    assert plain.direct is False and 'rcl pointer' in plain.reason
    plain.direct = True                     # what the node's publish_through_rcl does
    assert plain.direct is False
    plain.publish(bytearray(serialize_message(String(data='via rclpy'))))
    spin_until(executor, lambda: got, 'the message')
    assert got[0].data == 'via rclpy'
