"""Bags without a ROS installation: open, inspect, read head poses, write safely (rosbags).

Everything here goes through the pure-Python ``rosbags`` library (0.11), so it works where
``ros2 bag`` / ``rosbag2_py`` do not exist, and the files it writes are ordinary rosbag2 bags
(format version 9, Jazzy) that ``ros2 bag info/play`` reads.

Inputs accepted by :func:`open_bag`
  * a rosbag2 directory (``metadata.yaml`` + storage files, MCAP or sqlite3),
  * a single rosbag2 storage file: ``*.mcap`` or ``*.db3`` (as ``ros2 bag`` accepts too),
  * a ROS 1 bag ``*.bag`` (through ``rosbags.highlevel.AnyReader``).
  The kind is recognised from the file's magic bytes, not only its name.

Outputs (:class:`BagWriter`)
  * a path ending in ``.mcap`` / ``.db3`` is written as one storage file,
  * any other path becomes a rosbag2 directory (``--storage`` picks MCAP or sqlite3).
  The bag is written under a hidden temporary name in the same folder and renamed into place
  only when complete: an interrupted or failed run leaves nothing at the output path.

Head poses (:func:`read_head_poses`) come from ``geometry_msgs/PoseStamped``,
``TransformStamped``, ``PoseWithCovarianceStamped``, ``nav_msgs/Odometry`` or
``tf2_msgs/TFMessage`` (the transforms whose ``child_frame_id`` is the head frame, composed with
static transforms up to a chosen fixed frame), read by the same :mod:`msg_adapters.pose` the node
uses.  Units SI; a pose maps head-frame points into its parent frame,
``p_parent = position + R(q) @ p_head``.

MCAP files a recorder left cut short (no summary, no closing magic) are read to their last
whole message: :func:`open_bag` reads a closed copy of their whole records
(:mod:`hair_tracking.bags.mcap_salvage`, made once per file and process, in a temporary folder
removed at exit) and says on stderr how much it recovered; :func:`copy_bag` writes such a bag
(or any other) as a clean one (``hair_sim_bag recover``).

Every failure a user can cause raises :class:`BagError` with a message that names the path and
the reason, and an exit code (``EXIT_*``) for the command line.
"""
import atexit
from contextlib import contextmanager
from dataclasses import dataclass, field
import os
from pathlib import Path
import shutil
import struct
import sys
import tempfile
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from hair_tracking.resources import data_path

# ---------------------------------------------------------------- exit codes
EXIT_OK = 0
EXIT_FAILURE = 1        # the run itself failed (e.g. the hair went non-finite)
EXIT_USAGE = 2          # bad command line (argparse's own code)
EXIT_INPUT = 3          # input missing, not a bag, corrupt or unreadable
EXIT_CONTENT = 4        # the bag lacks what was asked for: no head-pose topic, unknown frame
EXIT_OUTPUT = 5         # output path exists or cannot be written

POSE_MSGTYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/TransformStamped',
                 'geometry_msgs/msg/PoseWithCovarianceStamped', 'nav_msgs/msg/Odometry')
TF_MSGTYPES = ('tf2_msgs/msg/TFMessage', 'tf/msg/tfMessage')
STORAGES = ('mcap', 'sqlite3')
STORAGE_SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3'}
_SUFFIX_STORAGE = {'.mcap': 'mcap', '.db3': 'sqlite3'}

_MAGIC = {b'\x89MCAP0\r\n': 'mcap', b'SQLite format 3\x00': 'sqlite3', b'#ROSBAG V2.0\n': 'ros1'}
_KIND_SUFFIX = {'mcap': '.mcap', 'sqlite3': '.db3', 'ros1': '.bag'}
_KIND_NAME = {'mcap': 'MCAP', 'sqlite3': 'sqlite3', 'ros1': 'ROS 1'}

BUNDLED_BAG = data_path('walk_head_pose.mcap')


class BagError(Exception):
    """A bag problem the user can fix; ``code`` is the command line's exit code."""

    def __init__(self, message: str, code: int = EXIT_INPUT):
        super().__init__(message)
        self.code = code


_TYPESTORE = None


#: Message types of the interface packages this project builds (``interfaces/``), which the
#: rosbags Jazzy typestore lacks: registered from their definitions where these are found.
OWN_MESSAGE_TYPES = (('hair_tracking_msgs', 'GuideState'), ('hri_msgs', 'IdsList'))


def typestore():
    """The ROS 2 Jazzy typestore of rosbags with :data:`OWN_MESSAGE_TYPES` (built once)."""
    global _TYPESTORE
    if _TYPESTORE is None:
        from rosbags.typesys import get_types_from_msg, get_typestore, Stores
        from hair_tracking.resources import message_definition
        store = get_typestore(Stores.ROS2_JAZZY)
        for package, name in OWN_MESSAGE_TYPES:
            msgtype = f'{package}/msg/{name}'
            text = message_definition(package, name)
            if msgtype not in store.types and text is not None:
                store.register(get_types_from_msg(text, msgtype))
        _TYPESTORE = store
    return _TYPESTORE


def bundled_bag() -> str:
    """Path of the sample head-pose bag shipped with the package (CMU 131_01 walk)."""
    if not os.path.isfile(BUNDLED_BAG):
        raise BagError(f'the bundled sample bag is missing: {BUNDLED_BAG}', EXIT_INPUT)
    return BUNDLED_BAG


# ================================================================ opening
def _sniff(path: Path) -> Optional[str]:
    try:
        with open(path, 'rb') as fh:
            head = fh.read(16)
    except OSError as exc:
        raise BagError(f'{path}: cannot read: {exc.strerror or exc}', EXIT_INPUT) from None
    for magic, kind in _MAGIC.items():
        if head.startswith(magic):
            return kind
    return None


def looks_like_bag(path) -> bool:
    """Whether ``path`` is meant as a bag: a folder, a storage file's name (``.mcap``, ``.db3``,
    ``.bag``) or a bag's first bytes (it need not be a readable one)."""
    p = Path(path)
    if p.is_dir() or p.suffix.lower() in _SUFFIX_STORAGE or p.suffix.lower() == '.bag':
        return True
    try:
        return p.is_file() and _sniff(p) is not None
    except BagError:
        return False


#: messages scanned to list the frames of a TF topic when choosing the head frame
_SCAN_LIMIT = 5000

_NOT_A_BAG = ('expected a rosbag2 directory (with metadata.yaml), an MCAP (.mcap) or sqlite3 '
              '(.db3) rosbag2 file, or a ROS 1 .bag file')


def bag_kind(path) -> Tuple[str, Path]:
    """``(kind, storage path)`` of a bag: kind is 'dir', 'mcap', 'sqlite3' or 'ros1'.

    A directory without metadata.yaml but holding exactly one .mcap/.db3 file is read as that
    file.  Raises BagError (EXIT_INPUT) for a missing path or something that is not a bag.
    """
    p = Path(path)
    if not p.exists():
        raise BagError(f'{path}: no such file or directory', EXIT_INPUT)
    if p.is_dir():
        if (p / 'metadata.yaml').is_file():
            return 'dir', p
        files = sorted(x for x in p.iterdir() if x.suffix in _SUFFIX_STORAGE and x.is_file())
        if len(files) == 1:
            return bag_kind(files[0])
        raise BagError(f'{path}: a directory but not a rosbag2 bag (no metadata.yaml'
                       + (f'; {len(files)} storage files' if files else '') + f'); {_NOT_A_BAG}',
                       EXIT_INPUT)
    if not p.is_file():
        raise BagError(f'{path}: not a regular file; {_NOT_A_BAG}', EXIT_INPUT)
    kind = _sniff(p)
    if kind is None:
        if p.stat().st_size == 0:
            raise BagError(f'{path}: empty file, not a bag; {_NOT_A_BAG}', EXIT_INPUT)
        with open(p, 'rb') as fh:
            head = fh.read(8)
        magics = ', '.join(f'{m!r} ({_KIND_NAME[k]})' for m, k in _MAGIC.items())
        raise BagError(f'{path}: not a bag (unknown file format): at byte 0 it holds {head!r} '
                       f'where a bag starts with one of {magics}; {_NOT_A_BAG}', EXIT_INPUT)
    return kind, p


def _sqlite_cut(p: Path) -> str:
    """Why a sqlite3 file is shorter than its header says ('' when it is not): the page size
    (bytes 16-17) times the page count (bytes 28-31, valid while bytes 92-95 equal the change
    counter at bytes 24-27; https://www.sqlite.org/fileformat.html)."""
    try:
        with open(p, 'rb') as fh:
            head = fh.read(100)
        size = p.stat().st_size
    except OSError:
        return ''
    if len(head) < 100:
        return f'the file ends at byte {len(head)} inside the 100-byte sqlite3 header'
    page = struct.unpack_from('>H', head, 16)[0]
    page = 65536 if page == 1 else page
    count, = struct.unpack_from('>I', head, 28)
    if head[24:28] != head[92:96] or not count or page * count <= size:
        return ''
    return (f'the header counts {count} pages of {page} bytes (byte 28) = {page * count} '
            f'bytes, the file ends at byte {size}: cut short (a sqlite3 file cannot be read '
            f"in part; sqlite3's .recover may save some of it)")


def _wrap_reader_error(path, exc) -> BagError:
    text = str(exc).strip() or type(exc).__name__
    try:
        kind, p = bag_kind(path)
    except BagError:
        kind = None
    cut = ''
    if kind == 'sqlite3':
        cut = _sqlite_cut(p)
    elif kind == 'mcap':
        from hair_tracking.bags.mcap_salvage import footer_problem
        cut = footer_problem(p)
    said = f'{cut}; the reader says: {text}' if cut else text
    return BagError(f'{path}: corrupt or unreadable bag: {said}', EXIT_INPUT)


#: closed copies of cut MCAP files: (real path, size, mtime) -> copy (see :func:`_salvaged`)
_SALVAGED: Dict[tuple, Path] = {}


def _warn(text: str) -> None:
    print(text, file=sys.stderr)


def _salvaged(path, p: Path, warn: Callable[[str], None]) -> Path:
    """The closed copy of the whole records of the cut MCAP file ``p`` (made at the first call
    for this file's size and time; ``warn`` then gets one line saying what was recovered)."""
    from rosbags.highlevel import AnyReader
    from hair_tracking.bags import mcap_salvage

    st = p.stat()
    key = (os.path.realpath(p), st.st_size, st.st_mtime_ns)
    if key in _SALVAGED:
        return _SALVAGED[key]
    tmp = tempfile.mkdtemp(prefix='hair_bag_salvage-')
    atexit.register(shutil.rmtree, tmp, True)
    copy = Path(tmp) / (p.stem + '.mcap')
    try:
        cut = mcap_salvage.salvage(p, copy)
    except mcap_salvage.McapError as exc:
        raise BagError(f'{path}: corrupt or unreadable bag: {exc}', EXIT_INPUT) from None
    except OSError as exc:
        raise BagError(f'{path}: cannot read: {exc.strerror or exc}', EXIT_INPUT) from None
    try:
        with AnyReader([copy], default_typestore=typestore()) as reader:
            n, t0, t1 = reader.message_count, reader.start_time, reader.end_time
    except Exception as exc:       # noqa: B902 - a damaged whole record
        raise _wrap_reader_error(path, exc) from None
    where = f'cut short at byte {cut.size} (no summary, no end magic)'
    if n == 0:
        raise BagError(f'{path}: corrupt or unreadable bag: {where}, before any whole message; '
                       f'it ends inside {cut.stop}', EXIT_INPUT)
    warn(f'warning: {path}: {where}: read to its last whole message: {n} messages, '
         f'{(t1 - t0) * 1e-9:.3f} s, {cut.kept} bytes of whole records; it ends inside '
         f'{cut.stop} (hair_sim_bag recover writes a clean copy)')
    _SALVAGED[key] = copy
    return copy


def _storage_files(kind: str, p: Path, path, warn) -> List[Path]:
    """What AnyReader opens: the bag, or, where MCAP files of it are cut short, every storage
    file of it with closed copies in their place."""
    from hair_tracking.bags.mcap_salvage import is_cut
    if kind == 'mcap':
        return [_salvaged(path, p, warn)] if is_cut(p) else [p]
    if kind == 'dir':
        files = sorted(x for x in p.iterdir() if x.suffix == '.mcap' and x.is_file())
        if any(is_cut(x) for x in files):
            return [_salvaged(x, x, warn) if is_cut(x) else x for x in files]
    return [p]


@contextmanager
def open_bag(path, warn: Optional[Callable[[str], None]] = None):
    """An opened ``rosbags.highlevel.AnyReader`` for ``path`` (see module doc for the kinds).

    A storage file whose name does not match its content (an MCAP file named ``x.dat``) is read
    through a temporary symbolic link with the right suffix.  An MCAP file cut short is read to
    its last whole message (see module doc); ``warn`` (default: a line on stderr) hears what
    was recovered, once per file.  Errors while opening become BagError; use
    :func:`messages` to read so that errors while reading do too.
    """
    from rosbags.highlevel import AnyReader

    kind, p = bag_kind(path)
    tmp = None
    try:
        files = _storage_files(kind, p, path, warn or _warn)
        if files == [p] and kind != 'dir' and p.suffix != _KIND_SUFFIX[kind]:
            tmp = tempfile.mkdtemp(prefix='hair_bag_link-')
            link = Path(tmp) / ('bag' + _KIND_SUFFIX[kind])
            os.symlink(os.path.abspath(p), link)
            files = [link]
        reader = AnyReader(files, default_typestore=typestore())
        try:
            reader.open()
        except Exception as exc:   # noqa: B902 - any failure of a third-party parser
            raise _wrap_reader_error(path, exc) from None
        reader.bag_path = str(path)
        try:
            yield reader
        finally:
            try:
                reader.close()
            except Exception:      # noqa: B902 - closing a broken file must not mask the cause
                pass
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def messages(reader, connections=None, start: Optional[int] = None,
             stop: Optional[int] = None):
    """Messages of ``connections`` (None: all; an empty list: none) as ``(connection, log
    time [ns], raw bytes)`` in log-time order, with parser errors turned into BagError."""
    if connections is not None and len(connections) == 0:
        return
    it = reader.messages(connections=connections or (), start=start, stop=stop)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except Exception as exc:   # noqa: B902 - corrupt chunk, bad CRC, truncated file ...
            raise _wrap_reader_error(getattr(reader, 'bag_path', '?'), exc) from None
        yield item


def deserialize(reader, raw, msgtype: str, topic: str = '?'):
    """Deserialize one message; a malformed one raises BagError naming the topic."""
    try:
        return reader.deserialize(raw, msgtype)
    except Exception as exc:       # noqa: B902
        raise BagError(f'{getattr(reader, "bag_path", "?")}: cannot decode a {msgtype} message '
                       f'on {topic}: {exc}', EXIT_INPUT) from None


@dataclass
class TopicInfo:
    topic: str
    msgtype: str
    count: int


def topics(reader) -> List[TopicInfo]:
    """Topics of an opened bag, sorted by name."""
    out: Dict[str, TopicInfo] = {}
    for c in reader.connections:
        info = out.setdefault(c.topic, TopicInfo(c.topic, c.msgtype, 0))
        info.count += int(c.msgcount or 0)
    return [out[k] for k in sorted(out)]


def format_topics(infos: Sequence[TopicInfo]) -> str:
    """Indented ``topic  type  count`` lines (or '(none)')."""
    if not infos:
        return '  (the bag has no topics)'
    w = max(len(i.topic) for i in infos)
    return '\n'.join(f'  {i.topic:<{w}}  {i.msgtype}  ({i.count} messages)' for i in infos)


def bag_info(path) -> dict:
    """Summary of a bag: kind, storage, topics, message count, start/end [ns], duration [s]."""
    kind, _ = bag_kind(path)
    with open_bag(path) as r:
        n = r.message_count
        start = r.start_time if n else 0
        end = r.end_time if n else 0
        return {'path': str(path), 'kind': kind, 'topics': topics(r), 'messages': n,
                'start_ns': start, 'end_ns': end, 'duration_s': max(0, end - start) * 1e-9}


# ================================================================ head poses
@dataclass
class HeadPoses:
    """Head poses read from a bag, in log-time order.

    ``t_ns`` (F,) int64 header stamps [ns] (the log time where a stamp is 0); ``log_ns`` (F,)
    int64 the bag's record times [ns]; ``position`` (F, 3) [m] in ``frame_id``; ``quaternion``
    (F, 4) (x, y, z, w) as received (finite, non-zero; the simulator's head track normalises);
    ``invalid`` counts messages that carried no usable pose (NaN/Inf, zero quaternion, bad
    stamp), with the first few reasons in ``invalid_reasons``.
    """

    topic: str
    msgtype: str
    frame_id: str
    child_frame_id: str
    t_ns: np.ndarray
    log_ns: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray
    invalid: int = 0
    invalid_reasons: List[str] = field(default_factory=list)
    messages: int = 0

    def __len__(self):
        return len(self.t_ns)

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) > 1 else 0.0


def _is_tf(msgtype: str) -> bool:
    return msgtype in TF_MSGTYPES or msgtype.endswith('/TFMessage') \
        or msgtype.endswith('/tfMessage')


def _tf_frames(reader, tf_conns, limit: Optional[int] = None):
    """{child_frame_id: parent frame_id} over the TF messages of ``tf_conns`` (first seen)."""
    frames: Dict[str, str] = {}
    n = 0
    for conn, _, raw in messages(reader, tf_conns):
        msg = deserialize(reader, raw, conn.msgtype, conn.topic)
        for tr in msg.transforms:
            frames.setdefault(str(tr.child_frame_id), str(tr.header.frame_id))
        n += 1
        if limit is not None and n >= limit:
            break
    return frames


def _ts_frames(reader, conns, limit: Optional[int] = None):
    """{child_frame_id: parent} of TransformStamped messages (the first ``limit``)."""
    frames: Dict[str, str] = {}
    for k, (conn, _, raw) in enumerate(messages(reader, conns)):
        msg = deserialize(reader, raw, conn.msgtype, conn.topic)
        frames.setdefault(str(msg.child_frame_id), str(msg.header.frame_id))
        if limit is not None and k + 1 >= limit:
            break
    return frames


def select_head_source(reader, topic: Optional[str] = None,
                       head_frame: Optional[str] = None) -> Tuple[str, str, Optional[str]]:
    """Pick the head-pose stream: ``(topic, msgtype, head frame or None)``.

    With ``topic`` given it must exist and have a supported type.  Otherwise: a single pose
    topic (PoseStamped, TransformStamped, PoseWithCovarianceStamped, Odometry) is taken; among
    several, one named ``.../head_pose``; else TF (``/tf``) with ``head_frame`` (or the one child
    frame whose name contains 'head' or 'face').  Raises BagError (EXIT_CONTENT) listing the
    bag's topics (or frames) when there is no such stream or the choice is ambiguous.
    """
    infos = topics(reader)
    by_topic = {i.topic: i for i in infos}
    listing = format_topics(infos)
    path = getattr(reader, 'bag_path', '?')
    supported = ', '.join(t.split('/')[-1] for t in POSE_MSGTYPES + TF_MSGTYPES[:1])
    if topic is not None:
        want = topic if topic in by_topic else ('/' + topic.lstrip('/'))
        if want not in by_topic:
            raise BagError(f'{path}: no topic {topic!r} in the bag; its topics:\n{listing}',
                           EXIT_CONTENT)
        mt = by_topic[want].msgtype
        if mt not in POSE_MSGTYPES and not _is_tf(mt):
            raise BagError(f'{path}: topic {want} has type {mt}, not a head pose ({supported})',
                           EXIT_CONTENT)
        return want, mt, head_frame
    poses = [i for i in infos if i.msgtype in POSE_MSGTYPES and i.count > 0]
    tfs = [i for i in infos if _is_tf(i.msgtype) and i.count > 0]
    if head_frame is not None:
        cands = [i for i in infos if i.count > 0 and not i.topic.endswith('tf_static')
                 and (_is_tf(i.msgtype) or i.msgtype.endswith('/TransformStamped'))]
        if not cands:
            raise BagError(f'{path}: --head-frame {head_frame!r} given but the bag has no TF or '
                           f'TransformStamped topic; its topics:\n{listing}', EXIT_CONTENT)
        seen: Dict[str, str] = {}
        hits = []
        for i in cands:
            conns = [c for c in reader.connections if c.topic == i.topic]
            frames = (_tf_frames(reader, conns, limit=_SCAN_LIMIT) if _is_tf(i.msgtype)
                      else _ts_frames(reader, conns, limit=_SCAN_LIMIT))
            seen.update(frames)
            if head_frame in frames:
                hits.append(i)
        if not hits:
            raise BagError(f'{path}: unknown frame {head_frame!r}: no transform has it as '
                           f'child_frame_id; child frames in the bag: '
                           + (', '.join(sorted(seen)) or '(none)'), EXIT_CONTENT)
        if len(hits) > 1:
            raise BagError(f'{path}: frame {head_frame!r} is published on several topics, '
                           f'choose one with --topic:\n' + format_topics(hits), EXIT_CONTENT)
        return hits[0].topic, hits[0].msgtype, head_frame
    if len(poses) == 1:
        return poses[0].topic, poses[0].msgtype, None
    if len(poses) > 1:
        named = [i for i in poses if i.topic.rstrip('/').endswith('head_pose')]
        if len(named) == 1:
            return named[0].topic, named[0].msgtype, None
        raise BagError(f'{path}: several pose topics, choose one with --topic:\n'
                       + format_topics(poses), EXIT_CONTENT)
    dyn = [i for i in tfs if not i.topic.endswith('tf_static')]
    if dyn:
        conns = [c for c in reader.connections if c.topic == dyn[0].topic]
        frames = _tf_frames(reader, conns, limit=_SCAN_LIMIT)
        guess = [f for f in frames if 'head' in f.lower() or 'face' in f.lower()]
        if len(guess) == 1:
            return dyn[0].topic, dyn[0].msgtype, guess[0]
        raise BagError(f'{path}: head poses would come from TF on {dyn[0].topic}; choose the '
                       f'head frame with --head-frame; child frames there: '
                       + (', '.join(sorted(frames)) or '(none)'), EXIT_CONTENT)
    raise BagError(f'{path}: no head-pose topic ({supported}); the bag has:\n{listing}',
                   EXIT_CONTENT)


def read_head_poses(path, topic: Optional[str] = None, head_frame: Optional[str] = None,
                    fixed_frame: Optional[str] = None, start_offset_s: float = 0.0,
                    duration_s: Optional[float] = None) -> HeadPoses:
    """Read the head-pose stream of a bag (see :func:`select_head_source` for the choice).

    ``start_offset_s`` / ``duration_s`` [s] keep the messages logged in
    ``[bag start + offset, bag start + offset + duration)``.  For TF, the transforms whose child
    is the head frame are used; when their parent is not ``fixed_frame``, static transforms
    (``/tf_static``) from ``fixed_frame`` down to that parent are composed in front.  Raises
    BagError: EXIT_CONTENT for no stream, an unknown head frame, a parent frame with no static
    path to ``fixed_frame``, or no usable pose in the range.
    """
    from msg_adapters.pose import pose_from_msg, PoseError
    from msg_adapters.tf_tree import compose, frame_name, TfTree

    with open_bag(path) as reader:
        src_topic, msgtype, frame = select_head_source(reader, topic, head_frame)
        is_tf = _is_tf(msgtype)
        conns = [c for c in reader.connections if c.topic == src_topic]
        t0 = reader.start_time if reader.message_count else 0
        start = t0 + int(round(max(0.0, start_offset_s) * 1e9)) if start_offset_s else None
        stop = None
        if duration_s is not None:
            stop = (start or t0) + int(round(duration_s * 1e9))

        statics = TfTree()
        if is_tf:
            static_conns = [c for c in reader.connections
                            if _is_tf(c.msgtype) and c.topic.endswith('tf_static')]
            for conn, _, raw in messages(reader, static_conns):
                statics.add_message(deserialize(reader, raw, conn.msgtype, conn.topic),
                                    static=True)
            if frame is None:
                raise BagError(f'{path}: {src_topic} is TF; choose the head frame with '
                               f'--head-frame', EXIT_CONTENT)
        t_list, log_list, p_list, q_list = [], [], [], []
        invalid, reasons, count = 0, [], 0
        frame_id = child_id = None
        seen_children: Dict[str, int] = {}
        chain_cache: Dict[str, Optional[tuple]] = {}
        n_read = 0
        for conn, log_t, raw in messages(reader, conns, start, stop):
            n_read += 1
            msg = deserialize(reader, raw, conn.msgtype, conn.topic)
            items = list(msg.transforms) if is_tf else [msg]
            for item in items:
                child = str(getattr(item, 'child_frame_id', ''))
                if is_tf or (frame is not None and msgtype.endswith('TransformStamped')):
                    seen_children[child] = seen_children.get(child, 0) + 1
                    if child != frame:
                        continue
                count += 1
                try:
                    s = pose_from_msg(item)
                except (PoseError, ValueError, TypeError) as exc:
                    invalid += 1
                    if len(reasons) < 5:
                        reasons.append(f't={log_t * 1e-9:.6f} s: {exc}')
                    continue
                p, q = np.array(s.position), np.array(s.quaternion)
                parent = s.frame_id
                if fixed_frame is not None and frame_name(parent) != frame_name(fixed_frame):
                    if parent not in chain_cache:
                        try:
                            chain_cache[parent] = statics.lookup(fixed_frame, parent)
                        except ValueError as exc:        # a loop in /tf_static
                            raise BagError(f'{path}: {exc}', EXIT_CONTENT) from None
                    ch = chain_cache[parent]
                    if ch is None:
                        raise BagError(
                            f'{path}: frame {parent!r} (parent of {child or "the head"!r}) has '
                            f'no static transform path to the fixed frame {fixed_frame!r}; '
                            f'static frames: {", ".join(statics.frames()) or "(none)"}',
                            EXIT_CONTENT)
                    p, q = compose(ch, (p, q))
                    parent = fixed_frame
                if frame_id is None:
                    frame_id, child_id = parent, child
                t_list.append(s.t_ns if s.t_ns > 0 else int(log_t))
                log_list.append(int(log_t))
                p_list.append(p)
                q_list.append(q)
        expected = sum(int(c.msgcount or 0) for c in conns)
        if start is None and stop is None and expected and n_read != expected:
            raise BagError(f'{path}: corrupt bag: its index lists {expected} messages on '
                           f'{src_topic} but only {n_read} could be read', EXIT_INPUT)
        if (is_tf or (frame is not None and msgtype.endswith('TransformStamped'))) \
                and count == 0:
            known = ', '.join(sorted(seen_children)) or '(none)'
            raise BagError(f'{path}: unknown frame {frame!r}: no transform on {src_topic} has '
                           f'it as child_frame_id; child frames there: {known}', EXIT_CONTENT)
        if not t_list:
            why = (f'; {invalid} message(s) had no usable pose, first: {reasons[0]}'
                   if invalid else '')
            rng = ' in the chosen time range' if (start or stop) else ''
            raise BagError(f'{path}: no head pose on {src_topic}{rng}{why}', EXIT_CONTENT)
        return HeadPoses(topic=src_topic, msgtype=msgtype, frame_id=frame_id or '',
                         child_frame_id=child_id or (frame or ''),
                         t_ns=np.array(t_list, dtype=np.int64),
                         log_ns=np.array(log_list, dtype=np.int64),
                         position=np.array(p_list, dtype=np.float64).reshape(-1, 3),
                         quaternion=np.array(q_list, dtype=np.float64).reshape(-1, 4),
                         invalid=invalid, invalid_reasons=reasons, messages=count)


# ================================================================ writing
def qos_profile(reliable: bool = True, depth: int = 10, transient_local: bool = False):
    """A rosbags ``Qos`` for a connection's ``offered_qos_profiles`` (what ``ros2 bag play``
    offers when it replays the topic): keep-last ``depth``, reliable or best effort, volatile
    or transient-local, no deadline/lifespan, automatic liveliness."""
    from rosbags.interfaces import (Qos, QosDurability, QosHistory, QosLiveliness,
                                    QosReliability, QosTime)
    zero = QosTime(0, 0)
    return Qos(history=QosHistory.KEEP_LAST, depth=int(depth),
               reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               durability=(QosDurability.TRANSIENT_LOCAL if transient_local
                           else QosDurability.VOLATILE),
               deadline=zero, lifespan=zero, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=zero, avoid_ros_namespace_conventions=False)


def output_storage(path, storage: Optional[str] = None) -> str:
    """The storage of an output path: from its suffix (.mcap/.db3), else ``storage`` or mcap."""
    suffix = Path(path).suffix
    if suffix in _SUFFIX_STORAGE:
        implied = _SUFFIX_STORAGE[suffix]
        if storage is not None and storage != implied:
            raise BagError(f'{path}: the name says {implied} ({suffix}) but --storage {storage} '
                           f'was given', EXIT_USAGE)
        return implied
    if storage is not None and storage not in STORAGES:
        raise BagError(f'unknown storage {storage!r}; one of {", ".join(STORAGES)}', EXIT_USAGE)
    return storage or 'mcap'


def check_output_path(path, overwrite: bool = False) -> Path:
    """Refuse an existing output (unless ``overwrite``) and a parent that is not a folder."""
    p = Path(path)
    if str(path).strip() == '':
        raise BagError('empty output path', EXIT_USAGE)
    if (p.exists() or p.is_symlink()) and not overwrite:
        raise BagError(f'{path}: output already exists (choose another name or pass '
                       f'--overwrite)', EXIT_OUTPUT)
    parent = p.parent if str(p.parent) else Path('.')
    if parent.exists() and not parent.is_dir():
        raise BagError(f'{path}: {parent} is not a folder', EXIT_OUTPUT)
    return p


def remove_path(p: Path):
    """Remove a file, a symlink or a folder tree (an output about to be replaced)."""
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif p.exists() or p.is_symlink():
        p.unlink()


class BagWriter:
    """A rosbag2 writer that commits atomically (see module doc).

    ``path`` ending in .mcap/.db3 gives one storage file, anything else a bag directory;
    ``storage`` 'mcap' (default) or 'sqlite3' for directories; ``compress`` zstd-compresses the
    MCAP chunks (MCAP only).  Use as a context manager (an
    exception aborts and removes the temporary files) or call :meth:`close` / :meth:`abort`.
    Message bytes are CDR as rclpy serializes them (identical to rosbags' serializer).
    """

    def __init__(self, path, storage: Optional[str] = None, overwrite: bool = False,
                 custom_data: Optional[Dict[str, str]] = None, compress: bool = False):
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

        self.path = check_output_path(path, overwrite)
        self.storage = output_storage(path, storage)
        self.single_file = self.path.suffix in _SUFFIX_STORAGE
        self.overwrite = overwrite
        if compress and self.storage != 'mcap':
            raise BagError(f'{path}: compression is available for MCAP output only', EXIT_USAGE)
        parent = self.path.parent if str(self.path.parent) else Path('.')
        try:
            parent.mkdir(parents=True, exist_ok=True)
            self._tmp = Path(tempfile.mkdtemp(prefix=f'.{self.path.name}.partial-',
                                              dir=parent))
        except OSError as exc:
            raise BagError(f'{path}: cannot create the output: {exc.strerror or exc}',
                           EXIT_OUTPUT) from None
        stem = self.path.stem if self.single_file else self.path.name
        self._bag_dir = self._tmp / (stem or 'bag')
        plugin = StoragePlugin.MCAP if self.storage == 'mcap' else StoragePlugin.SQLITE3
        self._writer = Writer(self._bag_dir, version=9, storage_plugin=plugin)
        if compress:
            # zstd-compressed MCAP chunks: self-describing, read natively by ros2 bag
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        for k, v in (custom_data or {}).items():
            self._writer.set_custom_data(str(k), str(v))
        try:
            self._writer.open()
        except Exception as exc:   # noqa: B902
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise BagError(f'{path}: cannot create the output: {exc}', EXIT_OUTPUT) from None
        self._conns: Dict[str, object] = {}
        self.counts: Dict[str, int] = {}
        self.closed = False

    def add_topic(self, topic: str, msgtype: str, qos=None):
        """Register ``topic`` of ``msgtype`` (e.g. 'sensor_msgs/msg/PointCloud2'); ``qos`` a
        rosbags ``Qos`` or a list of them (the offered QoS profiles)."""
        if topic in self._conns:
            return self._conns[topic]
        kwargs = {'typestore': typestore()}
        if msgtype not in typestore().types:
            raise BagError(f'unknown message type {msgtype} for {topic}', EXIT_CONTENT)
        if qos is not None:
            kwargs['offered_qos_profiles'] = qos if isinstance(qos, list) else [qos]
        conn = self._writer.add_connection(topic, msgtype, **kwargs)
        self._conns[topic] = conn
        self.counts[topic] = 0
        return conn

    def write(self, topic: str, t_ns: int, data) -> None:
        """Append serialized ``data`` (bytes) logged at ``t_ns`` [ns] to a registered topic."""
        self._writer.write(self._conns[topic], int(t_ns), bytes(data))
        self.counts[topic] += 1

    def close(self) -> Path:
        """Finish the bag and move it into place; returns the final path."""
        if self.closed:
            return self.path
        self.closed = True
        try:
            self._writer.close()
            if self.single_file:
                produced = [x for x in self._bag_dir.iterdir() if x.suffix in _SUFFIX_STORAGE]
                if len(produced) != 1:
                    raise BagError(f'{self.path}: writer produced {len(produced)} files',
                                   EXIT_FAILURE)
                src = produced[0]
            else:
                src = self._bag_dir
            if self.path.exists() or self.path.is_symlink():
                if not self.overwrite:
                    raise BagError(f'{self.path}: output appeared while writing; the new bag '
                                   f'is not moved over it', EXIT_OUTPUT)
                remove_path(self.path)
            os.replace(src, self.path)
        except OSError as exc:
            raise BagError(f'{self.path}: cannot write the output: {exc.strerror or exc}',
                           EXIT_OUTPUT) from None
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        """Drop everything written so far (nothing appears at the output path)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.close()
        except Exception:          # noqa: B902
            pass
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()
        return False


def copy_bag(src, output, *, storage: Optional[str] = None, compress: bool = False,
             overwrite: bool = False, warn: Optional[Callable[[str], None]] = None) -> dict:
    """Write every message of the bag ``src`` (read by :func:`open_bag`: a cut MCAP file to its
    last whole message) into a new bag ``output`` (:class:`BagWriter`, with the topics' QoS
    profiles; ROS 1 messages converted to CDR).  Topics of a type the Jazzy typestore does not
    know are left out, each with a line to ``warn``.  Returns ``{topic: messages}``."""
    warn = warn or _warn
    with open_bag(src, warn=warn) as reader, \
            BagWriter(output, storage=storage, overwrite=overwrite, compress=compress) as w:
        kept, types = [], {}
        for c in reader.connections:
            if c.msgtype not in typestore().types:
                warn(f'warning: {src}: {c.topic} left out: {c.msgtype} is unknown to the '
                     'rosbags Jazzy typestore')
            elif types.setdefault(c.topic, c.msgtype) != c.msgtype:
                warn(f'warning: {src}: {c.topic} left out in {c.msgtype}: the topic is '
                     f'written in {types[c.topic]}')
            else:
                w.add_topic(c.topic, c.msgtype, list(getattr(
                    getattr(c, 'ext', None), 'offered_qos_profiles', None) or []) or None)
                kept.append(c)
        for conn, t_ns, raw in messages(reader, kept):
            data = raw if reader.is2 else reader.typestore.ros1_to_cdr(raw, conn.msgtype)
            w.write(conn.topic, t_ns, data)
        return dict(w.counts)


# ================================================================ hair clouds
def cloud_messages(path, topic: str = '/hair/points'):
    """``(header stamp [ns], PointCloud2)`` of every message on ``topic`` of a bag, in log-time
    order (decode them with :func:`msg_adapters.pointcloud.pointcloud2_to_strands`)."""
    from msg_adapters.stamps import time_to_ns

    with open_bag(path) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        for conn, _, raw in messages(reader, conns):
            msg = deserialize(reader, raw, conn.msgtype, conn.topic)
            yield time_to_ns(msg.header.stamp), msg


# ================================================================ head poses -> bag
POSE_KINDS = ('pose', 'transform', 'tf')
# The topic of each kind: the hair_sim node's default input of that type, so an imported bag
# plays into the node without remapping (a 'tf' bag needs the node's use_tf).
POSE_KIND_TOPICS = {'pose': '/head_pose', 'transform': '/head_transform', 'tf': '/tf'}


def stamp_parts(t_ns: int) -> Tuple[int, int]:
    """``(sec, nanosec)`` of a ROS stamp [ns]; BagError (EXIT_USAGE) when it does not fit."""
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    if not 0 <= sec <= 2 ** 31 - 1:
        raise BagError(f'time {t_ns} ns does not fit a ROS stamp (sec is int32, >= 0)',
                       EXIT_USAGE)
    return sec, nanosec


def _time(t_ns: int):
    sec, nanosec = stamp_parts(t_ns)
    return typestore().types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)


def head_pose_message(kind: str, t_ns: int, position, quaternion, frame_id: str,
                      child_frame_id: str):
    """(msgtype, rosbags message) of one head pose: PoseStamped ('pose'), TransformStamped
    ('transform') or a TFMessage holding one TransformStamped ('tf')."""
    ts = typestore().types
    hdr = ts['std_msgs/msg/Header'](stamp=_time(t_ns), frame_id=frame_id)
    px, py, pz = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quaternion)
    quat = ts['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw)
    if kind == 'pose':
        pose = ts['geometry_msgs/msg/Pose'](
            position=ts['geometry_msgs/msg/Point'](x=px, y=py, z=pz), orientation=quat)
        return 'geometry_msgs/msg/PoseStamped', ts['geometry_msgs/msg/PoseStamped'](
            header=hdr, pose=pose)
    tr = ts['geometry_msgs/msg/Transform'](
        translation=ts['geometry_msgs/msg/Vector3'](x=px, y=py, z=pz), rotation=quat)
    stamped = ts['geometry_msgs/msg/TransformStamped'](header=hdr, child_frame_id=child_frame_id,
                                                       transform=tr)
    if kind == 'transform':
        return 'geometry_msgs/msg/TransformStamped', stamped
    if kind == 'tf':
        return 'tf2_msgs/msg/TFMessage', ts['tf2_msgs/msg/TFMessage'](transforms=[stamped])
    raise BagError(f'unknown pose message kind {kind!r}; one of {", ".join(POSE_KINDS)}',
                   EXIT_USAGE)


def write_head_pose_bag(path, t_ns, position, quaternion, *, kind: str = 'pose',
                        topic: Optional[str] = None, frame_id: str = 'world',
                        child_frame_id: str = 'head', storage: Optional[str] = None,
                        overwrite: bool = False, custom_data: Optional[Dict[str, str]] = None,
                        compress: bool = False) -> Path:
    """Write a head-pose stream to a new bag; returns its path.

    ``t_ns`` (F,) int stamps [ns] (header stamp = log time), ``position`` (F, 3) [m] in
    ``frame_id``, ``quaternion`` (F, 4) unit (x, y, z, w) head -> ``frame_id``.  ``kind`` 'pose'
    (PoseStamped on ``/head_pose``), 'transform' (TransformStamped on ``/head_transform``) or
    'tf' (TFMessage on ``/tf``, child ``child_frame_id``): the node's input topics
    (:data:`POSE_KIND_TOPICS`).  Serialized with the rosbags Jazzy
    typestore (byte-identical to rclpy's CDR); ``compress`` zstd-compresses MCAP chunks.
    """
    t = np.asarray(t_ns)
    p = np.asarray(position, dtype=np.float64)
    q = np.asarray(quaternion, dtype=np.float64)
    if t.ndim != 1 or p.shape != (len(t), 3) or q.shape != (len(t), 4):
        raise ValueError(f'need t_ns (F,), position (F, 3), quaternion (F, 4); got '
                         f'{t.shape}, {p.shape}, {q.shape}')
    if kind not in POSE_KINDS:
        raise BagError(f'unknown pose message kind {kind!r}; one of {", ".join(POSE_KINDS)}',
                       EXIT_USAGE)
    if not frame_id or (kind != 'pose' and not child_frame_id):
        raise BagError('frame ids must not be empty', EXIT_USAGE)
    topic = topic or POSE_KIND_TOPICS[kind]
    ts = typestore()
    with BagWriter(path, storage=storage, overwrite=overwrite, custom_data=custom_data,
                   compress=compress) as w:
        msgtype = head_pose_message(kind, 1, p[0] if len(p) else (0, 0, 0),
                                    q[0] if len(q) else (0, 0, 0, 1), frame_id,
                                    child_frame_id)[0]
        w.add_topic(topic, msgtype, qos_profile(reliable=True, depth=100))
        for ti, pi, qi in zip(t.tolist(), p, q):
            mt, msg = head_pose_message(kind, ti, pi, qi, frame_id, child_frame_id)
            w.write(topic, ti, ts.serialize_cdr(msg, mt))
    return Path(path)
