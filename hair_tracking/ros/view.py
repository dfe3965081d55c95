"""``hair_sim_view``: the live hair and the head in 3-D in a web browser, from the node's topics.

    hair_sim_view                         # then open http://127.0.0.1:8080
    hair_sim_view --follow --port 8090    # a walking head (hair_sim_bag play) stays in view

It subscribes to ``hair/points`` (or, with ``--shards N``, to the N ghost shards' clouds
``hair/shard_<k>/points``, joined: :class:`~hair_tracking.ros.view_geometry.ShardClouds`) (the
organized sensor_msgs/PointCloud2 of :mod:`.node`: one row per strand, ``x y z`` float32, packed
``rgb``) and ``hair/head`` (the collider as a visualization_msgs/Marker SPHERE, ``scale`` =
diameters) and draws each strand as line segments between its consecutive points in the cloud's
colours, and the head as an opaque ellipsoid, both as given in the frame of the cloud (``--follow``
shifts the view so that the head's centre stays at its origin). It draws the body's colliders too,
from ``hair/colliders`` (a visualization_msgs/MarkerArray of SPHEREs and CYLINDERs: the node's
bust, each capsule a cylinder and two spheres, :mod:`msg_adapters.capsule_markers`), as solids in
the cloud's frame. It only subscribes (reliable, keep last, as the node publishes): it changes
nothing in the node. Redraws are limited to ``--rate`` per second; messages that come faster
replace each other.

The page is served by `viser <https://viser.studio>`_ (``pip install viser``, an optional
dependency: the node and the simulation never import it), a Python library whose wheel
carries its whole three.js client (one 0.8 MB page), so it works offline and needs nothing
but a browser.  The server listens on 127.0.0.1 unless ``--host`` says otherwise, and viser's
share button (a public tunnel) is hidden.  Rejected alternatives, checked on their current
wheels:

* rerun-sdk (0.41): its own data model (archetypes logged from Python, not ROS messages), a
  170 MB Linux wheel holding a native viewer, and a web viewer that is a separate 17 MB
  package (``rerun-notebook``, a 67 MB wasm file unpacked);
* foxglove-sdk (0.30): a WebSocket server for the Foxglove app; the wheel has no viewer page
  (its notebook widget embeds the hosted app in an iframe), so the app must come from the
  web or a desktop install, which a pip-only user on an offline machine does not have.

Exit codes: 0 after Ctrl-C or an external shutdown, 1 when viser is not installed, 2 bad
command line.
"""
import argparse
import math
import sys
import threading
import time
from typing import List, Optional, Tuple

import numpy as np
from sensor_msgs.msg import PointCloud2
from visualization_msgs.msg import Marker, MarkerArray

from hair_tracking import executable, shutdown
from hair_tracking.ros.view_geometry import cloud_segments, collider_solids, framing, \
    head_shape, HeadShape, Latest, ShardClouds, Solid, srgb_to_linear_u8, strand_stride

DEFAULT_PORT = 8080
NAME = 'hair_sim_view'


# ==================================================================== the scene
class HairScene:
    """The viser scene: the strands as one set of line segments, the head as an icosphere
    scaled to the ellipsoid, a ground grid, and a line of text about what is shown.  Called
    from one thread (the spin loop); viser sends the changes to every connected browser.

    The data are drawn in the cloud's frame as given, through two frame nodes: ``/cloud`` (at
    the origin; with ``follow`` shifted so that the head stays at the origin while the grid
    slides by) and ``/cloud/head`` at the head's centre, which carries the head and the
    strands (sent relative to it).  A moving head then moves its hair with one transform,
    the same one as the head's, instead of a new set of points that a slow browser shows a
    few frames later than the head (seen at 6 frames/s with software WebGL)."""

    def __init__(self, server, *, max_strands: int = 0, line_width: float = 2.0,
                 follow: bool = False, topics: Tuple[str, str] = ('hair/points', 'hair/head')):
        self.server = server
        self.max_strands = int(max_strands)
        self.line_width = float(line_width)
        self.follow = bool(follow)
        self.topics = topics
        scene = server.scene
        scene.set_up_direction('+z')
        self._root = scene.add_frame('/cloud', show_axes=False)
        scene.add_grid('/cloud/grid', width=2.0, height=2.0, cell_size=0.1, section_size=0.5,
                       plane='xy')
        self._anchor = scene.add_frame('/cloud/head', show_axes=False)
        self._at = np.zeros(3)               # where /cloud/head is, in the cloud's frame
        self._lines = self._colors = self._head = self._head_shape = None
        self._framed_at = None
        # Browsers to turn to the hair: a browser's camera can be set only after it has
        # reported its own (viser's camera handle refuses before), so those that have not yet
        # are turned when they do (viser calls back from its worker threads).
        self._lock = threading.Lock()
        self._reported, self._to_turn = set(), set()
        server.on_client_connect(self._on_connect)
        server.on_client_disconnect(self._on_disconnect)
        self._solids: List[Solid] = []
        self._solid_handles: list = []
        self._status = server.gui.add_markdown(f'waiting for `{topics[0]}` ...')
        self._status_text = None
        self.clouds_drawn = 0

    def show(self, head: Optional[Marker], cloud: Optional[PointCloud2]) -> None:
        """Draw a head marker and a cloud (either may be None: unchanged), as one update."""
        shape = head_shape(head) if head is not None else self._head_shape
        seg = col = None
        if cloud is not None:
            seg, col = cloud_segments(cloud, self.max_strands)
        if shape is not None:
            at = np.array(shape.position)
        elif self.follow and seg is not None and len(seg):
            pts = seg.reshape(-1, 3)
            at = 0.5 * (pts.min(axis=0) + pts.max(axis=0)).astype(np.float64)
        else:
            at = self._at
        with self.server.atomic():
            if not np.array_equal(at, self._at):
                self._at = at
                self._anchor.position = tuple(at)
                if self.follow:
                    self._root.position = tuple(-at)
            if shape != self._head_shape:
                self._show_head(shape)
            if seg is not None:
                self._show_strands(seg - at.astype(np.float32), col)
        if shape is not None or seg is not None:
            self._frame(seg if seg is not None else np.zeros((0, 2, 3)),
                        turn_browsers=self._framed_at is None or
                        (seg is not None and not self.clouds_drawn))
        if cloud is not None:
            drawn = -(-cloud.height // strand_stride(cloud.height, self.max_strands))
            self._set_status(f'`{self.topics[0]}`: {drawn} of {cloud.height} strands x '
                             f'{cloud.width} points, frame `{cloud.header.frame_id}`'
                             + (', following the head' if self.follow else ''))
            self.clouds_drawn += 1

    def show_colliders(self, array: MarkerArray) -> None:
        """Draw the colliders of a MarkerArray (:func:`collider_solids`) in the cloud's frame,
        replacing those drawn before."""
        solids = collider_solids(array)
        if solids == self._solids:
            return
        scene = self.server.scene
        with self.server.atomic():
            for handle in self._solid_handles:
                handle.remove()
            self._solid_handles = []
            for k, s in enumerate(solids):
                name = f'/cloud/colliders/{k}'
                if s.kind == 'sphere':
                    handle = scene.add_icosphere(name, radius=1.0, color=s.rgb, subdivisions=3,
                                                 scale=s.size, wxyz=s.wxyz, position=s.position)
                else:
                    handle = scene.add_cylinder(name, radius=s.size[0], height=s.size[2],
                                                color=s.rgb, wxyz=s.wxyz, position=s.position)
                self._solid_handles.append(handle)
        self._solids = solids

    def _show_strands(self, seg: np.ndarray, col: np.ndarray) -> None:
        if self._lines is None or self._lines.points.shape != seg.shape:
            self._lines = self.server.scene.add_line_segments(
                '/cloud/head/hair', seg, srgb_to_linear_u8(col), thickness=self.line_width,
                thickness_units='screen')
            self._colors = col
            return
        self._lines.points = seg
        if not np.array_equal(col, self._colors):
            self._lines.colors = srgb_to_linear_u8(col)
            self._colors = col

    def _show_head(self, shape: Optional[HeadShape]) -> None:
        self._head_shape = shape
        if shape is None:
            if self._head is not None:
                self._head.visible = False
        elif self._head is None:
            self._head = self.server.scene.add_icosphere(
                '/cloud/head/ellipsoid', radius=1.0, color=shape.rgb, subdivisions=4,
                scale=shape.semi_axes, wxyz=shape.wxyz)
        else:
            self._head.color = shape.rgb
            self._head.scale = shape.semi_axes
            self._head.wxyz = shape.wxyz
            self._head.visible = True

    def _frame(self, seg: np.ndarray, turn_browsers: bool = False) -> None:
        """Point the camera at the hair and the head (``seg`` in the cloud's frame): the
        browsers' start and 'Reset View' pose, updated when they have moved by more than half
        the viewing distance; with ``turn_browsers`` (the first head, the first cloud) the
        browsers already open are turned to it too."""
        got = framing(seg, self._head_shape)
        if got is None:
            return
        shift = -self._at if self.follow else np.zeros(3)
        look_at, position = (v + shift for v in got)
        if not turn_browsers and self._framed_at is not None and \
                np.linalg.norm(look_at - self._framed_at[0]) < \
                0.5 * np.linalg.norm(self._framed_at[1] - self._framed_at[0]):
            return
        self._framed_at = (look_at, position)
        cam = self.server.initial_camera
        cam.look_at, cam.position = tuple(look_at), tuple(position)
        if turn_browsers:
            for client in self.server.get_clients().values():
                with self._lock:
                    if client.client_id not in self._reported:
                        self._to_turn.add(client.client_id)
                        continue
                self._turn(client.camera)

    def _turn(self, camera) -> None:
        look_at, position = self._framed_at
        camera.look_at, camera.position = tuple(look_at), tuple(position)

    def _on_connect(self, client) -> None:
        client.camera.on_update(self._on_camera)

    def _on_camera(self, camera) -> None:
        cid = camera.client.client_id
        with self._lock:
            self._reported.add(cid)
            turn = cid in self._to_turn and self._framed_at is not None
            self._to_turn.discard(cid)
        if turn:
            self._turn(camera)

    def _on_disconnect(self, client) -> None:
        with self._lock:
            self._reported.discard(client.client_id)
            self._to_turn.discard(client.client_id)

    def _set_status(self, text: str) -> None:
        if text != self._status_text:
            self._status.content = text
            self._status_text = text


# ==================================================================== command line
def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=NAME,
        description='Show the live hair and the head of a running hair_sim node in 3-D in a '
                    'web browser: subscribes to hair/points (PointCloud2) and hair/head '
                    '(Marker) and serves a page (viser, pip install viser) at '
                    'http://127.0.0.1:8080 by default. It only subscribes: it changes '
                    'nothing in the node.',
        epilog='ROS arguments follow --ros-args (e.g. -r __ns:=/robot). The page is served '
               'on 127.0.0.1 only unless --host says otherwise (e.g. --host 0.0.0.0 for '
               'every interface: anyone who can reach the port sees the hair).')
    parser.add_argument('--host', default='127.0.0.1',
                        help='address to listen on (default: 127.0.0.1, this machine only)')
    parser.add_argument('--port', type=int, default=DEFAULT_PORT,
                        help='port of the page (default: %(default)s; if it is taken, the '
                             'next free one, printed at start)')
    parser.add_argument('--points-topic', default='hair/points',
                        help='organized PointCloud2 of the strands (default: %(default)s)')
    parser.add_argument('--shards', type=int, default=0,
                        help='join the clouds of this many ghost shards (hair_sim_ghosts, '
                             'hair/shard_<k>/points) instead of --points-topic (default: '
                             '%(default)s, none)')
    parser.add_argument('--head-topic', default='hair/head',
                        help="the head's SPHERE Marker; '' for none (default: %(default)s)")
    parser.add_argument('--colliders-topic', default='hair/colliders',
                        help="the body's colliders (MarkerArray of SPHEREs and CYLINDERs); '' "
                             "for none (default: %(default)s)")
    parser.add_argument('--rate', type=float, default=30.0,
                        help='most redraws per second (default: %(default)s)')
    parser.add_argument('--max-strands', type=int, default=4096,
                        help='draw every k-th strand so that at most this many are drawn; 0 '
                             'for all (default: %(default)s)')
    parser.add_argument('--line-width', type=float, default=2.0,
                        help='strand width in pixels (default: %(default)s)')
    parser.add_argument('--follow', action='store_true',
                        help="keep the head's centre at the origin of the view (a head that "
                             "walks, e.g. from hair_sim_bag play, stays in view); without it "
                             "everything is drawn where the messages put it")
    return parser


def _check(options) -> Optional[str]:
    if not (options.rate > 0 and math.isfinite(options.rate)):
        return f'--rate must be a positive number, got {options.rate}'
    if not 0 <= options.port <= 65535:
        return f'--port must be 0..65535, got {options.port}'
    if options.max_strands < 0:
        return f'--max-strands must be >= 0, got {options.max_strands}'
    if not options.line_width > 0:
        return f'--line-width must be > 0, got {options.line_width}'
    if not options.points_topic:
        return '--points-topic must not be empty'
    if options.shards < 0:
        return f'--shards must be >= 0, got {options.shards}'
    return None


def serve(options, ros_args: List[str], stop: shutdown.StopRequest) -> int:
    """Start the page and the subscriptions; spin until a stop is asked for (``stop``)."""
    import viser
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rclpy.signals import SignalHandlerOptions

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=2,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    server = node = executor = None
    latest = Latest()
    try:
        rclpy.init(args=ros_args, signal_handler_options=SignalHandlerOptions.NO)
        executor = SingleThreadedExecutor()
        node = rclpy.create_node(NAME)
        if options.shards:
            from hair_tracking.ros.ghosts import shard_topic
            joined = ShardClouds(options.shards)
            for k in range(options.shards):
                node.create_subscription(
                    PointCloud2, shard_topic(k, 'points'),
                    lambda msg, k=k: latest.add_cloud(joined.add(k, msg)), qos)
        else:
            node.create_subscription(PointCloud2, options.points_topic, latest.add_cloud, qos)
        if options.head_topic:
            node.create_subscription(Marker, options.head_topic, latest.add_head, qos)
        if options.colliders_topic:
            node.create_subscription(MarkerArray, options.colliders_topic,
                                     latest.add_colliders, qos)
        executor.add_node(node)
        server = viser.ViserServer(host=options.host, port=options.port, label=NAME,
                                   verbose=False)
        server.gui.configure_theme(show_share_button=False)
        scene = HairScene(server, max_strands=options.max_strands,
                          line_width=options.line_width, follow=options.follow,
                          topics=(f'{options.shards} shards' if options.shards else
                                  node.resolve_topic_name(options.points_topic),
                                  options.head_topic and
                                  node.resolve_topic_name(options.head_topic)))
        print(f'{NAME}: serving http://{options.host}:{server.get_port()} '
              f'({scene.topics[0]}, {scene.topics[1] or "no head"}; Ctrl-C to stop)',
              flush=True)
        period = 1.0 / options.rate
        next_draw = time.monotonic()
        while not stop.requested:
            wait = min(period, next_draw - time.monotonic()) if latest else period
            shutdown.spin_until_stopped(executor, stop, timeout_sec=max(0.0, wait))
            if stop.requested or time.monotonic() < next_draw or not latest:
                continue
            head, points = latest.take()
            colliders = latest.take_colliders()
            try:
                if colliders is not None:
                    scene.show_colliders(colliders)
                scene.show(head, points)
                if points is not None and scene.clouds_drawn == 1:
                    print(f'{NAME}: drawing {points.height} strands x {points.width} points',
                          flush=True)
            except ValueError as e:
                node.get_logger().warn(f'message not drawn: {e}',
                                       throttle_duration_sec=5.0)
            next_draw = max(next_draw + period, time.monotonic())
    except ExternalShutdownException:
        pass
    finally:
        if server is not None:
            server.stop()
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


def main(args=None) -> int:
    """Console entry point ``hair_sim_view``: options before ``--ros-args`` are this
    executable's, the rest goes to rclpy."""
    argv = list(sys.argv if args is None else args)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    options = make_parser().parse_args(argv[1:split])
    problem = _check(options)
    if problem:
        print(f'{NAME}: {problem}', file=sys.stderr)
        return 2
    with executable.started() as stop:
        try:
            import viser  # noqa: F401  (optional: only this viewer needs it)
        except ImportError:
            print(f'{NAME} needs the viser package, which is not installed: pip install viser '
                  f'(make install does)', file=sys.stderr)
            return 1
        return serve(options, argv[:1] + argv[split:], stop)


if __name__ == '__main__':
    sys.exit(main())
