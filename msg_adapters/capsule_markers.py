"""Capsules as visualization_msgs/Marker: rviz has no capsule marker, so each is a CYLINDER
(its full axes ``scale`` = 2 r, 2 r, 2 h along the marker's x, y, z) and a SPHERE at each end
of its core segment.  Every scalar is set as a Python ``float`` (see :mod:`msg_adapters.markers`).
"""
from typing import List, Sequence

import numpy as np
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from msg_adapters.stamps import time_msg

NAMESPACE = 'colliders'


def capsule_markers(centers, quaternions, radii, half_lengths, *, frame_id: str, stamp_ns: int,
                    color: Sequence[float], ns: str = NAMESPACE) -> List[Marker]:
    """Three markers a capsule (ids ``3 k``, ``3 k + 1``, ``3 k + 2``): capsule ``k`` centred at
    ``centers[k]`` (3,), its core segment along the local z of ``quaternions[k]`` (x, y, z, w)
    from ``-half_lengths[k]`` to ``+half_lengths[k]``, radius ``radii[k]``, in ``frame_id``."""
    centers = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    quats = np.asarray(quaternions, dtype=np.float64).reshape(-1, 4)
    radii = np.asarray(radii, dtype=np.float64).reshape(-1)
    halves = np.asarray(half_lengths, dtype=np.float64).reshape(-1)
    if not (len(centers) == len(quats) == len(radii) == len(halves)):
        raise ValueError(f'capsules: {len(centers)} centres, {len(quats)} rotations, '
                         f'{len(radii)} radii and {len(halves)} half lengths must be as many')
    header = Header(stamp=time_msg(int(stamp_ns)), frame_id=str(frame_id))
    rgba = ColorRGBA(**dict(zip('rgba', (float(v) for v in color))))
    out = []
    for k, (c, q, r, h) in enumerate(zip(centers, quats, radii, halves)):
        q = q / np.linalg.norm(q)
        x, y, z, w = q
        axis = np.array([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])
        parts = ((Marker.CYLINDER, c, (2 * r, 2 * r, 2 * h)),
                 (Marker.SPHERE, c - h * axis, (2 * r,) * 3),
                 (Marker.SPHERE, c + h * axis, (2 * r,) * 3))
        for i, (kind, at, scale) in enumerate(parts):
            m = Marker(header=header, ns=ns, id=3 * k + i, type=kind, action=Marker.ADD)
            m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in at)
            o = m.pose.orientation
            o.x, o.y, o.z, o.w = (float(v) for v in q)
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
            m.color = rgba
            out.append(m)
    return out
