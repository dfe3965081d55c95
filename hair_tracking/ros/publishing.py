"""The ``hair_sim`` node's outputs.

Publishers exist only while their feature is on (made and destroyed as the parameters change):
``hair/points`` and ``hair/markers`` (not with ``shards``: the shards publish the ghosts),
``hair/guides/points`` and ``hair/guides/markers`` (``publish_guides``), ``hair/head``
(``head_marker``), ``hair/colliders`` (``head_marker`` and ``body.bust`` or a collider slot),
``hair/guides/state``
and the latched ``hair/scene`` (``shards`` or ``publish_guide_state``).  A message is built only
when somebody subscribes; the strand outputs are encoded by one
:class:`~hair_tracking.output.frame_encoder.FrameEncoder` (the people's clouds too) and sent as
CDR bytes, resent from a cache while the hair has not changed.  Publishing runs on its own
timer (``publish_rate_hz``); ``publish_on_pose`` additionally publishes right after a pose.
"""
import collections
import math
import time
from typing import Dict

import numpy as np
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.capsule_markers import capsule_markers
from msg_adapters.guide_state import GuideState
from msg_adapters.head_marker import collider_marker
from msg_adapters.rcl_serialized import SerializedPublisher

from hair_tracking.colliders.shapes import A0, A1, CAPSULE, CX, CZ, KIND, R00, R22, SPHERE
from hair_tracking.core.transforms import matrix_to_quat
from hair_tracking.output.frame_encoder import FrameEncoder
from hair_tracking.output.shards import fingerprint, guide_state_bytes, settings_text, \
    SHARDABLE
from hair_tracking.ros.topics import COLLIDERS_TOPIC, GUIDE_STATE_TOPIC, HEAD_MARKER_TOPIC, \
    latched_qos, output_qos, SCENE_TOPIC, STRAND_TOPICS

_STRAND_TYPES = {'points': PointCloud2, 'markers': MarkerArray,
                 'guide_points': PointCloud2, 'guide_markers': MarkerArray}


class _Output:
    """One published strand topic: its two publishers' state and a cache of the last bytes."""

    def __init__(self, node, topic: str, msg_type, depth: int = 2):
        self.pub = node.create_publisher(msg_type, topic, output_qos(depth))
        self.raw = SerializedPublisher(self.pub)     # direct with publish_through_rcl
        self.cached = None               # the last message sent (bytes or a uint8 array)
        self.encoded = 0             # messages built (encoded) so far
        self.published = 0

    def wanted(self) -> bool:
        return self.pub.get_subscription_count() > 0


def strand_outputs_on(settings) -> Dict[str, bool]:
    """Which strand outputs the settings feed."""
    ghosts = settings.shards == 0
    return {'points': ghosts, 'markers': ghosts, 'guide_points': settings.publish_guides,
            'guide_markers': settings.publish_guides}


class Publishing:
    """The outputs of ``node`` (a :class:`~hair_tracking.ros.node.HairSimNode`: its ``sim``,
    ``settings``, ``intake``, ``work_clock``); see the module docstring."""

    def __init__(self, node):
        self._node = node
        s = node.settings
        self.encoder = FrameEncoder(s)   # the messages of a frame, the people's clouds too
        self.outputs: Dict[str, _Output] = {}
        self.head_pub = self.colliders_pub = None
        self.dirty = False               # the hair changed since the last encoding
        self.last_publish = -math.inf    # time.monotonic() of the last publication
        self.pose_publish_at = -math.inf     # ... of the last one publish_on_pose made
        self.frames_built = 0            # sim.frame() calls made for publishing
        self.publish_ms = collections.deque(maxlen=1000)
        self.ms_since_pose = 0.0         # publishing time since the last pose (shedding)
        self._rcl_refusal_logged = False
        self.guide_state_pub = self.scene_pub = None
        self.guide_states_sent = 0
        self._guide_state_key = None     # (sim time, tracker steps) of the last state sent
        self._guide_sequence = 0
        self._scene_text = self._scene_fingerprint = None
        self.sync(s)
        if s.guide_state:
            self._start_guide_state()

    # ---------------------------------------------------------------- publishers
    def sync(self, s) -> None:
        """Publishers for the features ``s`` (the settings) turns on, none for the others."""
        node, depth = self._node, s.output_queue_depth
        for key, on in strand_outputs_on(s).items():
            if on and key not in self.outputs:
                self.outputs[key] = _Output(node, STRAND_TOPICS[key], _STRAND_TYPES[key], depth)
            elif not on and key in self.outputs:
                node.destroy_publisher(self.outputs.pop(key).pub)
        self.head_pub = self._publisher(self.head_pub, s.head_marker, Marker,
                                        HEAD_MARKER_TOPIC, depth)
        bodies = s.scene.body.bust or bool(s.scene.colliders.used())
        self.colliders_pub = self._publisher(self.colliders_pub, s.head_marker and bodies,
                                             MarkerArray, COLLIDERS_TOPIC, depth)

    def _publisher(self, pub, on: bool, msg_type, topic: str, depth: int):
        if on and pub is None:
            return self._node.create_publisher(msg_type, topic, output_qos(depth))
        if not on and pub is not None:
            self._node.destroy_publisher(pub)
            return None
        return pub

    def _start_guide_state(self) -> None:
        """The publishers of the guides' state and the settings for hair_sim_ghosts
        (``shards`` / ``publish_guide_state``, read-only); this node's ghosts are then placed
        from the guides as they send them."""
        node = self._node
        if GuideState is None:
            node.get_logger().warn('shards / publish_guide_state: hair_tracking_msgs is not '
                                   'installed, the guides\' state is not published')
            return
        self.guide_state_pub = node.create_publisher(GuideState, GUIDE_STATE_TOPIC,
                                                     output_qos(node.settings.output_queue_depth))
        self.scene_pub = node.create_publisher(String, SCENE_TOPIC, latched_qos())
        mode = node.settings.scene.tracking.mode
        if mode not in SHARDABLE:
            node.get_logger().warn(f'shards / publish_guide_state: tracking.mode {mode} cannot '
                                   f'be sharded (only {", ".join(SHARDABLE)}): no guides\' '
                                   'state is sent, and hair_sim_ghosts refuses these settings')
        node.sim.guides_as_float32 = True
        self.publish_scene()

    # ---------------------------------------------------------------- frames
    def invalidate(self) -> None:
        self.dirty = True
        for out in self.outputs.values():
            out.cached = None

    def output_frame_id(self) -> str:
        """frame_id of the published hair (see ``output_frame``)."""
        intake = self._node.intake
        if self._node.settings.output_frame == 'head':
            return intake.head_frame()
        return intake.pose_frame()

    def on_timer(self) -> None:
        """The publishing rate: resend or rebuild the frame, unless a pose just sent one, or
        ``publish_on_pose`` sent one within the last period (the poses keep the rate then; a
        resend would only repeat their frame and keep the node from the next pose)."""
        self._node.apply_pending()
        s = self._node.settings
        now, period = time.monotonic(), s.publish_period
        if now - self.last_publish < 0.5 * period:
            return                       # just published from a pose callback
        if s.publish_on_pose and now - self.pose_publish_at < period:
            return
        self.publish()

    def publish(self) -> None:
        """Encode and publish the outputs somebody subscribes to (nothing else is built)."""
        node = self._node
        if not node.intake.has_pose:
            return
        self._publish_head()
        self._publish_colliders()
        self._publish_guide_state()
        outs, s = self.outputs, node.settings
        wanted = {k: o.wanted() for k, o in outs.items()}
        self.last_publish = time.monotonic()
        if not any(wanted.values()):
            return
        start = node.work_clock()
        for o in outs.values():
            o.raw.direct = s.publish_through_rcl     # stays False where rcl is not usable
        reason = next(iter(outs.values())).raw.reason
        if s.publish_through_rcl and reason and not self._rcl_refusal_logged:
            node.get_logger().warn(f'publish_through_rcl: {reason}; publishing through rclpy')
            self._rcl_refusal_logged = True
        if not self.dirty:               # same hair: resend the bytes (keeps markers alive)
            for k, o in outs.items():
                if wanted[k] and o.cached is not None:
                    o.raw.publish(o.cached)
                    o.published += 1
                    wanted[k] = False
            if not any(wanted.values()):
                return
        head_frame = s.output_frame == 'head'
        # the clouds are written from the simulator's state (the ghosts from the tracker's
        # own layout) into buffers kept per output; a frame is built only for markers
        frame = None
        if wanted.get('markers') or wanted.get('guide_markers'):
            frame = node.sim.frame(head_frame=head_frame, copy=False)
            self.frames_built += 1
        self.encoder.settings = s
        encoded = self.encoder.frame(node.sim, [k for k, on in wanted.items() if on],
                                     self.output_frame_id(), node.intake.stamp(), head_frame,
                                     frame)
        for key, msg in encoded.items():
            o = outs[key]
            o.cached = None if msg.fresh else msg.data     # never resend a DELETEALL
            o.encoded += 1
            o.raw.publish(msg.data)
            o.published += 1
        self.dirty = False
        took = (node.work_clock() - start) * 1e3
        self.publish_ms.append(took)
        self.ms_since_pose += took

    # ---------------------------------------------------------------- ghost shards
    def publish_scene(self) -> None:
        """The settings on the latched scene topic when they changed."""
        if self.scene_pub is None:
            return
        text = settings_text(self._node.settings)
        if text != self._scene_text:
            self._scene_text, self._scene_fingerprint = text, fingerprint(text)
            self.scene_pub.publish(String(data=text))

    def _publish_guide_state(self) -> None:
        """The guides' state of a frame whose ghosts were placed from the guides and head
        pose alone (not right after a reset or a jump, which carry the hair), once a frame."""
        node = self._node
        sim = node.sim
        tracker = sim.ghost_tracker
        if self.guide_state_pub is None or tracker is None or \
                not getattr(tracker, 'from_step', False):
            return
        key = (sim.time_ns, tracker.stats['steps'])
        if key == self._guide_state_key:
            return
        self._guide_state_key = key
        self._guide_sequence = (self._guide_sequence + 1) % (1 << 32)
        self.guide_state_pub.publish(guide_state_bytes(
            sim, node.intake.frame_id or node.settings.fixed_frame or 'world',
            node.intake.stamp(), self._scene_fingerprint, self._guide_sequence))
        self.guide_states_sent += 1

    # ---------------------------------------------------------------- colliders
    def _publish_head(self) -> None:
        """The collider as a Marker on ``hair/head`` in the frame of the hair (``head_marker``;
        built only when somebody subscribes)."""
        if self.head_pub is None or self.head_pub.get_subscription_count() == 0:
            return
        node = self._node
        s, sim = node.settings, node.sim
        c = sim.scene.collider
        kw = {}
        if s.output_frame != 'head':
            kw = dict(head_position=sim.head.position, head_quaternion=sim.head.quaternion)
        self.head_pub.publish(collider_marker(
            c.shape, c.center, c.radius, c.radii, frame_id=self.output_frame_id(),
            stamp_ns=node.intake.stamp(), color=s.head_color, **kw))

    def _publish_colliders(self) -> None:
        """The body's capsules and spheres (the bust's, the collider slots') as markers on
        ``hair/colliders`` in the frame of the hair, at the head pose of the hair
        (``head_marker``, with a bust or a slot; built only when somebody subscribes)."""
        node = self._node
        s, sim = node.settings, node.sim
        body = getattr(sim.guide_solver, 'body', None)
        if body is None or self.colliders_pub is None or \
                self.colliders_pub.get_subscription_count() == 0:
            return
        head = sim.head
        sh = body.posed_bare(head)
        sh = sh[np.isin(sh[:, KIND], (SPHERE, CAPSULE))]
        centers = sh[:, CX:CZ + 1]
        rots = sh[:, R00:R22 + 1].reshape(-1, 3, 3)
        if s.output_frame == 'head':
            centers = head.to_head(centers)
            rots = np.einsum('ji,kjl->kil', head.rotation, rots)
        self.colliders_pub.publish(MarkerArray(markers=capsule_markers(
            centers, [matrix_to_quat(r) for r in rots], sh[:, A0], sh[:, A1],
            frame_id=self.output_frame_id(), stamp_ns=node.intake.stamp(),
            color=s.head_color)))
