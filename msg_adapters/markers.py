"""Strands ``(S, N, 3)`` -> visualization_msgs/MarkerArray as message objects.

This is the readable reference path (about 4 µs per point in rclpy); publishers that care about
speed send the byte-identical CDR from :mod:`msg_adapters.marker_cdr` instead. Parameters and
rviz semantics: :mod:`msg_adapters.marker_spec`. Every scalar is set as an exact Python
``float``/``int`` (with ``ROS_PYTHON_CHECK_FIELDS`` off, rclpy would silently corrupt numpy
scalars).
"""
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, Vector3
import numpy as np
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

from msg_adapters.marker_spec import ADD, check_frame_id, check_ns, DELETEALL, \
    prepare_markers
from msg_adapters.stamps import time_msg


def _segments(x):
    """(S, N, 3) -> (S, N - 1, 2, 3): the point pairs of a LINE_LIST."""
    seg = np.empty((x.shape[0], x.shape[1] - 1, 2) + x.shape[2:], dtype=x.dtype)
    seg[:, :, 0] = x[:, :-1]
    seg[:, :, 1] = x[:, 1:]
    return seg


def _points(xyz):
    return [Point(x=a, y=b, z=c) for a, b, c in xyz.reshape(-1, 3).tolist()]


def _colors(rgba):
    return [ColorRGBA(r=r, g=g, b=b, a=a)
            for r, g, b, a in rgba.reshape(-1, 4).astype(np.float64).tolist()]


def _marker(spec, mid, mtype, action):
    m = Marker(header=Header(stamp=Time(sec=spec.stamp[0], nanosec=spec.stamp[1]),
                             frame_id=spec.frame_id),
               ns=spec.ns, id=mid, type=mtype, action=action)
    m.pose.orientation.w = 1.0
    m.scale = Vector3(x=spec.width, y=0.0, z=0.0)
    r, g, b, a = spec.color
    m.color = ColorRGBA(r=r, g=g, b=b, a=a)
    m.lifetime = Duration(sec=spec.lifetime[0], nanosec=spec.lifetime[1])
    return m


def delete_all_marker(frame_id, stamp_ns=0, ns=''):
    """A DELETEALL marker: rviz2 clears the markers of namespace ``ns`` (all namespaces when
    ``ns`` is ''); it needs a valid ``frame_id``.

    As bytes: ``strands_to_marker_array_cdr(np.empty((0, 2, 3)), style='line_strips',
    delete_all_first=True, ...)`` is a MarkerArray holding just this marker.
    """
    return Marker(header=Header(stamp=time_msg(stamp_ns), frame_id=check_frame_id(frame_id)),
                  ns=check_ns(ns), id=0, action=DELETEALL)


def strands_to_marker_array(strands, *, frame_id, stamp_ns=0, ns='strands', style='line_list',
                            width=0.001, color=(1.0, 1.0, 1.0, 1.0), colors=None,
                            lifetime_ns=0, first_id=0, delete_all_first=False):
    """MarkerArray of ``strands`` (S, N >= 2, 3) [m] in ``frame_id`` at ``stamp_ns`` [ns].

    style 'line_list': one LINE_LIST marker (id ``first_id``) of all segments; 'line_strips':
    one LINE_STRIP per strand (ids ``first_id + s``). ``color`` RGBA is the marker colour,
    ``colors`` optional per-strand ``(S, 3|4)`` or per-point ``(S, N, 3|4)`` colours in [0, 1]
    (expanded to one per point). ``width`` [m] -> scale.x; ``lifetime_ns`` 0 = forever;
    ``delete_all_first`` puts a DELETEALL marker (same ns) first. ValueError on bad input
    (wrong shape, NaN/Inf points, N < 2, colours out of range, empty frame_id).
    """
    spec, x, cols = prepare_markers(
        strands, frame_id=frame_id, stamp_ns=stamp_ns, ns=ns, style=style, width=width,
        color=color, colors=colors, lifetime_ns=lifetime_ns, first_id=first_id,
        delete_all_first=delete_all_first)
    n_strands, n_points = x.shape[:2]
    if cols is not None:
        cols = np.broadcast_to(cols, (n_strands, n_points, 4))
    markers = []
    if spec.delete_all_first:
        markers.append(delete_all_marker(spec.frame_id, stamp_ns, spec.ns))
    if spec.style == 'line_list':
        m = _marker(spec, spec.first_id, spec.marker_type(), ADD)
        m.points = _points(_segments(x))
        if cols is not None:
            m.colors = _colors(_segments(cols))
        markers.append(m)
    else:
        for s in range(n_strands):
            m = _marker(spec, spec.first_id + s, spec.marker_type(), ADD)
            m.points = _points(x[s])
            if cols is not None:
                m.colors = _colors(cols[s])
            markers.append(m)
    return MarkerArray(markers=markers)
