"""hair_tracking_msgs/GuideState <-> numpy: the guide strands of one frame, as CDR bytes or as
the rclpy message.

``hair_tracking_msgs`` comes from a colcon workspace, or in the pip-only venv from
``interfaces/build_interfaces.sh`` (``make install``); the CDR functions work without it,
:data:`GuideState` is None then.

The message (``interfaces/hair_tracking_msgs/msg/GuideState.msg``): ``header`` (the head pose's
stamp, the frame of the pose and the positions), ``head`` (geometry_msgs/Pose), ``person_id``,
``scene_fingerprint`` (uint64), ``sequence`` (uint32), ``guides``, ``nodes`` (uint32) and
``positions``, float32 x y z of ``guides * nodes`` points, guide-major: the C order of a
``(guides, nodes, 3)`` array.  12 bytes a guide node, plus a fixed part (116 bytes with the
frame ``world`` and no person id).

:func:`guide_state_cdr` writes the serialized message straight from the arrays (layout and
padding as :mod:`msg_adapters.cdr` describes, the positions one numpy copy);
:func:`guide_state_from_cdr` reads one back without building a message object, the positions a
view of the bytes or a copy.  :func:`guide_state_msg` and :func:`guide_state_from_msg` do the same
with the rclpy message (and any object with its fields, e.g. one rosbags deserialized).  Both
builders validate alike and make the same message: ``serialize_message`` of the one is the
bytes of the other, padding aside.
"""
import array
from dataclasses import dataclass
from types import SimpleNamespace

from builtin_interfaces.msg import Time
import numpy as np

from msg_adapters.arrays import as_strands
from msg_adapters.cdr import CdrReader, CdrWriter, MessageBuffer, put_pieces
from msg_adapters.marker_spec import _text, check_frame_id
from msg_adapters.pose import _check_arrays, pose_msg
from msg_adapters.stamps import as_int, split_ns, time_to_ns

try:
    from hair_tracking_msgs.msg import GuideState
except ImportError:                     # pragma: no cover - depends on the installation
    GuideState = None

#: GuideState's fields in the order :func:`guide_state_cdr` writes them (the tests compare this
#: with the generated message's).
GUIDE_STATE_FIELDS = ('header', 'head', 'person_id', 'scene_fingerprint', 'sequence', 'guides',
                      'nodes', 'positions')
TYPE_NAME = 'hair_tracking_msgs/msg/GuideState'


@dataclass(frozen=True, eq=False)
class GuideStateSample:
    """One GuideState read back.

    t_ns: header stamp [ns]; frame_id: the frame of the head pose and the positions.
    head_position (3,), head_quaternion (4,) x y z w: float64, the head pose as sent.
    positions: (guides, nodes, 3) float32 [m], read-only.
    """

    t_ns: int
    frame_id: str
    head_position: np.ndarray
    head_quaternion: np.ndarray
    person_id: str
    scene_fingerprint: int
    sequence: int
    positions: np.ndarray


def _unsigned(value, bits, what):
    v = as_int(value, what)
    if not 0 <= v < 1 << bits:
        raise ValueError(f'{what} is {v}: it must fit uint{bits} (0 .. 2**{bits} - 1)')
    return v


def _check(positions, stamp_ns, frame_id, head_position, head_quaternion, person_id,
           scene_fingerprint, sequence):
    """The builders' inputs checked -> (positions (G, N, 3) float64, scalars...)."""
    x = as_strands(positions, name='positions')
    for name, n in zip(('guides', 'nodes'), x.shape[:2]):
        _unsigned(n, 32, name)
    try:
        p, q = _check_arrays(head_position, head_quaternion, True)
    except ValueError as exc:
        raise type(exc)(f'head pose: {exc}') from None
    return (x, split_ns(stamp_ns, 'stamp_ns'), check_frame_id(frame_id), p, q,
            _text(person_id, 'person_id', allow_empty=True),
            _unsigned(scene_fingerprint, 64, 'scene_fingerprint'),
            _unsigned(sequence, 32, 'sequence'))


def guide_state_cdr(positions, *, frame_id, head_position, head_quaternion, scene_fingerprint,
                    sequence, stamp_ns=0, person_id=''):
    """The serialized GuideState (``bytes``, CDR little-endian) of ``positions``.

    ``positions`` (G, N, 3) [m] in ``frame_id``, finite (a NaN guide is a caller bug; sent as
    float32); ``head_position`` (3,) and ``head_quaternion`` (4,) x y z w the head pose in
    ``frame_id`` (finite, non-zero quaternion); ``scene_fingerprint`` fits uint64, ``sequence``
    uint32; ``stamp_ns`` [ns]; ``person_id`` '' for one person.  ValueError (TypeError for a
    non-integer count) names the argument.
    """
    x, stamp, frame_id, p, q, person, fingerprint, seq = _check(
        positions, stamp_ns, frame_id, head_position, head_quaternion, person_id,
        scene_fingerprint, sequence)
    n_guides, n_nodes = x.shape[:2]
    w = CdrWriter()
    w.time(*stamp)
    w.string(frame_id)
    for v in p + q:
        w.float64(v)
    w.string(person)
    w.uint64(fingerprint)
    w.uint32(seq)
    w.uint32(n_guides)
    w.uint32(n_nodes)
    w.uint32(x.size)
    at = w.hole(4 * x.size, 4)
    buf = MessageBuffer(w.offset)
    put_pieces(buf.body, w.pieces())
    buf.body[at:at + 4 * x.size].view('<f4')[:] = x.reshape(-1)
    return buf.finish()


def guide_state_msg(positions, *, frame_id, head_position, head_quaternion, scene_fingerprint,
                    sequence, stamp_ns=0, person_id=''):
    """hair_tracking_msgs/GuideState of the same arguments as :func:`guide_state_cdr`."""
    if GuideState is None:
        raise RuntimeError('hair_tracking_msgs is not installed (make install generates it)')
    x, stamp, frame_id, p, q, person, fingerprint, seq = _check(
        positions, stamp_ns, frame_id, head_position, head_quaternion, person_id,
        scene_fingerprint, sequence)
    msg = GuideState(person_id=person, scene_fingerprint=fingerprint, sequence=seq,
                     guides=x.shape[0], nodes=x.shape[1],
                     positions=array.array('f', x.astype('<f4').tobytes()))
    msg.header.stamp = Time(sec=stamp[0], nanosec=stamp[1])
    msg.header.frame_id = frame_id
    msg.head = pose_msg(p, q)
    return msg


def _sample(t_ns, frame_id, p, q, person, fingerprint, seq, n_guides, n_nodes, flat, copy):
    if flat.size != 3 * n_guides * n_nodes:
        raise ValueError(f'GuideState has {flat.size} position values for guides={n_guides} x '
                         f'nodes={n_nodes}, which need {3 * n_guides * n_nodes}')
    pos = flat.reshape(n_guides, n_nodes, 3)
    if copy:
        pos = pos.copy()
        pos.flags.writeable = False
    hp, hq = np.array(p, dtype=np.float64), np.array(q, dtype=np.float64)
    hp.flags.writeable = hq.flags.writeable = False
    return GuideStateSample(t_ns, frame_id, hp, hq, person, fingerprint, seq, pos)


def guide_state_from_cdr(data, *, copy=True):
    """Read the CDR bytes of a GuideState (``bytes``, ``memoryview``, uint8 array) into a
    :class:`GuideStateSample`.

    ``copy=False`` leaves ``positions`` a read-only view of ``data``, valid while ``data`` is
    (not across :class:`~msg_adapters.rcl_serialized.SerializedTaker` takes).  ValueError when
    the bytes are not a whole GuideState or its counts disagree.
    """
    r = CdrReader(data, 'GuideState')
    sec, nanosec = r.time('header.stamp')
    t_ns = time_to_ns(SimpleNamespace(sec=sec, nanosec=nanosec))
    frame_id = r.string('header.frame_id')
    pose = [r.float64('head') for _ in range(7)]
    person = r.string('person_id')
    fingerprint = r.uint64('scene_fingerprint')
    seq = r.uint32('sequence')
    n_guides, n_nodes = r.uint32('guides'), r.uint32('nodes')
    count = r.uint32('positions')
    flat = r.array('<f4', count, 'positions')
    if r.remaining:
        raise ValueError(f'GuideState: {r.remaining} bytes after the positions')
    return _sample(t_ns, frame_id, pose[:3], pose[3:], person, fingerprint, seq, n_guides,
                   n_nodes, flat, copy)


def guide_state_from_msg(msg, *, copy=True):
    """Read a GuideState message (rclpy's, or any object with its fields) into a
    :class:`GuideStateSample`; ``copy=False`` lets ``positions`` share the message's array
    where it can.  ValueError as :func:`guide_state_from_cdr`."""
    t_ns = time_to_ns(msg.header.stamp)
    pos, rot = msg.head.position, msg.head.orientation
    flat = np.asarray(msg.positions, dtype=np.float32)
    if flat.ndim != 1:
        raise ValueError(f'GuideState positions must be flat, got shape {flat.shape}')
    if not copy:
        flat = flat.view()
        flat.flags.writeable = False
    return _sample(t_ns, str(msg.header.frame_id), (pos.x, pos.y, pos.z),
                   (rot.x, rot.y, rot.z, rot.w), str(msg.person_id),
                   int(msg.scene_fingerprint), int(msg.sequence), int(msg.guides),
                   int(msg.nodes), flat, copy)
