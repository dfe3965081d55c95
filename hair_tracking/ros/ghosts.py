"""``hair_sim_ghosts``: one ghost shard, a share of the ghost strands placed in a process (or on a
machine) of its own from the guides the ``hair_sim`` node publishes.

    hair_sim_ghosts --ros-args -p shard:=0 -p shards:=2
    ros2 launch hair_tracking hair_sim_shards.launch.py shards:=2

The ``hair_sim`` node with ``shards`` > 0 (or ``publish_guide_state``) publishes its settings
on ``hair/scene`` (std_msgs/String, YAML, transient-local: a shard started later gets them) and
each frame the guides' state on ``hair/guides/state`` (hair_tracking_msgs/GuideState).  The
shard builds the same groom from the settings, places the strands of its contiguous share
(:func:`hair_tracking.output.shards.shard_rows`) from every guides message and publishes them
on ``hair/shard_<shard>/points`` (PointCloud2, rows numbered and coloured as in the node's
cloud of all strands) and ``hair/shard_<shard>/markers`` (MarkerArray), each built only when
somebody subscribes, stamped with the guides' stamp; and ``/diagnostics``.  Concatenated in
shard order, the shards' rows are the rows of the cloud the node would publish itself.

A guides message of other settings (fingerprint) or another guide count is refused, with an
error; one that is not after the last one used (late, repeated, out of order: its sequence) is
dropped; both are counted in the diagnostics.  Settings the shard cannot place (a tracker other
than blend or turn) are refused with an error, and the shard waits for the next settings.

The guides are taken reliably with a queue of one (the newest: a shard that falls behind
places the newest frame, as the node's pose queue does).  Parameters: ``shard`` (0-based),
``shards`` (how many in all), ``output_queue_depth`` (of its outputs),
``diagnostics_rate_hz``.  Everything runs in one thread.
"""
import argparse
import collections
import sys
import time
from typing import List, Optional

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from msg_adapters.guide_state import guide_state_from_cdr, GuideState
from msg_adapters.rcl_serialized import SerializedPublisher

from hair_tracking import executable
from hair_tracking.output.diagnostics import make_status, WARN
from hair_tracking.output.shards import fingerprint, GhostShard, SequenceGate, ShardError
from hair_tracking.ros.topics import diagnostic_status, GUIDE_STATE_TOPIC, latched_qos, \
    output_qos, SCENE_TOPIC, WARN_THROTTLE_S
from hair_tracking.ros.spin_node import spin_node

NODE_NAME = 'hair_sim_ghosts'


def shard_topic(shard: int, what: str) -> str:
    """The topic of shard ``shard``'s ``what`` (points, markers)."""
    return f'hair/shard_{int(shard)}/{what}'


class GhostShardNode(Node):
    """The ``hair_sim_ghosts`` node (see the module docstring); ``context``,
    ``parameter_overrides`` and ``cli_args`` as for :class:`rclpy.node.Node`.  Invalid
    ``shard`` / ``shards`` raise ShardError."""

    def __init__(self, node_name: str = NODE_NAME, *, context=None,
                 parameter_overrides: Optional[List[Parameter]] = None,
                 cli_args: Optional[List[str]] = None, namespace: Optional[str] = None):
        super().__init__(node_name, context=context, cli_args=cli_args, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.index = int(self.declare_parameter('shard', 0).value)
        self.count = int(self.declare_parameter('shards', 1).value)
        depth = int(self.declare_parameter('output_queue_depth', 2).value)
        rate = float(self.declare_parameter('diagnostics_rate_hz', 1.0).value)
        if not 0 <= self.index < self.count:
            raise ShardError(f'shard {self.index} of shards {self.count} does not exist '
                             '(0 <= shard < shards)')
        if depth < 1 or rate <= 0.0:
            raise ShardError('output_queue_depth must be >= 1 and diagnostics_rate_hz > 0')
        if GuideState is None:
            raise ShardError('hair_tracking_msgs is not installed (make install generates it)')
        self.shard: Optional[GhostShard] = None
        self.problem = 'waiting for the settings on ' + SCENE_TOPIC
        self._fingerprint = None         # of the settings last received
        self.gate = SequenceGate()
        self.refused = 0                 # guides of other settings or another size
        self.unusable = 0                # guides messages that are not a GuideState
        self.waiting = 0                 # guides that came before usable settings
        self.published = 0
        self.work_ms = collections.deque(maxlen=1000)   # placing, encoding, publishing
        self.cloud_bytes = 0             # the size of the last cloud
        self.outputs = {
            key: SerializedPublisher(self.create_publisher(
                kind, shard_topic(self.index, key), output_qos(depth)))
            for key, kind in (('points', PointCloud2), ('markers', MarkerArray))}
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(String, SCENE_TOPIC, self._on_scene, latched_qos())
        # the newest guides only: a shard that falls behind places the newest frame
        self.create_subscription(GuideState, GUIDE_STATE_TOPIC, self._on_guides,
                                 output_qos(1), raw=True)
        self.create_timer(1.0 / rate, self._on_diag_timer)
        self.get_logger().info(f'shard {self.index} of {self.count}: waiting for the settings '
                               f'on {SCENE_TOPIC}')

    def _on_scene(self, msg) -> None:
        """New settings: build the groom and this shard's share (or say why not)."""
        text = str(msg.data)
        fp = fingerprint(text)
        if fp == self._fingerprint:
            return
        self._fingerprint = fp
        self.gate.restart()
        try:
            self.shard = GhostShard(text, self.index, self.count)
        except ShardError as exc:
            self.shard, self.problem = None, str(exc)
            self.get_logger().error(f'settings refused: {exc}')
            return
        self.problem = ''
        rows = self.shard.rows
        self.get_logger().info(f'shard {self.index} of {self.count}: ghost strands '
                               f'{rows.start}-{rows.stop - 1} of {self.shard.total}')

    def _on_guides(self, data: bytes) -> None:
        """A guides message: checked, gated, placed, published."""
        try:
            sample = guide_state_from_cdr(data, copy=False)
        except ValueError as exc:
            self.unusable += 1
            self.get_logger().warn(f'guides message dropped: {exc}',
                                   throttle_duration_sec=WARN_THROTTLE_S)
            return
        self.receive(sample)

    def receive(self, sample) -> bool:
        """Place and publish the guides ``sample`` (a
        :class:`~msg_adapters.guide_state.GuideStateSample`) unless it is refused or dropped;
        returns whether it was placed."""
        shard = self.shard
        if shard is None:
            self.waiting += 1
            return False
        try:
            shard.check(sample)
        except ShardError as exc:
            self.refused += 1
            self.get_logger().error(str(exc), throttle_duration_sec=WARN_THROTTLE_S)
            return False
        if not self.gate.accept(sample.sequence):
            return False
        start = time.perf_counter()
        shard.apply(sample)
        keys = [k for k, out in self.outputs.items() if out.publisher.get_subscription_count() > 0]
        if keys:
            for key, data in shard.encode(keys, shard.frame_id(sample.frame_id)).items():
                self.outputs[key].publish(data)
                if key == 'points':
                    self.cloud_bytes = len(data)
            self.published += 1
        self.work_ms.append((time.perf_counter() - start) * 1e3)
        return True

    def diagnostics(self):
        """The shard's health: its share, the guides placed, dropped and refused."""
        shard = self.shard
        problems = [self.problem] if self.problem else []
        if self.refused:
            problems.append(f'{self.refused} guides messages refused (other settings)')
        values = {
            'shard': f'{self.index} of {self.count}',
            'strands': 'n/a' if shard is None else f'{shard.rows.start}-{shard.rows.stop - 1}',
            'guides_applied': str(0 if shard is None else shard.counters.applied),
            'guides_dropped_late': str(self.gate.dropped),
            'guides_refused': str(self.refused),
            'guides_unusable': str(self.unusable),
            'guides_before_settings': str(self.waiting),
            'frames_published': str(self.published),
            'work_ms_median': f'{np.median(self.work_ms):.3f}' if self.work_ms else 'n/a',
            'work_ms_p99': f'{np.percentile(self.work_ms, 99):.3f}' if self.work_ms else 'n/a',
            'cloud_bytes': str(self.cloud_bytes),
        }
        return diagnostic_status(f'{self.get_name()}: ghost shard',
                                 make_status(WARN if problems else 0, problems, values))

    def _on_diag_timer(self) -> None:
        msg = DiagnosticArray(status=[self.diagnostics()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(msg)


def make_parser() -> argparse.ArgumentParser:
    """The command line of ``hair_sim_ghosts`` in front of ``--ros-args``."""
    parser = argparse.ArgumentParser(
        prog='hair_sim_ghosts',
        description='One ghost shard: places shard k of n of the ghost strands from the guides '
                    'the hair_sim node publishes (hair/scene, hair/guides/state; the node\'s '
                    'shards parameter) and publishes them on hair/shard_<k>/points '
                    '(PointCloud2) and hair/shard_<k>/markers (MarkerArray); /diagnostics.',
        epilog='ROS arguments follow --ros-args, e.g. hair_sim_ghosts --ros-args -p shard:=1 '
               '-p shards:=2')
    executable.add_arguments(parser)
    return parser


def main(args=None) -> int:
    """Console entry point ``hair_sim_ghosts``: as ``hair_sim_node``'s main (0 once stopped,
    2 for invalid parameters)."""
    argv = list(sys.argv if args is None else args)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    options = make_parser().parse_args(argv[1:split])
    with executable.started() as stop:
        try:
            done = executable.apply(options)
        except ValueError as e:
            print(f'[{NODE_NAME}] {e}', file=sys.stderr)
            return 2
        return spin_node(NODE_NAME, GhostShardNode, argv[:1] + argv[split:], stop, done,
                         options.gc_freeze,
                         lambda e: f'[{NODE_NAME}] {e}' if isinstance(e, ShardError) else None)


if __name__ == '__main__':
    sys.exit(main())
