"""The head collider as a visualization_msgs/Marker (a SPHERE marker, scaled to an ellipsoid).

rviz draws a SPHERE marker as an ellipsoid whose full axes are ``scale`` along the marker's own
x, y, z (the marker pose's orientation), so an axis-aligned ellipsoid of semi-axes ``radii``
centred at ``center`` in the head frame is the marker with ``scale = 2 * radii`` posed at
``center`` in the head frame, or at ``head * center`` with the head's orientation in a fixed
frame.  Every scalar is set as a Python ``float`` (see :mod:`msg_adapters.markers`).
"""
from typing import Optional, Sequence

import numpy as np
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from msg_adapters.stamps import time_msg

NAMESPACE = 'head'
SHAPES = ('none', 'sphere', 'ellipsoid')


def collider_marker(shape: str, center: Sequence[float], radius: float,
                    radii: Sequence[float], *, frame_id: str, stamp_ns: int,
                    color: Sequence[float], head_position: Optional[Sequence[float]] = None,
                    head_quaternion: Optional[Sequence[float]] = None) -> Marker:
    """The collider of ``shape`` ('sphere', 'ellipsoid'; 'none' gives a DELETE of the marker).

    Without ``head_position``/``head_quaternion`` the marker is in the head frame; with them,
    in the fixed frame of that head pose (``p_fixed = position + R(q) @ p_head``).
    """
    if shape not in SHAPES:
        raise ValueError(f'collider shape must be one of {", ".join(SHAPES)}, got {shape!r}')
    m = Marker(header=Header(stamp=time_msg(int(stamp_ns)), frame_id=str(frame_id)),
               ns=NAMESPACE, id=0)
    if shape == 'none':
        m.action = Marker.DELETE
        return m
    m.type, m.action = Marker.SPHERE, Marker.ADD
    c = np.asarray(center, dtype=np.float64).reshape(3)
    axes = 2.0 * (np.full(3, float(radius)) if shape == 'sphere'
                  else np.asarray(radii, dtype=np.float64).reshape(3))
    q = np.array([0.0, 0.0, 0.0, 1.0])
    if head_position is not None:
        q = np.asarray(head_quaternion, dtype=np.float64).reshape(4)
        q = q / np.linalg.norm(q)
        x, y, z, w = q
        rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        c = np.asarray(head_position, dtype=np.float64).reshape(3) + rot @ c
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in c)
    o = m.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in axes)
    r, g, b, a = (float(v) for v in color)
    m.color = ColorRGBA(r=r, g=g, b=b, a=a)
    m.frame_locked = head_position is None     # follows the head frame as TF moves it
    return m
