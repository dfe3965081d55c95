"""``hair_sim``: the ROS 2 node that makes hair follow a head pose stream.

    ros2 run hair_tracking hair_sim_node --ros-args --params-file config/hair_sim.yaml
    hair_sim_node --ros-args -p groom.guides:=32 -r head_pose:=/face/pose

Inputs (all remappable, subscribed with the sensor-data QoS, so reliable and best-effort
publishers both connect):

* ``head_pose`` (geometry_msgs/PoseStamped) and ``head_transform`` (geometry_msgs/
  TransformStamped): the head in a fixed frame, ``p_fixed = position + R(q) @ p_head``.
* ``/tf`` (tf2_msgs/TFMessage) with ``use_tf``, when tf2_msgs is importable: the transform whose
  child frame is ``head_frame`` or, with ``head_frame_prefix``, the first child frame starting
  with it (REP-155 face trackers publish ``face_<id>``), kept until it goes stale.

The header stamp drives the simulation (``advance_to(stamp)``); a stamp of 0 means "now" on the
node clock (so ``use_sim_time`` is honoured); a stamp older than the last one resets the hair
(a looping bag); NaN/Inf or zero-quaternion poses are dropped, counted and warned about
(throttled).  Without poses for ``stale_timeout`` the last pose is held and the hair keeps
settling, stepped from the node clock.

Outputs, built only when somebody subscribes: ``hair/points`` (organized PointCloud2, one row per
strand, x y z float32, ``strand`` index, packed ``rgb``), ``hair/markers`` (MarkerArray,
``line_list`` or ``line_strips``, a DELETEALL first whenever the strand count or style changes,
lifetime of a few publishing periods), optionally ``hair/guides/points`` and
``hair/guides/markers``, the head collider on ``hair/head`` (Marker, ``head_marker``), the
body's bust on ``hair/colliders`` (MarkerArray, ``head_marker`` and ``body.bust``), each
head pose on ``/tf`` (``publish_tf``), and ``/diagnostics``.  Both hair outputs are serialized
straight to CDR bytes with numpy (:mod:`msg_adapters.pointcloud`,
:mod:`msg_adapters.marker_cdr`).  Publishing runs on its own timer (``publish_rate_hz``);
``publish_on_pose`` additionally publishes right after a simulated pose when a period of stream
time has passed, for the lowest latency.

Service ``~/reset`` (std_srvs/Trigger): hair back to its rest shape at the current head pose.

Parameters: one per row of the parameter table (:func:`hair_tracking.core.param_table.table`: the
node's settings plus every scene field), each declared with a descriptor built from its row
(:mod:`hair_tracking.ros.parameters`: description, range, read-only); changes are validated in
the on-set callback
(a rejection names the parameter and the allowed values and changes nothing) and stored by the
post-set callback as a frozen :class:`~hair_tracking.output.settings.Settings` snapshot that the
next step applies (a groom change rebuilds the hair at the current head pose; a ``groom.file``
that cannot be imported is refused in the on-set callback, and the hair is kept).

Everything runs in one thread (a SingleThreadedExecutor), so callbacks never race.
"""
import argparse
import collections
import dataclasses
import math
import sys
import time
from typing import Callable, Dict, List, Optional, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TransformStamped
import numba
import numpy as np
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.capsule_markers import capsule_markers
from msg_adapters.guide_state import GuideState
from msg_adapters.head_marker import collider_marker
from msg_adapters.pose import pose_from_msg, PoseError
from msg_adapters.rcl_serialized import SerializedPublisher
from msg_adapters.stamps import time_to_ns
from msg_adapters.tf import transform_message
from msg_adapters.tf_tree import compose as tf_compose, TfTree

from hair_tracking import executable
from hair_tracking.bags.warmup import warm_up
from hair_tracking.core.head_track import PoseResult
from hair_tracking.core.params import ParamError
from hair_tracking.core.scene import SceneError
from hair_tracking.grooms.polylines import GroomFileError
from hair_tracking.colliders.shapes import A0, A1, CAPSULE, CX, CZ, KIND, R00, R22, SPHERE
from hair_tracking.core.transforms import matrix_to_quat, quat_to_matrix
from hair_tracking.output.params_check import params_files_problem, rcl_arguments_problem
from hair_tracking.core.param_table import NODE_NAME
from hair_tracking.output.diagnostics import HairHealth, HARDWARE_ID, make_status, \
    status_name, WARN
from hair_tracking.output.frame_encoder import FrameEncoder
from hair_tracking.output.shards import fingerprint, guide_state_bytes, settings_text, \
    SHARDABLE
from hair_tracking.ros.faces import FaceHair
from hair_tracking.ros.load_shedding import LoadShedder
from hair_tracking.ros.parameters import NodeParameters
from hair_tracking.ros.spin_node import spin_node
from hair_tracking.simulator import HairSimulator

try:                                    # optional: /tf input
    from tf2_msgs.msg import TFMessage
except ImportError:                     # pragma: no cover - depends on the installation
    TFMessage = None

WARN_THROTTLE_S = 5.0
#: Ghost strands whose stretch and head penetration one diagnostics report checks; a larger hair
#: is checked a part per report, in turn.  A whole-hair check of 100 k ghosts takes about 30 ms
#: of the executor's thread, during which the poses behind it wait.
DIAG_AUDIT_STRANDS = 4096
HEAD_MARKER_TOPIC = 'hair/head'
#: The scene's body (the bust's capsules) as markers.
COLLIDERS_TOPIC = 'hair/colliders'
#: What ghost shards (hair_sim_ghosts) place their ghosts from: the guides' state of each frame
#: and the node's settings (latched).
GUIDE_STATE_TOPIC = 'hair/guides/state'
SCENE_TOPIC = 'hair/scene'


def latched_qos() -> QoSProfile:
    """Reliable, transient-local, keep-last 1: a late subscriber gets the last message."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def output_qos(depth: int) -> QoSProfile:
    """Reliable, volatile, keep-last ``depth`` (parameter ``output_queue_depth``)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def diagnostic_status(name: str, status) -> DiagnosticStatus:
    """The DiagnosticStatus of a :class:`hair_tracking.output.diagnostics.Status`."""
    return DiagnosticStatus(level=bytes([status.level]), name=name, message=status.message,
                            hardware_id=HARDWARE_ID,
                            values=[KeyValue(key=k, value=v) for k, v in status.values.items()])


class _Output:
    """One published strand topic: its two publishers' state and a cache of the last bytes."""

    def __init__(self, node: Node, topic: str, msg_type, depth: int = 2):
        self.pub = node.create_publisher(msg_type, topic, output_qos(depth))
        self.raw = SerializedPublisher(self.pub)     # direct with publish_through_rcl
        self.cached = None               # the last message sent (bytes or a uint8 array)
        self.encoded = 0             # messages built (encoded) so far
        self.published = 0

    def wanted(self) -> bool:
        return self.pub.get_subscription_count() > 0


class HairSimNode(Node):
    """The ``hair_sim`` node (see the module docstring).

    ``context``, ``parameter_overrides`` and ``cli_args`` are passed to :class:`rclpy.node.Node`
    so tests and benchmarks can run it in-process; ``work_clock()`` [s] times the work of each
    step and publication that load shedding weighs (tests inject a deterministic one).
    Construction declares the parameters, builds the simulator, warms up the kernels
    (``warmup``) and only then subscribes.  Invalid start parameters raise
    :class:`~hair_tracking.core.params.ParamError` naming the parameter.
    """

    def __init__(self, node_name: str = NODE_NAME, *, context=None,
                 parameter_overrides: Optional[List[Parameter]] = None,
                 cli_args: Optional[List[str]] = None, namespace: Optional[str] = None,
                 work_clock: Callable[[], float] = time.perf_counter):
        super().__init__(node_name, context=context, cli_args=cli_args, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.parameters = NodeParameters(self, self._on_params_changed)
        settings = self._settings = self.parameters.pending
        self._apply_threads(settings.numba_threads)
        self.shedder = LoadShedder(settings.load_shedding_budget)
        self._work_clock = work_clock    # times the step and publish work (load shedding)
        try:
            self.sim = HairSimulator(settings.scene, clock=work_clock)
        except GroomFileError as e:
            raise ParamError('groom.file', str(e)) from None
        if self.sim.groom_note:
            self.get_logger().info(self.sim.groom_note)
        if settings.warmup:
            secs = warm_up(settings.scene)
            self.get_logger().info(f'kernels and encoders ready in {secs:.2f} s')

        # state read by the step and publish paths
        self._pose_frame = ''            # header.frame_id of the last pose
        self._pose_child = ''            # child_frame_id of the last pose ('' for PoseStamped)
        self._last_arrival_ns: Optional[int] = None   # node clock at the last accepted pose
        self._last_stamp_ns: Optional[int] = None     # its stamp (the stream's time base)
        self._offset_ns = 0              # simulator time = stream stamp + this (see _on_pose)
        self._has_pose = False
        self._dirty = False              # the hair changed since the last encoding
        self._last_publish = -math.inf   # time.monotonic() of the last publication
        self._pose_publish_at = -math.inf    # ... of the last one publish_on_pose made
        self._pose_published_ns = None   # sim time of the last frame publish_on_pose sent
        self._tf_child: Optional[str] = None
        self._tf_seen_ns = 0
        self.encoder = FrameEncoder(settings)     # the messages of a frame
        self._rcl_refusal_logged = False
        self.rejected = 0                # poses dropped (malformed, NaN, zero quaternion ...)
        self.rebuilds = 0
        self.frames_built = 0            # sim.frame() calls made for publishing
        self.step_ms = collections.deque(maxlen=1000)
        self.publish_ms = collections.deque(maxlen=1000)
        self._publish_ms_since_pose = 0.0    # publishing time since the last pose (shedding)
        self._health = HairHealth()      # substeps dropped, poses rejected since a report
        self._audit_part = 0             # the part of the ghosts the next report checks

        depth = settings.output_queue_depth
        self.outputs: Dict[str, _Output] = {
            'points': _Output(self, 'hair/points', PointCloud2, depth),
            'markers': _Output(self, 'hair/markers', MarkerArray, depth),
            'guide_points': _Output(self, 'hair/guides/points', PointCloud2, depth),
            'guide_markers': _Output(self, 'hair/guides/markers', MarkerArray, depth),
        }
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.diagnostics_sent = 0
        self._head_pub = self.create_publisher(Marker, HEAD_MARKER_TOPIC, output_qos(depth))
        self._colliders_pub = self.create_publisher(MarkerArray, COLLIDERS_TOPIC,
                                                    output_qos(depth))
        self._guide_state_pub = self._scene_pub = None
        self._guide_state_key = None     # (sim time, tracker steps) of the last state sent
        self.guide_states_sent = 0
        self._guide_state_on = False
        self._start_guide_state(depth, settings.guide_state)
        self._tf = TfTree()              # /tf_static and /tf, for use_tf and gravity_frame
        self._tf_pub = None              # publish_tf
        self._tf_sent_key = None         # (child, stamp) of the last transform broadcast
        self.tf_sent = 0
        self._gravity_used = None        # gravity in the pose's frame given to the simulator
        self._body_seen = None           # (arrival [ns], static) of body.frame on /tf
        if TFMessage is not None:
            self._tf_pub = self.create_publisher(TFMessage, '/tf', QoSProfile(
                history=HistoryPolicy.KEEP_LAST, depth=100,
                reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE))
        elif settings.publish_tf:
            self.get_logger().warn('publish_tf is true but tf2_msgs is not installed: the head '
                                   'pose is not broadcast on /tf')
        self.create_service(Trigger, '~/reset', self._on_reset)
        period = settings.publish_period
        self._publish_timer = self.create_timer(period, self._on_publish_timer)
        self._idle_timer = self.create_timer(period, self._on_idle_timer)
        self._diag_timer = self.create_timer(1.0 / settings.diagnostics_rate_hz,
                                             self._on_diag_timer)
        pose_qos = QoSProfile(history=qos_profile_sensor_data.history,
                              depth=settings.pose_queue_depth,
                              reliability=qos_profile_sensor_data.reliability,
                              durability=qos_profile_sensor_data.durability)
        self.create_subscription(PoseStamped, 'head_pose', self._on_pose, pose_qos)
        self.create_subscription(TransformStamped, 'head_transform', self._on_pose, pose_qos)
        self._tf_subscribed = False
        self._frames_seen: Dict[str, Tuple[int, bool]] = {}   # collider TF frame: as _body_seen
        self._subscribe_tf()
        scene = settings.scene
        #: people.source hri: every tracked face's hair (ros/faces.py); None for one head
        self.faces = FaceHair(self, lambda: self.parameters.pending) \
            if scene.people.source == 'hri' else None
        ghosts = self.sim.ghosts.count if self.sim.ghosts is not None else 0
        self.get_logger().info(
            f'ready: {self.sim.guides.count} guides ({scene.groom.guide_nodes} nodes), '
            f'{ghosts} ghosts ({scene.groom.ghost_nodes} nodes), solver {scene.solver.type}, '
            f'publishing at {settings.publish_rate_hz:g} Hz')

    def _subscribe_tf(self) -> None:
        """/tf and /tf_static, once, when use_tf, gravity_frame, body.frame or a collider on a
        TF frame asks for them (at start or when a parameter change sets one)."""
        settings = self._settings
        if self._tf_subscribed or not (settings.use_tf or settings.gravity_frame
                                       or self._body_frame() or self.sim.collider_frames()):
            return
        self._tf_subscribed = True
        if TFMessage is None:
            self.get_logger().warn('use_tf, gravity_frame, body.frame or a collider on a TF '
                                   'frame is set but tf2_msgs is not installed: /tf is not '
                                   'subscribed (head_pose and head_transform still are)')
            return
        tf_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                            reliability=ReliabilityPolicy.BEST_EFFORT,
                            durability=DurabilityPolicy.VOLATILE)
        self.create_subscription(TFMessage, '/tf', self._on_tf if settings.use_tf
                                 else self._on_tf_dynamic, tf_qos)
        static_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.create_subscription(TFMessage, '/tf_static', self._on_tf_static, static_qos)

    # ================================================================ parameters
    @property
    def settings(self):
        """The settings the node runs with now (a frozen
        :class:`~hair_tracking.output.settings.Settings`)."""
        return self._settings

    def _on_params_changed(self, old, new) -> None:
        """An accepted change: timers and threads are not part of a step, they follow at
        once (the rest waits for the next step, :meth:`_apply_pending`)."""
        if new.publish_rate_hz != old.publish_rate_hz:
            period_ns = int(round(1e9 / new.publish_rate_hz))
            self._publish_timer.timer_period_ns = period_ns
            self._idle_timer.timer_period_ns = period_ns
        if new.diagnostics_rate_hz != old.diagnostics_rate_hz:
            self._diag_timer.timer_period_ns = int(round(1e9 / new.diagnostics_rate_hz))
        if new.numba_threads != old.numba_threads:
            self._apply_threads(new.numba_threads)

    def _apply_threads(self, wanted: int) -> None:
        """Threads of numba's parallel kernels (0 = all it was started with)."""
        most = numba.config.NUMBA_NUM_THREADS
        n = most if wanted <= 0 else min(wanted, most)
        if wanted > most:
            self.get_logger().warn(f'numba_threads {wanted} > NUMBA_NUM_THREADS {most}: '
                                   f'using {most}')
        numba.set_num_threads(n)
        self.numba_threads = n

    def _apply_pending(self) -> None:
        """Adopt the pending snapshot (start of every step/publication); rebuild if needed."""
        new = self.parameters.pending
        if new is self._settings:
            return
        old, self._settings = self._settings, new
        if new.scene != old.scene:
            try:
                rebuilt = self.sim.update_scene(new.scene)
            except GroomFileError as e:      # the file changed since the change was checked
                self.get_logger().error(f'groom.file: {e}; the hair is kept')
                self._settings = old
                self.parameters.keep(old)
                return
            if rebuilt:
                self.shedder.reset()
                self.rebuilds += 1
                self.get_logger().info(
                    f'groom changed: hair rebuilt ({self.sim.guides.count} guides, '
                    f'{self.sim.ghosts.count if self.sim.ghosts is not None else 0} ghosts)'
                    + (f'; {self.sim.groom_note}' if self.sim.groom_note else ''))
            self._gravity_used = None
            self._update_gravity()
            self._subscribe_tf()
        self._publish_scene()
        self._invalidate()

    # ================================================================ inputs
    def _reject(self, reason: str) -> None:
        self.rejected += 1
        self.get_logger().warn(f'head pose dropped ({self.rejected} so far): {reason}',
                               throttle_duration_sec=WARN_THROTTLE_S)

    def _on_pose(self, msg, from_tf: bool = False) -> None:
        """A head pose (PoseStamped, TransformStamped or a /tf entry): feed and step."""
        self._apply_pending()
        try:
            sample = pose_from_msg(msg)
        except (PoseError, TypeError, ValueError) as e:
            self._reject(str(e))
            return
        now_ns = self.get_clock().now().nanoseconds
        t_ns = sample.t_ns if sample.t_ns > 0 else now_ns
        if t_ns <= 0:
            self._reject('stamp is 0 and the node clock has not started '
                         '(use_sim_time without /clock?)')
            return
        offset = self._offset_ns
        if self._last_stamp_ns is not None and t_ns < self._last_stamp_ns:
            offset = 0                   # backwards: the simulator resets to this stamp
        elif self._last_stamp_ns is not None and \
                self.sim.time_ns > self._last_stamp_ns + offset and \
                t_ns + offset <= self.sim.time_ns:
            # The stream resumes behind the time the hair settled to while it was stale
            # (stamps slower than the node clock): continue one substep after it, do not
            # freeze.  Output stamps subtract the offset again.
            offset = self.sim.time_ns + self.sim.dt_ns - t_ns
        result = self.sim.push_pose(t_ns + offset, sample.position, sample.quaternion)
        if result is PoseResult.REJECTED:
            self._reject(self.sim.track.last_rejection)
            return
        if result is PoseResult.RESET_BACKWARDS:
            self.get_logger().info('head pose time went backwards: hair reset',
                                   throttle_duration_sec=WARN_THROTTLE_S)
        self._offset_ns = offset
        self._pose_frame = sample.frame_id
        self._pose_child = sample.child_frame_id
        self._last_arrival_ns = now_ns
        self._last_stamp_ns = t_ns
        if result.is_reset:
            self.shedder.reset()
        if not from_tf:
            self._broadcast_head(t_ns, sample.position, sample.quaternion)
        self._update_gravity()
        self._step(t_ns + offset)
        if self._settings.publish_on_pose and self._pose_frame_due():
            self._publish()
            self._pose_publish_at = time.monotonic()
        self._shed_load(t_ns)

    def _on_tf_static(self, msg) -> None:
        self._store_tf(msg, static=True)

    def _on_tf_dynamic(self, msg) -> None:
        """/tf without use_tf (for gravity_frame): the transforms are only kept."""
        self._store_tf(msg, static=False)

    def _store_tf(self, msg, static: bool) -> None:
        self._tf.add_message(msg, static=static)
        frame = self._body_frame()
        colliders = self.sim.collider_frames()
        if frame or colliders:
            now = self.get_clock().now().nanoseconds
            for tr in msg.transforms:
                child = str(tr.child_frame_id).lstrip('/')
                if child == frame:
                    self._body_seen = (now, static)
                if child in colliders:
                    self._frames_seen[child] = (now, static)
        if self._settings.gravity_frame and self._has_pose:
            self._update_gravity()

    def _on_tf(self, msg) -> None:
        """Pick the head transform out of a TFMessage (``head_frame`` or the prefix) and
        compose it with its parents' transforms (``/tf_static``, ``/tf``) up to the root."""
        self._store_tf(msg, static=False)
        self._apply_pending()
        prefix = self._settings.head_frame_prefix
        if self._tf_child is not None and not (prefix and self._tf_child.startswith(prefix)):
            self._tf_child = None        # the prefix changed: choose again
        now_ns = self.get_clock().now().nanoseconds
        for tr in msg.transforms:
            child = str(tr.child_frame_id).lstrip('/')
            if self._tf_sent_key is not None and self._tf_sent_key[0] == child:
                try:
                    if time_to_ns(tr.header.stamp) == self._tf_sent_key[1]:
                        continue         # this node's own broadcast (publish_tf)
                except ValueError:
                    pass
            if prefix:
                if not child.startswith(prefix):
                    continue
                stale = (now_ns - self._tf_seen_ns) * 1e-9 > self._settings.stale_timeout
                if self._tf_child is None or (child != self._tf_child and stale):
                    if self._tf_child != child:
                        self.get_logger().info(f'head frame from /tf: {child}')
                    self._tf_child = child
                if child != self._tf_child:
                    continue
                self._tf_seen_ns = now_ns
            elif child != self._settings.head_frame.lstrip('/'):
                continue
            self._on_pose(self._to_root(tr), from_tf=True)

    def _to_root(self, tr):
        """The head transform ``tr`` (parent -> head) expressed in the root of the parent's
        tree: ``root -> ... -> parent`` composed in front (``tr`` itself when the parent has
        no parent)."""
        try:
            root, t, q = self._tf.to_root(tr.header.frame_id)
        except ValueError as e:                  # a loop in the tree
            self.get_logger().warn(str(e), throttle_duration_sec=WARN_THROTTLE_S)
            return tr
        if root == str(tr.header.frame_id).lstrip('/'):
            return tr
        a, b = tr.transform.translation, tr.transform.rotation
        head = (np.array([a.x, a.y, a.z]), np.array([b.x, b.y, b.z, b.w]))
        pos, quat = tf_compose((t, q), head)
        out = TransformStamped()
        out.header.stamp = tr.header.stamp
        out.header.frame_id = root
        out.child_frame_id = tr.child_frame_id
        o, r = out.transform.translation, out.transform.rotation
        o.x, o.y, o.z = (float(v) for v in pos)
        r.x, r.y, r.z, r.w = (float(v) for v in quat)
        return out

    def _broadcast_head(self, t_ns: int, position, quaternion) -> None:
        """``publish_tf``: the accepted head pose on /tf, parent and child as the hair's
        fixed and head frames (:meth:`output_frame_id`), stamped with the pose's stamp."""
        s = self._settings
        if not s.publish_tf or self._tf_pub is None:
            return
        parent = self._pose_frame or s.fixed_frame or 'world'
        child = self._pose_child or s.head_frame or 'head'
        if parent.lstrip('/') == child.lstrip('/'):
            return
        q = np.asarray(quaternion, dtype=np.float64)
        self._tf_pub.publish(transform_message(t_ns, parent, child, position,
                                               q / np.linalg.norm(q)))
        self._tf_sent_key = (child.lstrip('/'), t_ns)
        self.tf_sent += 1

    def _update_gravity(self) -> None:
        """``gravity_frame``: the scene's gravity rotated into the pose's frame (through
        /tf_static and /tf) and handed to the simulator when it changed."""
        s = self._settings
        if not s.gravity_frame:
            return
        g = np.asarray(s.scene.gravity, dtype=np.float64)
        pose_frame = self._pose_frame or s.fixed_frame or 'world'
        try:
            found = self._tf.lookup(pose_frame, s.gravity_frame)
        except ValueError:                       # a loop in the tree
            found = None
        if found is None:
            self.get_logger().warn(
                f'gravity_frame {s.gravity_frame!r}: no transform to the pose frame '
                f'{pose_frame!r} on /tf_static or /tf yet; gravity taken in {pose_frame!r}',
                throttle_duration_sec=WARN_THROTTLE_S)
        else:
            g = quat_to_matrix(found[1]) @ g
        if self._gravity_used is not None and np.allclose(g, self._gravity_used, rtol=0.0,
                                                          atol=1e-9):
            return
        self._gravity_used = g
        self.sim.update_scene(dataclasses.replace(self.sim.scene,
                                                  gravity=tuple(float(v) for v in g)))

    def _body_frame(self) -> str:
        """The TF frame the scene's bust rides on ('' without one)."""
        body = self.sim.scene.body
        return body.frame.lstrip('/') if body.bust else ''

    def _frame_pose(self, frame: str, who: str, keeps: str):
        """``frame``'s pose in the pose's frame through /tf_static and /tf as (rotation matrix,
        position), or ``None`` (warned, throttled, naming ``who`` and what it ``keeps``)."""
        pose_frame = self._pose_frame or self._settings.fixed_frame or 'world'
        try:
            found = self._tf.lookup(pose_frame, frame)
        except ValueError:                       # a loop in the tree
            found = None
        if found is None:
            self.get_logger().warn(
                f'{who}: no transform from TF frame {frame!r} to the pose frame '
                f'{pose_frame!r} on /tf_static or /tf; {keeps}',
                throttle_duration_sec=WARN_THROTTLE_S)
            return None
        return quat_to_matrix(found[1]), found[0]

    def _update_body_frame(self) -> None:
        """``body.frame``: its pose handed to the simulator; the last one found is kept while
        none arrives."""
        frame = self._body_frame()
        if not frame:
            return
        found = self._frame_pose(frame, 'body.frame',
                                 'the bust keeps its last pose (the neck frame until one arrives)')
        if found is not None:
            self.sim.set_body_frame(*found)

    def _update_collider_frames(self) -> None:
        """The TF frames of the collider slots: each one's pose handed to the simulator; the
        last one found is kept while none arrives."""
        for frame in self.sim.collider_frames():
            found = self._frame_pose(frame, self._colliders_on(frame),
                                     'the collider keeps its last pose (off until one arrives)')
            if found is not None:
                self.sim.set_collider_frame(frame, *found)

    def _colliders_on(self, frame: str) -> str:
        """The collider slots riding on the TF frame ``frame``, as ``colliders.<slot>``."""
        return ', '.join(f'colliders.{slot}' for slot, c in self.sim.scene.colliders.used()
                         if c.frame.lstrip('/') == frame)

    def _step(self, t_ns: int) -> None:
        start = self._work_clock()
        self._update_body_frame()
        self._update_collider_frames()
        self.sim.advance_to(t_ns)
        self.step_ms.append((self._work_clock() - start) * 1e3)
        self._has_pose = True
        self._dirty = True

    def _shed_load(self, stamp_ns: int) -> None:
        """Track the ghosts once per pose while the steps do not fit the pose period
        (``load_shedding``; the policy is
        :class:`~hair_tracking.ros.load_shedding.LoadShedder`)."""
        s, sim = self._settings, self.sim
        if not (s.load_shedding and sim.ghost_tracker is not None
                and sim.scene.tracking.every_substep
                and sim.scene.tracking.mode == 'paper'):    # nothing to shed
            sim.track_once_per_call = False
            self._publish_ms_since_pose = 0.0
            return
        self.shedder.budget = s.load_shedding_budget
        c = sim.counters
        work = self.step_ms[-1] + self._publish_ms_since_pose   # this thread's time per pose
        self._publish_ms_since_pose = 0.0
        shed = self.shedder.update(stamp_ns, work, c.last_track_ms, c.last_substeps)
        if shed != sim.track_once_per_call:
            sim.track_once_per_call = shed
            self.get_logger().info(
                'load shedding: ghosts tracked once per pose (simulating and publishing took '
                f'more than {s.load_shedding_budget:g} of the pose period)' if shed else
                'load shedding ended: ghosts tracked as the scene says again')

    def _pose_frame_due(self) -> bool:
        """``publish_on_pose``: is this pose's frame due?  Once 0.9 publishing periods of
        *stream* time (the stamps) have passed since the last frame sent this way, or time went
        back.  Counting stamps rather than wall-clock time makes the set of frames a function of
        the input alone, as in ``hair_sim_bag run``: poses that DDS delivers in a burst (1 ms
        apart on the wall clock, 8 ms apart in their stamps) each get their frame, where a
        wall-clock cap skipped one and the next pose overwrote it before the timer sent it."""
        t = self.sim.time_ns
        last = self._pose_published_ns
        if last is not None and 0 <= t - last < 0.9e9 * self._settings.publish_period:
            return False
        self._pose_published_ns = t
        return True

    def _on_idle_timer(self) -> None:
        """A stale stream: hold the last pose and let the hair settle on the node clock."""
        self._apply_pending()
        if self._last_arrival_ns is None:
            return
        now_ns = self.get_clock().now().nanoseconds
        since = now_ns - self._last_arrival_ns
        if since * 1e-9 < self._settings.stale_timeout:
            return
        target = self._last_stamp_ns + self._offset_ns + since
        if self.sim.time_ns is not None and target > self.sim.time_ns:
            self._step(target)

    def _on_reset(self, request, response):
        self._apply_pending()
        self.sim.reset()
        self._invalidate()
        response.success = True
        response.message = 'hair reset to its rest shape at the current head pose'
        self.get_logger().info(response.message)
        return response

    # ================================================================ outputs
    def _invalidate(self) -> None:
        self._dirty = True
        for out in self.outputs.values():
            out.cached = None

    def _on_publish_timer(self) -> None:
        """The publishing rate: resend or rebuild the frame, unless a pose just sent one, or
        ``publish_on_pose`` sent one within the last period (the poses keep the rate then; a
        resend would only repeat their frame and keep the node from the next pose)."""
        self._apply_pending()
        now, period = time.monotonic(), self._settings.publish_period
        if now - self._last_publish < 0.5 * period:
            return                       # just published from a pose callback
        if self._settings.publish_on_pose and now - self._pose_publish_at < period:
            return
        self._publish()

    def output_frame_id(self) -> str:
        """frame_id of the published hair (see ``output_frame``)."""
        s = self._settings
        if s.output_frame == 'head':
            return self._pose_child or s.head_frame or 'head'
        return self._pose_frame or s.fixed_frame or 'world'

    def _publish(self) -> None:
        """Encode and publish the outputs somebody subscribes to (nothing else is built)."""
        if not self._has_pose:
            return
        self._publish_head()
        self._publish_colliders()
        outs = self.outputs
        s = self._settings
        self._publish_guide_state()
        wanted = {k: o.wanted() for k, o in outs.items()}
        if not s.publish_guides:
            wanted['guide_points'] = wanted['guide_markers'] = False
        if s.shards > 0:                 # the shards publish the ghosts
            wanted['points'] = wanted['markers'] = False
        self._last_publish = time.monotonic()
        if not any(wanted.values()):
            return
        start = self._work_clock()
        for o in outs.values():
            o.raw.direct = s.publish_through_rcl     # stays False where rcl is not usable
        reason = outs['points'].raw.reason
        if s.publish_through_rcl and reason and not self._rcl_refusal_logged:
            self.get_logger().warn(f'publish_through_rcl: {reason}; publishing through rclpy')
            self._rcl_refusal_logged = True
        if not self._dirty:              # same hair: resend the bytes (keeps markers alive)
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
        if wanted['markers'] or wanted['guide_markers']:
            frame = self.sim.frame(head_frame=head_frame, copy=False)
            self.frames_built += 1
        stamp = max(0, (self.sim.time_ns or 0) - self._offset_ns)   # the stream's time base
        self.encoder.settings = s
        encoded = self.encoder.frame(self.sim, [k for k, on in wanted.items() if on],
                                     self.output_frame_id(), stamp, head_frame, frame)
        for key, msg in encoded.items():
            o = outs[key]
            o.cached = None if msg.fresh else msg.data     # never resend a DELETEALL
            o.encoded += 1
            o.raw.publish(msg.data)
            o.published += 1
        self._dirty = False
        took = (self._work_clock() - start) * 1e3
        self.publish_ms.append(took)
        self._publish_ms_since_pose += took

    # ================================================================ ghost shards
    def _start_guide_state(self, depth: int, on: bool) -> None:
        """The publishers of the guides' state and the settings for hair_sim_ghosts (made
        always, like the guide clouds'); with ``on`` (``shards`` / ``publish_guide_state``)
        they publish, and this node's ghosts are placed from the guides as they send them."""
        if GuideState is None:
            if on:
                self.get_logger().warn('shards / publish_guide_state: hair_tracking_msgs is '
                                       'not installed, the guides\' state is not published')
            return
        self._guide_state_pub = self.create_publisher(GuideState, GUIDE_STATE_TOPIC,
                                                      output_qos(depth))
        self._scene_pub = self.create_publisher(String, SCENE_TOPIC, latched_qos())
        self._scene_text = None
        self._guide_sequence = 0
        self._guide_state_on = on
        if not on:
            return
        mode = self._settings.scene.tracking.mode
        if mode not in SHARDABLE:
            self.get_logger().warn(f'shards / publish_guide_state: tracking.mode {mode} cannot '
                                   f'be sharded (only {", ".join(SHARDABLE)}): no guides\' '
                                   'state is sent, and hair_sim_ghosts refuses these settings')
        self.sim.guides_as_float32 = True
        self._publish_scene()

    def _publish_scene(self) -> None:
        """The settings on the latched scene topic when they changed."""
        if self._scene_pub is None or not self._guide_state_on:
            return
        text = settings_text(self._settings)
        if text != self._scene_text:
            self._scene_text, self._scene_fingerprint = text, fingerprint(text)
            self._scene_pub.publish(String(data=text))

    def _publish_guide_state(self) -> None:
        """The guides' state of a frame whose ghosts were placed from the guides and head
        pose alone (not right after a reset or a jump, which carry the hair), once a frame."""
        tracker = self.sim.ghost_tracker
        if self._guide_state_pub is None or not self._guide_state_on or tracker is None or \
                not getattr(tracker, 'from_step', False):
            return
        key = (self.sim.time_ns, tracker.stats['steps'])
        if key == self._guide_state_key:
            return
        self._guide_state_key = key
        stamp = max(0, (self.sim.time_ns or 0) - self._offset_ns)
        self._guide_sequence = (self._guide_sequence + 1) % (1 << 32)
        self._guide_state_pub.publish(guide_state_bytes(
            self.sim, self._pose_frame or self._settings.fixed_frame or 'world', stamp,
            self._scene_fingerprint, self._guide_sequence))
        self.guide_states_sent += 1

    # ================================================================ diagnostics
    def diagnostics(self) -> DiagnosticStatus:
        """The node's health: timings, substeps, stretch, rejected poses (one status)."""
        sim = self.sim
        problems = []
        now_ns = self.get_clock().now().nanoseconds
        if self._last_arrival_ns is None:
            problems = ['waiting for a head pose']
        else:
            age = (now_ns - self._last_arrival_ns) * 1e-9
            if age > self._settings.stale_timeout:
                problems.append(f'head pose stale for {age:.1f} s (holding the last pose)')
        problems += self._health.problems(sim, self.rejected)
        if sim.track_once_per_call:
            problems.append('load shedding: ghosts tracked once per pose to keep up')
        body_frame, body_age = self._body_frame(), 'n/a'
        if body_frame:
            seen = self._body_seen
            if seen is None:
                problems.append(f'body.frame {body_frame!r} not received: the bust rides on '
                                'the neck frame')
            elif not seen[1]:
                body_age = f'{(now_ns - seen[0]) * 1e-9:.3f}'
                if (now_ns - seen[0]) * 1e-9 > self._settings.stale_timeout:
                    problems.append(f'body.frame {body_frame!r} stale for {body_age} s (the '
                                    'bust keeps its last pose)')
        for frame in sim.collider_frames():
            seen = self._frames_seen.get(frame)
            who = self._colliders_on(frame)
            if seen is None:
                problems.append(f'{who}: TF frame {frame!r} not received (off until it is)')
            elif not seen[1] and (now_ns - seen[0]) * 1e-9 > self._settings.stale_timeout:
                problems.append(f'{who}: TF frame {frame!r} stale for '
                                f'{(now_ns - seen[0]) * 1e-9:.3f} s (keeps its last pose)')
        step = list(self.step_ms)[-100:]
        pub = list(self.publish_ms)[-100:]
        ghosts = sim.ghosts.count if sim.ghosts is not None else 0
        parts = max(1, -(-ghosts // DIAG_AUDIT_STRANDS))
        part = self._audit_part % parts
        self._audit_part = part + 1
        stretch, depth, checked = sim.audit(part, parts)
        values = {
            'step_ms_last': f'{step[-1]:.3f}' if step else 'n/a',
            'step_ms_max_recent': f'{max(step):.3f}' if step else 'n/a',
            'publish_ms_last': f'{pub[-1]:.3f}' if pub else 'n/a',
            'publish_ms_max_recent': f'{max(pub):.3f}' if pub else 'n/a',
        }
        values.update(HairHealth.values(sim, stretch, depth, self.rejected, self.rebuilds,
                                        checked))
        values.update({
            'stream_offset_ms': f'{self._offset_ns * 1e-6:.3f}',
            'numba_threads': str(self.numba_threads),
            'load_shedding': 'active' if sim.track_once_per_call else
                             ('ready' if self._settings.load_shedding else 'off'),
            'load_shedding_switches': str(self.shedder.switches),
            'ghost_kernel': 'none' if sim.ghost_tracker is None else
                            ('parallel' if sim.ghost_tracker.stats['parallel'] else 'serial'),
            'output_frame': self.output_frame_id(),
            'tf_sent': str(self.tf_sent),
            'gravity_in_pose_frame': 'n/a' if self._gravity_used is None else
                                     ' '.join(f'{v:.4f}' for v in self._gravity_used),
            'body_frame_age_s': body_age,
        })
        if self._guide_state_on:
            values['guide_states_sent'] = str(self.guide_states_sent)
        return diagnostic_status(status_name(self.get_name()),
                                 make_status(WARN if problems else 0, problems, values))

    def _on_diag_timer(self) -> None:
        """Diagnostics at ``diagnostics_rate_hz``, listened to or not (an aggregator expects
        a steady rate)."""
        msg = DiagnosticArray(status=[self.diagnostics()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(msg)
        self.diagnostics_sent += 1

    # ================================================================ head marker
    def _publish_head(self) -> None:
        """The collider as a Marker on ``hair/head`` in the frame of the hair (``head_marker``;
        built only when somebody subscribes)."""
        s = self._settings
        if not s.head_marker or self._head_pub.get_subscription_count() == 0:
            return
        c = self.sim.scene.collider
        kw = {}
        if s.output_frame != 'head':
            kw = dict(head_position=self.sim.head.position,
                      head_quaternion=self.sim.head.quaternion)
        stamp = max(0, (self.sim.time_ns or 0) - self._offset_ns)
        self._head_pub.publish(collider_marker(
            c.shape, c.center, c.radius, c.radii, frame_id=self.output_frame_id(),
            stamp_ns=stamp, color=s.head_color, **kw))

    def _publish_colliders(self) -> None:
        """The body's capsules and spheres (the bust's, the collider slots') as markers on
        ``hair/colliders`` in the frame of the hair, at the head pose of the hair
        (``head_marker``; built only when somebody subscribes)."""
        s = self._settings
        body = getattr(self.sim.guide_solver, 'body', None)
        if body is None or not s.head_marker or \
                self._colliders_pub.get_subscription_count() == 0:
            return
        head = self.sim.head
        sh = body.posed_bare(head)
        sh = sh[np.isin(sh[:, KIND], (SPHERE, CAPSULE))]
        centers = sh[:, CX:CZ + 1]
        rots = sh[:, R00:R22 + 1].reshape(-1, 3, 3)
        if s.output_frame == 'head':
            centers = head.to_head(centers)
            rots = np.einsum('ji,kjl->kil', head.rotation, rots)
        stamp = max(0, (self.sim.time_ns or 0) - self._offset_ns)
        self._colliders_pub.publish(MarkerArray(markers=capsule_markers(
            centers, [matrix_to_quat(r) for r in rots], sh[:, A0], sh[:, A1],
            frame_id=self.output_frame_id(), stamp_ns=stamp, color=s.head_color)))

    # ================================================================ parameters files
    def warn_unknown_parameters(self, argv: List[str]) -> Dict[str, List[str]]:
        """:meth:`~hair_tracking.ros.parameters.NodeParameters.warn_unknown`."""
        return self.parameters.warn_unknown(argv)


# ==================================================================== helpers
def make_parser() -> argparse.ArgumentParser:
    """The command line of ``hair_sim_node`` in front of ``--ros-args``."""
    parser = argparse.ArgumentParser(
        prog='hair_sim_node',
        description='ROS 2 node that makes hair follow a head-pose stream: subscribes '
                    'head_pose (PoseStamped) and head_transform (TransformStamped), with use_tf '
                    '/tf and /tf_static (TFMessage); publishes hair/points (PointCloud2), '
                    'hair/markers (MarkerArray), hair/head (Marker, the head collider), '
                    'hair/colliders (MarkerArray, the body\'s bust, body.bust), /tf (the '
                    'head pose, publish_tf), /diagnostics, with publish_guides '
                    'hair/guides/points and hair/guides/markers, and with shards or '
                    'publish_guide_state hair/guides/state (GuideState) and hair/scene (the '
                    'settings, latched) for hair_sim_ghosts; offers ~/reset. Every setting '
                    'is a ROS parameter (see config/hair_sim.yaml and docs/node.md).',
        epilog='ROS arguments follow --ros-args, e.g. hair_sim_node --ros-args '
               '--params-file config/hair_sim.yaml -p scene_file:=long_hair '
               '-r head_pose:=/face/pose')
    executable.add_arguments(parser)
    return parser


def main(args=None) -> int:
    """Console entry point ``hair_sim_node``: init, spin until a stop is asked for, clean up.

    ``args`` is the whole command line (``sys.argv`` by default): the options before
    ``--ros-args`` are this executable's (``--help``, the process settings of
    :mod:`hair_tracking.executable`), the rest goes to rclpy.  Returns 0 once stopped (SIGINT or
    SIGTERM, in any state: :mod:`hair_tracking.shutdown`), 2 when the start parameters are
    invalid (the message names the parameter and the allowed values).
    """
    argv = list(sys.argv if args is None else args)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    options = make_parser().parse_args(argv[1:split])
    problem = params_files_problem(argv)      # before rcl, whose parse error is a traceback
    if problem:
        print(f'[hair_sim] {problem}', file=sys.stderr)
        return 2
    with executable.started() as stop:
        try:
            done = executable.apply(options)
        except ValueError as e:
            print(f'[hair_sim] {e}', file=sys.stderr)
            return 2

        def make_node() -> HairSimNode:
            node = HairSimNode()
            node.warn_unknown_parameters(argv)
            return node

        def user_error(e: Exception) -> Optional[str]:
            if isinstance(e, (ParamError, SceneError, ParameterException)):
                return f'[hair_sim] invalid parameters: {e}'
            if isinstance(e, RuntimeError):  # rcl refused the ROS arguments that
                problem = rcl_arguments_problem(e)     # params_files_problem passed
                return None if problem is None else f'[hair_sim] {problem}'
            return None

        return spin_node(NODE_NAME, make_node, argv[:1] + argv[split:], stop, done,
                         options.gc_freeze, user_error)


if __name__ == '__main__':
    sys.exit(main())
