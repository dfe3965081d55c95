"""The ``hair_sim`` node's TF frames.

:class:`Frames` is the node's one TF tree: ``/tf_static`` and ``/tf`` subscribed once, when
something reads TF (``use_tf``, ``gravity_frame``, ``body.frame``, a collider slot on a TF frame,
``people.source: hri``), every transform stored once, and each message then handed to the
listeners (the head from ``/tf``, the people's faces).  With ``people.source: hri`` the dynamic
``face_<id>`` frames are not stored (their random ids would pile up; the people read them from
the message).  It also broadcasts the head pose on ``/tf`` (``publish_tf``).

:class:`SceneFrames` turns the tree into the simulator's per-step inputs: gravity given in
``gravity_frame`` rotated into the pose's frame, the pose of ``body.frame`` and of each collider
slot's frame (the last one found kept while none arrives).
"""
from typing import Callable, Dict, List, Optional, Set, Tuple

from geometry_msgs.msg import TransformStamped
import numpy as np

from msg_adapters.tf import transform_message, transforms
from msg_adapters.tf_tree import compose as tf_compose, TfTree

from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.people.roster import face_id
from hair_tracking.ros.topics import best_effort_qos, tf_out_qos, tf_static_qos, \
    WARN_THROTTLE_S

try:                                    # optional: /tf input and output
    from tf2_msgs.msg import TFMessage
except ImportError:                     # pragma: no cover - depends on the installation
    TFMessage = None


class Frames:
    """The one TF tree of ``node`` (see the module docstring).

    ``listeners`` are called with each message and whether it is static, after it was stored;
    ``seen`` holds the arrival time [ns] on the node clock and staticness of each frame of
    ``watched`` (``body.frame``, the collider slots' frames)."""

    def __init__(self, node, skip_faces: bool = False):
        self._node = node
        self.tree = TfTree()
        self.skip_faces = skip_faces
        self.listeners: List[Callable] = []
        self.subscribed = False
        self.watched: Set[str] = set()
        self.seen: Dict[str, Tuple[int, bool]] = {}
        self._pub = None                 # publish_tf
        self._sent_key = None            # (child, stamp) of the last transform broadcast
        self.sent = 0

    # ---------------------------------------------------------------- input
    def subscribe(self, who: str) -> None:
        """``/tf`` and ``/tf_static``, once (``who`` asks for them: named in the warning when
        tf2_msgs is missing)."""
        if self.subscribed:
            return
        self.subscribed = True
        if TFMessage is None:
            self._node.get_logger().warn(f'{who}: /tf is needed but tf2_msgs is not '
                                         'installed, it is not subscribed')
            return
        self._node.create_subscription(TFMessage, '/tf', self.on_tf, best_effort_qos())
        self._node.create_subscription(TFMessage, '/tf_static', self.on_tf_static,
                                       tf_static_qos())

    def on_tf_static(self, msg) -> None:
        self._store(msg, static=True)

    def on_tf(self, msg) -> None:
        self._store(msg, static=False)

    def _store(self, msg, static: bool) -> None:
        if static or not self.skip_faces:
            self.tree.add_message(msg, static=static)
        else:
            for parent, child, t, q, stamp in transforms(msg):
                if face_id(child) is None:
                    self.tree.set(parent, child, t, q, stamp)
        if self.watched:
            now = self._node.get_clock().now().nanoseconds
            for tr in msg.transforms:
                child = str(tr.child_frame_id).lstrip('/')
                if child in self.watched:
                    self.seen[child] = (now, static)
        for listener in self.listeners:
            listener(msg, static)

    # ---------------------------------------------------------------- lookups
    def lookup(self, target: str, source: str):
        """``(translation, rotation)`` from ``source`` into ``target`` through the tree, or
        None (not in one tree, or a loop)."""
        try:
            return self.tree.lookup(target, source)
        except ValueError:                       # a loop in the tree
            return None

    def frame_pose(self, pose_frame: str, frame: str, who: str, keeps: str):
        """``frame``'s pose in ``pose_frame`` as (rotation matrix, position), or ``None``
        (warned, throttled, naming ``who`` and what it ``keeps``)."""
        found = self.lookup(pose_frame, frame)
        if found is None:
            self._node.get_logger().warn(
                f'{who}: no transform from TF frame {frame!r} to the pose frame '
                f'{pose_frame!r} on /tf_static or /tf; {keeps}',
                throttle_duration_sec=WARN_THROTTLE_S)
            return None
        return quat_to_matrix(found[1]), found[0]

    def to_root(self, tr):
        """The transform ``tr`` (parent -> child) expressed in the root of the parent's tree:
        ``root -> ... -> parent`` composed in front (``tr`` itself when the parent has no
        parent)."""
        try:
            root, t, q = self.tree.to_root(tr.header.frame_id)
        except ValueError as e:                  # a loop in the tree
            self._node.get_logger().warn(str(e), throttle_duration_sec=WARN_THROTTLE_S)
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

    # ---------------------------------------------------------------- output
    @property
    def publisher(self):
        """The ``/tf`` publisher of :meth:`broadcast` (None while ``publish_tf`` is off)."""
        return self._pub

    def broadcasting(self, on: bool) -> None:
        """Create or destroy the ``/tf`` publisher (``publish_tf``)."""
        if on and self._pub is None:
            if TFMessage is None:
                self._node.get_logger().warn('publish_tf is true but tf2_msgs is not '
                                             'installed: the head pose is not broadcast on /tf')
                return
            self._pub = self._node.create_publisher(TFMessage, '/tf', tf_out_qos())
        elif not on and self._pub is not None:
            self._node.destroy_publisher(self._pub)
            self._pub = None

    def broadcast(self, t_ns: int, parent: str, child: str, position, quaternion) -> None:
        """``parent -> child`` on /tf, stamped ``t_ns`` (nothing while not broadcasting)."""
        if self._pub is None or parent.lstrip('/') == child.lstrip('/'):
            return
        q = np.asarray(quaternion, dtype=np.float64)
        self._pub.publish(transform_message(t_ns, parent, child, position,
                                            q / np.linalg.norm(q)))
        self._sent_key = (child.lstrip('/'), t_ns)
        self.sent += 1

    def is_own(self, child: str, stamp_ns: Optional[int]) -> bool:
        """Whether the transform of ``child`` stamped ``stamp_ns`` is this node's broadcast."""
        return self._sent_key is not None and self._sent_key == (child, stamp_ns)


class SceneFrames:
    """The scene's frames as the simulator's per-step inputs (see the module docstring):
    ``frames`` the tree, ``sim()`` the simulator, ``settings()`` the node's settings,
    ``pose_frame()`` the frame the head poses are given in."""

    def __init__(self, node, frames: Frames, sim: Callable, settings: Callable,
                 pose_frame: Callable[[], str]):
        self._node = node
        self.frames = frames
        self._sim = sim
        self._settings = settings
        self._pose_frame = pose_frame
        self.gravity_used = None         # gravity in the pose's frame given to the simulator

    def body_frame(self) -> str:
        """The TF frame the scene's bust rides on ('' without one)."""
        body = self._sim().scene.body
        return body.frame.lstrip('/') if body.bust else ''

    def needs_tf(self) -> bool:
        """Whether gravity, the bust or a collider slot reads TF."""
        return bool(self._settings().gravity_frame or self.body_frame() or
                    self._sim().collider_frames())

    def watch(self) -> None:
        """The frames whose arrival :class:`Frames` records (scene changes move them)."""
        self.frames.watched = {f for f in (self.body_frame(),) if f} | \
            set(self._sim().collider_frames())

    def scene_changed(self) -> None:
        """A new scene: gravity handed over again, the frames watched anew."""
        self.gravity_used = None
        self.update_gravity()
        self.watch()

    def update_gravity(self) -> None:
        """``gravity_frame``: the scene's gravity rotated into the pose's frame (through
        /tf_static and /tf) and handed to the simulator when it changed."""
        s = self._settings()
        if not s.gravity_frame:
            return
        g = np.asarray(s.scene.gravity, dtype=np.float64)
        pose_frame = self._pose_frame()
        found = self.frames.lookup(pose_frame, s.gravity_frame)
        if found is None:
            self._node.get_logger().warn(
                f'gravity_frame {s.gravity_frame!r}: no transform to the pose frame '
                f'{pose_frame!r} on /tf_static or /tf yet; gravity taken in {pose_frame!r}',
                throttle_duration_sec=WARN_THROTTLE_S)
        else:
            g = quat_to_matrix(found[1]) @ g
        if self.gravity_used is not None and np.allclose(g, self.gravity_used, rtol=0.0,
                                                         atol=1e-9):
            return
        self.gravity_used = g
        self._sim().set_gravity(g)

    def update_bodies(self) -> None:
        """``body.frame`` and the collider slots' frames: each one's pose handed to the
        simulator; the last one found is kept while none arrives."""
        sim, pose_frame = self._sim(), self._pose_frame()
        frame = self.body_frame()
        if frame:
            found = self.frames.frame_pose(
                pose_frame, frame, 'body.frame',
                'the bust keeps its last pose (the neck frame until one arrives)')
            if found is not None:
                sim.set_body_frame(*found)
        for frame in sim.collider_frames():
            found = self.frames.frame_pose(
                pose_frame, frame, self.colliders_on(frame),
                'the collider keeps its last pose (off until one arrives)')
            if found is not None:
                sim.set_collider_frame(frame, *found)

    def colliders_on(self, frame: str) -> str:
        """The collider slots riding on the TF frame ``frame``, as ``colliders.<slot>``."""
        return ', '.join(f'colliders.{slot}' for slot, c in self._sim().scene.colliders.used()
                         if c.frame.lstrip('/') == frame)

    def problems(self, now_ns: int, stale_timeout: float) -> Tuple[List[str], str]:
        """What the diagnostics say about ``body.frame`` and the collider frames, and the age
        of ``body.frame`` [s] as text ('n/a' without one or while static)."""
        problems, body_age = [], 'n/a'
        seen_all = self.frames.seen
        body_frame = self.body_frame()
        if body_frame:
            seen = seen_all.get(body_frame)
            if seen is None:
                problems.append(f'body.frame {body_frame!r} not received: the bust rides on '
                                'the neck frame')
            elif not seen[1]:
                body_age = f'{(now_ns - seen[0]) * 1e-9:.3f}'
                if (now_ns - seen[0]) * 1e-9 > stale_timeout:
                    problems.append(f'body.frame {body_frame!r} stale for {body_age} s (the '
                                    'bust keeps its last pose)')
        for frame in self._sim().collider_frames():
            seen = seen_all.get(frame)
            who = self.colliders_on(frame)
            if seen is None:
                problems.append(f'{who}: TF frame {frame!r} not received (off until it is)')
            elif not seen[1] and (now_ns - seen[0]) * 1e-9 > stale_timeout:
                problems.append(f'{who}: TF frame {frame!r} stale for '
                                f'{(now_ns - seen[0]) * 1e-9:.3f} s (keeps its last pose)')
        return problems, body_age
