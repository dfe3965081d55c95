"""The ``hair_sim`` node's head-pose intake: ``head_pose`` (PoseStamped), ``head_transform``
(TransformStamped) and, with ``use_tf``, the head's transform on ``/tf``.

Each pose is checked (NaN/Inf or zero-quaternion poses are dropped, counted and warned about,
throttled), its stamp mapped onto the simulator's time
(:class:`~hair_tracking.core.head_track.StreamClock`; a stamp of 0 means "now" on the node clock,
so ``use_sim_time`` is honoured), pushed, broadcast on ``/tf`` (``publish_tf``) and stepped to;
with ``publish_on_pose`` its frame is published when a period of stream time has passed.
Without poses for ``stale_timeout`` the last pose is held and the hair keeps settling, stepped
from the node clock (:meth:`PoseIntake.on_idle`).  Load shedding
(:class:`~hair_tracking.ros.load_shedding.LoadShedder`) weighs each pose's work.
"""
import collections
import time
from typing import Optional

from msg_adapters.pose import pose_from_msg, PoseError
from msg_adapters.stamps import time_to_ns

from hair_tracking.core.head_track import PoseResult, StreamClock
from hair_tracking.ros.topics import WARN_THROTTLE_S


class PoseIntake:
    """The head poses of ``node`` (a :class:`~hair_tracking.ros.node.HairSimNode`: its
    ``sim``, ``settings``, ``frames``, ``scene_frames``, ``publishing``, ``shedder``,
    ``work_clock`` and ``apply_pending()``)."""

    def __init__(self, node):
        self._node = node
        self.clock = StreamClock()
        self.frame_id = ''               # header.frame_id of the last pose
        self.child_frame_id = ''         # child_frame_id of the last pose ('' for PoseStamped)
        self.last_arrival_ns: Optional[int] = None    # node clock at the last accepted pose
        self.has_pose = False
        self.rejected = 0                # poses dropped (malformed, NaN, zero quaternion ...)
        self.step_ms = collections.deque(maxlen=1000)
        self.tf_child: Optional[str] = None     # the /tf child chosen by head_frame_prefix
        self.tf_seen_ns = 0
        self._pose_published_ns = None   # sim time of the last frame publish_on_pose sent

    def pose_frame(self) -> str:
        """The fixed frame of the head poses (``fixed_frame`` until one names it)."""
        return self.frame_id or self._node.settings.fixed_frame or 'world'

    def head_frame(self) -> str:
        """The head's frame (``head_frame`` unless the pose names its child frame)."""
        return self.child_frame_id or self._node.settings.head_frame or 'head'

    def stamp(self) -> int:
        """The stream stamp of the simulator's time (what the outputs are stamped with)."""
        return self.clock.stamp(self._node.sim.time_ns)

    def _reject(self, reason: str) -> None:
        self.rejected += 1
        self._node.get_logger().warn(f'head pose dropped ({self.rejected} so far): {reason}',
                                     throttle_duration_sec=WARN_THROTTLE_S)

    def on_pose(self, msg, from_tf: bool = False) -> None:
        """A head pose (PoseStamped, TransformStamped or a /tf entry): feed and step."""
        node = self._node
        node.apply_pending()
        try:
            sample = pose_from_msg(msg)
        except (PoseError, TypeError, ValueError) as e:
            self._reject(str(e))
            return
        now_ns = node.get_clock().now().nanoseconds
        t_ns = sample.t_ns if sample.t_ns > 0 else now_ns
        if t_ns <= 0:
            self._reject('stamp is 0 and the node clock has not started '
                         '(use_sim_time without /clock?)')
            return
        sim = node.sim
        sim_t, offset = self.clock.sim_time(t_ns, sim.time_ns, sim.dt_ns)
        result = sim.push_pose(sim_t, sample.position, sample.quaternion)
        if result is PoseResult.REJECTED:
            self._reject(sim.track.last_rejection)
            return
        if result is PoseResult.RESET_BACKWARDS:
            node.get_logger().info('head pose time went backwards: hair reset',
                                   throttle_duration_sec=WARN_THROTTLE_S)
        self.clock.accept(t_ns, offset)
        self.frame_id = sample.frame_id
        self.child_frame_id = sample.child_frame_id
        self.last_arrival_ns = now_ns
        if result.is_reset:
            node.shedder.reset()
        if not from_tf and node.settings.publish_tf:
            node.frames.broadcast(t_ns, self.pose_frame(), self.head_frame(), sample.position,
                                  sample.quaternion)
        node.scene_frames.update_gravity()
        self.step(sim_t)
        publishing = node.publishing
        if node.settings.publish_on_pose and self.pose_frame_due():
            publishing.publish()
            publishing.pose_publish_at = time.monotonic()
        self._shed_load(t_ns)

    def on_tf(self, msg, static: bool) -> None:
        """``use_tf``: pick the head transform out of a TFMessage (``head_frame`` or the
        prefix) and compose it with its parents' transforms up to the root."""
        if static:
            return
        node = self._node
        node.apply_pending()
        s = node.settings
        prefix = s.head_frame_prefix
        if self.tf_child is not None and not (prefix and self.tf_child.startswith(prefix)):
            self.tf_child = None         # the prefix changed: choose again
        now_ns = node.get_clock().now().nanoseconds
        for tr in msg.transforms:
            child = str(tr.child_frame_id).lstrip('/')
            try:
                if node.frames.is_own(child, time_to_ns(tr.header.stamp)):
                    continue             # this node's own broadcast (publish_tf)
            except ValueError:
                pass
            if prefix:
                if not child.startswith(prefix):
                    continue
                stale = (now_ns - self.tf_seen_ns) * 1e-9 > s.stale_timeout
                if self.tf_child is None or (child != self.tf_child and stale):
                    if self.tf_child != child:
                        node.get_logger().info(f'head frame from /tf: {child}')
                    self.tf_child = child
                if child != self.tf_child:
                    continue
                self.tf_seen_ns = now_ns
            elif child != s.head_frame.lstrip('/'):
                continue
            self.on_pose(node.frames.to_root(tr), from_tf=True)

    def step(self, t_ns: int) -> None:
        """Hand the frames' poses over and step the simulator to ``t_ns``."""
        node = self._node
        start = node.work_clock()
        node.scene_frames.update_bodies()
        node.sim.advance_to(t_ns)
        self.step_ms.append((node.work_clock() - start) * 1e3)
        self.has_pose = True
        node.publishing.dirty = True

    def _shed_load(self, stamp_ns: int) -> None:
        """Track the ghosts once per pose while the steps do not fit the pose period
        (``load_shedding``)."""
        node = self._node
        s, sim, publishing = node.settings, node.sim, node.publishing
        if not (s.load_shedding and sim.ghost_tracker is not None
                and sim.scene.tracking.every_substep
                and sim.scene.tracking.mode == 'paper'):    # nothing to shed
            sim.track_once_per_call = False
            publishing.ms_since_pose = 0.0
            return
        node.shedder.budget = s.load_shedding_budget
        c = sim.counters
        work = self.step_ms[-1] + publishing.ms_since_pose   # this thread's time per pose
        publishing.ms_since_pose = 0.0
        shed = node.shedder.update(stamp_ns, work, c.last_track_ms, c.last_substeps)
        if shed != sim.track_once_per_call:
            sim.track_once_per_call = shed
            node.get_logger().info(
                'load shedding: ghosts tracked once per pose (simulating and publishing took '
                f'more than {s.load_shedding_budget:g} of the pose period)' if shed else
                'load shedding ended: ghosts tracked as the scene says again')

    def pose_frame_due(self) -> bool:
        """``publish_on_pose``: is this pose's frame due?  Once 0.9 publishing periods of
        *stream* time (the stamps) have passed since the last frame sent this way, or time went
        back.  Counting stamps rather than wall-clock time makes the set of frames a function of
        the input alone, as in ``hair_sim_bag run``: poses that DDS delivers in a burst (1 ms
        apart on the wall clock, 8 ms apart in their stamps) each get their frame, where a
        wall-clock cap skipped one and the next pose overwrote it before the timer sent it."""
        t = self._node.sim.time_ns
        last = self._pose_published_ns
        if last is not None and 0 <= t - last < 0.9e9 * self._node.settings.publish_period:
            return False
        self._pose_published_ns = t
        return True

    def on_idle(self) -> None:
        """A stale stream: hold the last pose and let the hair settle on the node clock."""
        node = self._node
        node.apply_pending()
        if self.last_arrival_ns is None:
            return
        since = node.get_clock().now().nanoseconds - self.last_arrival_ns
        if since * 1e-9 < node.settings.stale_timeout:
            return
        target = self.clock.last_stamp_ns + self.clock.offset_ns + since
        if node.sim.time_ns is not None and target > node.sim.time_ns:
            self.step(target)
