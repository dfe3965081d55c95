"""tf2_msgs/TFMessage helpers: one head transform out, every transform's numbers in.

``tf2_msgs`` comes from a ROS installation, or in the pip-only venv from
``interfaces/build_interfaces.sh`` (``make install``); :data:`TFMessage` is None without it.
"""
from typing import Iterator, Tuple

from geometry_msgs.msg import TransformStamped

from msg_adapters.stamps import time_msg, time_to_ns

try:
    from tf2_msgs.msg import TFMessage
except ImportError:                     # pragma: no cover - depends on the installation
    TFMessage = None


def transform_message(t_ns: int, parent: str, child: str, position, quaternion):
    """A TFMessage holding the one transform ``parent -> child``."""
    if TFMessage is None:
        raise RuntimeError('tf2_msgs is not installed (make install generates it)')
    tr = TransformStamped()
    tr.header.stamp = time_msg(int(t_ns), 't_ns')
    tr.header.frame_id = str(parent)
    tr.child_frame_id = str(child)
    t, r = tr.transform.translation, tr.transform.rotation
    t.x, t.y, t.z = (float(v) for v in position)
    r.x, r.y, r.z, r.w = (float(v) for v in quaternion)
    return TFMessage(transforms=[tr])


def transforms(msg) -> Iterator[Tuple[str, str, Tuple[float, float, float],
                                      Tuple[float, float, float, float], int]]:
    """``(parent, child, translation, rotation, stamp_ns)`` of every transform in ``msg``."""
    for tr in msg.transforms:
        t, r = tr.transform.translation, tr.transform.rotation
        try:
            stamp = time_to_ns(tr.header.stamp)
        except ValueError:
            stamp = 0
        yield (str(tr.header.frame_id), str(tr.child_frame_id), (t.x, t.y, t.z),
               (r.x, r.y, r.z, r.w), stamp)
