"""What ``hair_sim_view`` draws, from the node's messages (no viser here): the strands of an
organized PointCloud2 as line segments in its colours (:func:`cloud_segments`), the head
collider's Marker as an ellipsoid (:func:`head_shape`), the body's MarkerArray as solids
(:func:`collider_solids`), the view that frames them (:func:`framing`), the newest message of
each topic (:class:`Latest`) and the ghost shards' clouds joined into one (:class:`ShardClouds`).
"""
import collections
import math
from typing import List, NamedTuple, Optional, Tuple

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.pointcloud import pointcloud2_to_strands

#: The node's default ``marker_color`` as 8-bit RGB, for clouds without an ``rgb`` field.
HAIR_RGB = (115, 77, 38)


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
