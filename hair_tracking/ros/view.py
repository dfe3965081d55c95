"""``hair_sim_view``: the live hair and the head in 3-D in a web browser, from the node's topics.

    hair_sim_view                         # then open http://127.0.0.1:8080
    hair_sim_view --follow --port 8090    # a walking head (hair_sim_bag play) stays in view

It subscribes to ``hair/points`` (or, with ``--shards N``, to the N ghost shards' clouds
``hair/shard_<k>/points``, joined: :class:`ShardClouds`) (the organized
sensor_msgs/PointCloud2 of :mod:`.node`: one
row per strand, ``x y z`` float32, packed ``rgb``) and ``hair/head`` (the collider as a
visualization_msgs/Marker SPHERE, ``scale`` = diameters) and draws each strand as line
segments between its consecutive points in the cloud's colours, and the head as an opaque
ellipsoid, both as given in the frame of the cloud (``--follow`` shifts the view so that the
head's centre stays at its origin).  It draws the body's colliders too, from ``hair/colliders``
(a visualization_msgs/MarkerArray of SPHEREs and CYLINDERs: the node's bust, each capsule a
cylinder and two spheres, :mod:`msg_adapters.capsule_markers`), as solids in the cloud's
frame.  It only subscribes (reliable, keep last, as the node
publishes): it changes nothing in the node.  Redraws are limited to ``--rate`` per second;
messages that come faster replace each other.

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
import collections
import math
import sys
import threading
import time
from typing import List, NamedTuple, Optional, Tuple

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.pointcloud import pointcloud2_to_strands

from hair_tracking import executable, shutdown

DEFAULT_PORT = 8080
#: The node's default ``marker_color`` as 8-bit RGB, for clouds without an ``rgb`` field.
HAIR_RGB = (115, 77, 38)
NAME = 'hair_sim_view'


# ==================================================================== messages -> geometry
def cloud_colors(msg: PointCloud2) -> Optional[np.ndarray]:
    """The packed ``rgb`` (or ``rgba``) field of a cloud -> ``(height, width, 3)`` uint8, or
    None when the cloud has no such field (float32 or uint32 holding 0x00RRGGBB)."""
    f = next((f for f in msg.fields if f.name in ('rgb', 'rgba')), None)
    if f is None or f.count != 1 or f.datatype not in (PointField.FLOAT32, PointField.UINT32):
        return None
    h, w, step = int(msg.height), int(msg.width), int(msg.point_step)
    raw = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if raw.size < h * msg.row_step or w * step > msg.row_step or f.offset + 4 > step:
        raise ValueError('PointCloud2 data is shorter than its height, width and steps say')
    rows = np.ascontiguousarray(raw[:h * msg.row_step].reshape(h, msg.row_step)[:, :w * step])
    dt = np.dtype({'names': ['c'], 'formats': [('>' if msg.is_bigendian else '<') + 'u4'],
                   'offsets': [f.offset], 'itemsize': step})
    c = rows.view(dt).reshape(h, w)['c']
    return np.stack([(c >> 16) & 255, (c >> 8) & 255, c & 255], axis=-1).astype(np.uint8)


def srgb_to_linear_u8(rgb: np.ndarray) -> np.ndarray:
    """8-bit sRGB (the display colours a cloud's ``rgb`` holds, as rviz shows them) -> 8-bit
    linear RGB.  viser hands per-vertex line colours to three.js as linear values, which the
    renderer encodes to sRGB for the screen, so this makes the strands show their own colours
    instead of paler ones."""
    return _SRGB_TO_LINEAR[rgb]


def _srgb_to_linear_table() -> np.ndarray:
    c = np.arange(256) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.rint(255.0 * lin).astype(np.uint8)


_SRGB_TO_LINEAR = _srgb_to_linear_table()


def strand_stride(n_strands: int, max_strands: int) -> int:
    """Every how many strands one is drawn, so that at most ``max_strands`` (0: all) are."""
    return max(1, -(-int(n_strands) // int(max_strands))) if max_strands > 0 else 1


def cloud_segments(msg: PointCloud2, max_strands: int = 0) -> Tuple[np.ndarray, np.ndarray]:
    """An organized cloud of strands -> line segments between each row's consecutive points:
    ``(points (M, 2, 3) float32, colors (M, 2, 3) uint8)``, colours as the cloud has them
    (sRGB).

    With ``max_strands`` > 0 every k-th strand is kept so that at most that many are drawn.
    Segments with a non-finite end are left out.  Colours from the cloud's ``rgb``, else
    :data:`HAIR_RGB`.
    """
    pts, _ = pointcloud2_to_strands(msg, dtype=np.float32)
    rgb = cloud_colors(msg)
    if rgb is None:
        rgb = np.broadcast_to(np.array(HAIR_RGB, dtype=np.uint8), pts.shape)
    k = strand_stride(pts.shape[0], max_strands)
    pts, rgb = pts[::k], rgb[::k]
    if pts.shape[1] < 2:
        return np.zeros((0, 2, 3), np.float32), np.zeros((0, 2, 3), np.uint8)
    seg = np.stack([pts[:, :-1], pts[:, 1:]], axis=2).reshape(-1, 2, 3)
    col = np.stack([rgb[:, :-1], rgb[:, 1:]], axis=2).reshape(-1, 2, 3)
    ok = np.isfinite(seg).all(axis=(1, 2))
    if not ok.all():
        seg, col = seg[ok], col[ok]
    return np.ascontiguousarray(seg), np.ascontiguousarray(col)


class HeadShape(NamedTuple):
    """An ellipsoid to draw: centre, orientation (w, x, y, z), semi-axes, RGB."""
    position: Tuple[float, float, float]
    wxyz: Tuple[float, float, float, float]
    semi_axes: Tuple[float, float, float]
    rgb: Tuple[int, int, int]


def head_shape(marker: Marker) -> Optional[HeadShape]:
    """A SPHERE marker (``scale`` = full axes along the pose's own axes) -> its ellipsoid;
    None for a DELETE / DELETEALL or a marker of another type (nothing to draw).  The alpha is
    not kept: the head is drawn opaque (a see-through head drawn after the strands would veil
    the hair in front of it too)."""
    if marker.action != Marker.ADD or marker.type != Marker.SPHERE:
        return None
    p, o, s, c = marker.pose.position, marker.pose.orientation, marker.scale, marker.color
    q = np.array([o.w, o.x, o.y, o.z], dtype=np.float64)
    n = float(np.linalg.norm(q))
    q = q / n if n > 0 and math.isfinite(n) else np.array([1.0, 0.0, 0.0, 0.0])
    axes = tuple(max(0.5 * float(v), 1e-6) for v in (s.x, s.y, s.z))
    rgb = tuple(int(round(min(max(float(v), 0.0), 1.0) * 255)) for v in (c.r, c.g, c.b))
    return HeadShape((float(p.x), float(p.y), float(p.z)), tuple(float(v) for v in q), axes,
                     rgb)


class Solid(NamedTuple):
    """A collider part to draw: ``kind`` ``'sphere'`` (``size`` its semi-axes) or
    ``'cylinder'`` (``size`` = radius, radius, height along its local z), centre, orientation
    (w, x, y, z), RGB."""
    kind: str
    position: Tuple[float, float, float]
    wxyz: Tuple[float, float, float, float]
    size: Tuple[float, float, float]
    rgb: Tuple[int, int, int]


def collider_solids(array: MarkerArray) -> List[Solid]:
    """The SPHERE and CYLINDER markers of a MarkerArray that add something, as solids (other
    types, DELETE and DELETEALL: nothing to draw)."""
    out = []
    for m in array.markers:
        if m.action != Marker.ADD or m.type not in (Marker.SPHERE, Marker.CYLINDER):
            continue
        if m.type == Marker.SPHERE:
            shape = head_shape(m)
            out.append(Solid('sphere', shape.position, shape.wxyz, shape.semi_axes, shape.rgb))
            continue
        p, o, sc, c = m.pose.position, m.pose.orientation, m.scale, m.color
        q = np.array([o.w, o.x, o.y, o.z], dtype=np.float64)
        n = float(np.linalg.norm(q))
        q = q / n if n > 0 and math.isfinite(n) else np.array([1.0, 0.0, 0.0, 0.0])
        size = tuple(max(0.5 * float(v), 1e-6) for v in (sc.x, sc.y)) + \
            (max(float(sc.z), 1e-6),)
        rgb = tuple(int(round(min(max(float(v), 0.0), 1.0) * 255)) for v in (c.r, c.g, c.b))
        out.append(Solid('cylinder', (float(p.x), float(p.y), float(p.z)),
                         tuple(float(v) for v in q), size, rgb))
    return out


def framing(segments: np.ndarray, head: Optional[HeadShape]):
    """``(look_at, camera position)`` that show ``segments`` and the head: a three-quarter view
    from +x, +y and above (the front left of a head that faces +x, z up, as in the node's
    head frame), at a distance of 0.8 times the diagonal of what is drawn."""
    pts = segments.reshape(-1, 3).astype(np.float64)
    if head is not None:
        c, r = np.array(head.position), max(head.semi_axes)
        pts = np.vstack([pts, c - r, c + r])
    if not len(pts):
        return None
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = 0.5 * (lo + hi)
    size = max(float(np.linalg.norm(hi - lo)), 0.05)
    direction = np.array([0.75, 0.55, 0.35])
    return centre, centre + 0.8 * size * direction / np.linalg.norm(direction)


# ==================================================================== what to draw next
class Latest:
    """The newest cloud and the head marker that goes with it: the one with the cloud's stamp
    among the last few heads (the node publishes both each tick, the head first), else the
    newest head not drawn yet, so a fast-moving head is not drawn a frame apart from its
    hair."""

    def __init__(self, keep: int = 8):
        self._heads = collections.deque(maxlen=keep)
        self._cloud = None
        self._drawn = None                  # the head last handed out
        self._colliders = None              # the newest collider array not drawn yet

    def add_cloud(self, msg: PointCloud2) -> None:
        self._cloud = msg

    def add_head(self, msg: Marker) -> None:
        self._heads.append(msg)

    def add_colliders(self, msg: MarkerArray) -> None:
        self._colliders = msg

    def take_colliders(self) -> Optional[MarkerArray]:
        """The newest collider array not drawn yet, or None."""
        msg, self._colliders = self._colliders, None
        return msg

    def __bool__(self) -> bool:
        """Whether something is new."""
        return self._cloud is not None or self._colliders is not None or \
            bool(self._heads) and self._heads[-1] is not self._drawn

    def take(self) -> Tuple[Optional[Marker], Optional[PointCloud2]]:
        """-> (head or None, cloud or None) to draw now; None for what is not new."""
        cloud, self._cloud = self._cloud, None
        head = None
        if cloud is not None:
            head = next((h for h in reversed(self._heads)
                         if h.header.stamp == cloud.header.stamp), None)
        if head is None and self._heads and self._heads[-1] is not self._drawn:
            head = self._heads[-1]
        if head is not None:
            self._drawn = head
        return head, cloud


class ShardClouds:
    """The ghost shards' clouds (``hair_sim_ghosts``, ``--shards``) joined into one: the newest
    cloud of each shard, in shard order, leaving out those more than ``max_age_ns`` older than
    the newest (a shard that stopped); the rows of all shards are the rows of the node's
    cloud of all strands."""

    def __init__(self, shards: int, max_age_ns: int = 1_000_000_000):
        self._clouds: List[Optional[PointCloud2]] = [None] * int(shards)
        self.max_age_ns = int(max_age_ns)

    def add(self, shard: int, msg: PointCloud2) -> PointCloud2:
        """Keep ``msg`` as shard ``shard``'s newest; the joined cloud now."""
        self._clouds[shard] = msg

        def stamp(m):
            return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
        newest = max(stamp(m) for m in self._clouds if m is not None)
        parts = [m for m in self._clouds if m is not None and
                 newest - stamp(m) <= self.max_age_ns and m.width == msg.width and
                 m.point_step == msg.point_step]
        out = PointCloud2(header=msg.header, height=sum(m.height for m in parts),
                          width=msg.width, fields=msg.fields, is_bigendian=msg.is_bigendian,
                          point_step=msg.point_step, row_step=msg.row_step,
                          is_dense=all(m.is_dense for m in parts))
        out.data = b''.join(bytes(m.data) for m in parts)
        return out


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
