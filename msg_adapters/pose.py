"""Pose messages <-> numpy: ``(t_ns, position (3,), quaternion (4,) x, y, z, w)``.

Reading accepts, by duck typing (so rclpy messages and rosbags-deserialized ones both work):
``geometry_msgs/PoseStamped``, ``TransformStamped``, ``PoseWithCovarianceStamped``,
``nav_msgs/Odometry`` (``header`` + ``pose.pose`` + ``child_frame_id``), and bare ``Pose`` /
``Transform`` (no stamp: ``t_ns`` 0, frames ''). Units: metres; the pose maps points of
``child_frame_id`` (the head) into ``frame_id``: ``p_parent = position + R(q) @ p_child``.

The quaternion is returned as received (not normalised; the caller's pose hygiene does that),
but a non-finite component or a (near-)zero norm raises :class:`PoseError` naming the field.
A stamp of 0 is returned as 0: the caller decides whether that means 'now'.
"""
from dataclasses import dataclass
import math

from geometry_msgs.msg import Pose, PoseStamped, TransformStamped
import numpy as np
from std_msgs.msg import Header

from msg_adapters.stamps import time_msg, time_to_ns

# A quaternion whose norm is below this is treated as zero (it carries no rotation).
QUAT_MIN_NORM = 1e-9


class PoseError(ValueError):
    """A pose message that cannot be used: NaN/Inf value, zero quaternion, bad stamp."""


@dataclass(frozen=True, eq=False)
class PoseSample:
    """One pose read from a message.

    t_ns: header stamp [ns] (0 when the stamp is 0 or the message has no header).
    position: (3,) float64 [m], in ``frame_id``.
    quaternion: (4,) float64 (x, y, z, w), as received (finite, norm >= QUAT_MIN_NORM).
    frame_id: parent frame ('' if none); child_frame_id: child frame ('' if the type has none).
    The arrays are read-only; compare samples field by field (no ``==``).
    """

    t_ns: int
    position: np.ndarray
    quaternion: np.ndarray
    frame_id: str
    child_frame_id: str


def _vec(obj, names, prefix):
    out = np.empty(len(names))
    for i, n in enumerate(names):
        v = float(getattr(obj, n))
        if not math.isfinite(v):
            raise PoseError(f'{prefix}.{n} is {v}: pose values must be finite')
        out[i] = v
    out.flags.writeable = False
    return out


def _parts(msg):
    """(stamp or None, frame_id, child, position obj, orientation obj, field prefixes)."""
    header = getattr(msg, 'header', None)
    child = str(getattr(msg, 'child_frame_id', ''))
    if hasattr(msg, 'transform'):
        tf = msg.transform
        return header, child, tf.translation, tf.rotation, 'transform.translation', \
            'transform.rotation'
    if hasattr(msg, 'pose'):
        pose, prefix = msg.pose, 'pose'
        if hasattr(pose, 'pose'):               # PoseWithCovariance(Stamped), Odometry
            pose, prefix = pose.pose, 'pose.pose'
        return header, child, pose.position, pose.orientation, prefix + '.position', \
            prefix + '.orientation'
    if hasattr(msg, 'translation') and hasattr(msg, 'rotation'):
        return None, '', msg.translation, msg.rotation, 'translation', 'rotation'
    if hasattr(msg, 'position') and hasattr(msg, 'orientation'):
        return None, '', msg.position, msg.orientation, 'position', 'orientation'
    raise TypeError(f'cannot read a pose from a {type(msg).__name__}: expected PoseStamped, '
                    'TransformStamped, PoseWithCovarianceStamped, Odometry, Pose or Transform')


def pose_from_msg(msg):
    """Read a pose message into a :class:`PoseSample`; PoseError (a ValueError) if unusable."""
    header, child, pos, rot, pos_name, rot_name = _parts(msg)
    t_ns, frame_id = 0, ''
    if header is not None:
        try:
            t_ns = time_to_ns(header.stamp)
        except (TypeError, ValueError) as exc:
            raise PoseError(str(exc)) from None
        frame_id = str(header.frame_id)
    position = _vec(pos, 'xyz', pos_name)
    quaternion = _vec(rot, 'xyzw', rot_name)
    norm = math.sqrt(float(np.dot(quaternion, quaternion)))
    if not norm >= QUAT_MIN_NORM:
        raise PoseError(f'{rot_name} has norm {norm:.3g}: a zero quaternion is no rotation')
    return PoseSample(t_ns, position, quaternion, frame_id, child)


def _check_arrays(position, quaternion, check):
    p = np.asarray(position, dtype=np.float64)
    q = np.asarray(quaternion, dtype=np.float64)
    if p.shape != (3,):
        raise ValueError(f'position must have shape (3,), got {p.shape}')
    if q.shape != (4,):
        raise ValueError(f'quaternion must have shape (4,) (x, y, z, w), got {q.shape}')
    if check:
        if not np.isfinite(p).all():
            raise PoseError(f'position {p.tolist()} is not finite')
        if not (np.isfinite(q).all() and np.linalg.norm(q) >= QUAT_MIN_NORM):
            raise PoseError(f'quaternion {q.tolist()} is not finite or has zero norm')
    return [float(v) for v in p], [float(v) for v in q]


def pose_msg(position, quaternion, *, check=True):
    """geometry_msgs/Pose from numpy; ``check=False`` lets tests build invalid poses."""
    p, q = _check_arrays(position, quaternion, check)
    msg = Pose()
    msg.position.x, msg.position.y, msg.position.z = p
    msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = q
    return msg


def pose_stamped_msg(t_ns, position, quaternion, frame_id, *, check=True):
    """geometry_msgs/PoseStamped at ``t_ns`` [ns] in ``frame_id``."""
    return PoseStamped(header=Header(stamp=time_msg(t_ns, 't_ns'), frame_id=str(frame_id)),
                       pose=pose_msg(position, quaternion, check=check))


def transform_stamped_msg(t_ns, position, quaternion, frame_id, child_frame_id, *,
                          check=True):
    """geometry_msgs/TransformStamped: ``child_frame_id`` expressed in ``frame_id``."""
    p, q = _check_arrays(position, quaternion, check)
    msg = TransformStamped(header=Header(stamp=time_msg(t_ns, 't_ns'), frame_id=str(frame_id)),
                           child_frame_id=str(child_frame_id))
    tr = msg.transform
    tr.translation.x, tr.translation.y, tr.translation.z = p
    tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w = q
    return msg
