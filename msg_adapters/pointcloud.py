"""Strands ``(S, N, 3)`` <-> organized sensor_msgs/PointCloud2.

Layout: ``height = S`` rows (one per strand), ``width = N`` points, little-endian, fields
``x, y, z`` float32 [m] (offsets 0, 4, 8), ``strand`` uint32 (offset 12, the strand index or
the ids given), and, when colours are given, ``rgb`` float32 (offset 16) holding the packed
``0x00RRGGBB`` bits as rviz/PCL expect. ``point_step`` 16 or 20, ``row_step = N * point_step``,
``is_dense`` true when every coordinate is finite (NaN points are allowed in clouds).
Built through a numpy structured array (or straight into the CDR bytes) in one compiled pass
whose coordinates go through the package's one record writer
(:func:`hair_tracking.core.point_records.put_record`, which also says whether every coordinate
is a finite float32), no per-point Python.  :class:`CloudBuffer` can also leave the
``strand`` field out (the row is the strand; ``point_step`` 12, or 16 with ``rgb`` at offset
12): the bytes every frame copies through the middleware then shrink by a quarter or more.
"""
import array
import struct

from numba import njit
import numpy as np
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header

from msg_adapters.arrays import as_colors, as_strands
from msg_adapters.cdr import CdrWriter, ENCAPSULATION_LE, MessageBuffer, put_pieces
from msg_adapters.marker_spec import check_frame_id
from msg_adapters.stamps import split_ns, time_msg

from hair_tracking.core.point_records import put_record

_NP_OF_DATATYPE = {PointField.INT8: 'i1', PointField.UINT8: 'u1', PointField.INT16: 'i2',
                   PointField.UINT16: 'u2', PointField.INT32: 'i4', PointField.UINT32: 'u4',
                   PointField.FLOAT32: 'f4', PointField.FLOAT64: 'f8'}


def cloud_dtype(with_rgb, with_strand=True):
    """numpy structured dtype of one point (little-endian, packed): x y z, then ``strand``
    (with ``with_strand``), then ``rgb`` (with ``with_rgb``)."""
    names = ['x', 'y', 'z'] + (['strand'] if with_strand else []) + \
        (['rgb'] if with_rgb else [])
    formats = ['<f4', '<f4', '<f4'] + (['<u4'] if with_strand else []) + \
        (['<f4'] if with_rgb else [])
    return np.dtype({'names': names, 'formats': formats})


def cloud_fields(with_rgb, with_strand=True):
    """The PointField list matching :func:`cloud_dtype`."""
    dt = cloud_dtype(with_rgb, with_strand)
    types = {'f4': PointField.FLOAT32, 'u4': PointField.UINT32}
    return [PointField(name=name, offset=int(dt.fields[name][1]),
                       datatype=types[dt.fields[name][0].str[1:]], count=1)
            for name in dt.names]


def pack_rgb(colors):
    """RGB(A) in [0, 1], shape (..., 3|4) -> float32 (...) carrying 0x00RRGGBB (alpha dropped)."""
    c = np.asarray(colors, dtype=np.float64)
    c8 = np.rint(np.clip(c[..., :3], 0.0, 1.0) * 255.0).astype(np.uint32)
    packed = (c8[..., 0] << 16) | (c8[..., 1] << 8) | c8[..., 2]
    return packed.astype('<u4').view('<f4')


def pack_rgb_u32(colors):
    """Per-strand ``(S, 3|4)`` or per-point ``(S, N, 3|4)`` RGB(A) in [0, 1] -> uint32 ``(S,)``
    or ``(S, N)`` ``0x00RRGGBB``: what ``packed_rgb`` takes.  Checked and converted by
    :func:`~msg_adapters.arrays.as_colors`, as ``colors`` are, so both give the same bytes."""
    c = np.asarray(colors)
    if c.ndim not in (2, 3):
        raise ValueError(f'colors must be shaped (S, 3|4) or (S, N, 3|4), got {c.shape}')
    cols = as_colors(c, c.shape[0], c.shape[1] if c.ndim == 3 else 1)
    return pack_rgb(cols).view('<u4').reshape(c.shape[:-1])


def as_packed_rgb(packed, n_strands, n_points):
    """Packed colours ``(S,)`` (per strand) or ``(S, N)`` (per point) of unsigned 32-bit
    ``0x00RRGGBB`` values, as :func:`pack_rgb_u32` makes them -> the float32 words of the
    ``rgb`` field, ``(S, 1|N)``."""
    a = np.asarray(packed)
    if a.dtype.kind != 'u' or a.dtype.itemsize != 4 or \
            a.shape not in ((n_strands,), (n_strands, n_points)):
        raise ValueError(f'packed_rgb must be uint32 shaped ({n_strands},) or ({n_strands}, '
                         f'{n_points}), got {a.dtype} {a.shape}')
    words = np.ascontiguousarray(a, dtype='<u4').view('<f4')
    return words.reshape(a.shape if a.ndim == 2 else (n_strands, 1))


@njit(cache=True, nogil=True)
def _fill_records(records, x, ids, rgb, per_point, rot, origin):
    """One pass over the points: x y z through :func:`put_record` (the package's one record
    writer and finiteness rule), the strand id and colour words beside them.  ``records``
    (S, N, stride) float32, ``x`` (S, N, 3), ``ids`` (S,) the uint32 ids viewed as float32,
    ``rgb`` (S, 1|N) float32 packed colours or (0, 1) for none: ids and colours are bit
    patterns copied as float32 words, unchanged.  Returns True when every coordinate is
    finite."""
    bad = 0
    with_rgb = rgb.shape[0] > 0
    for s in range(records.shape[0]):
        sid = ids[s]
        for j in range(records.shape[1]):
            bad += put_record(records, s, j, x[s, j, 0], x[s, j, 1], x[s, j, 2], rot, origin,
                              False)
            records[s, j, 3] = sid
            if with_rgb:
                records[s, j, 4] = rgb[s, j if per_point else 0]
    return bad == 0


def fill_records(words, x, rgb, ids):
    """Write points into ``words``, the (S, N, 4|5+) little-endian float32 view of a cloud's
    data: x y z of ``x`` (S, N, 3) as :func:`~hair_tracking.core.point_records.put_record`
    writes them, ``ids`` (S,) uint32 as the strand word, ``rgb`` (S, 1|N) packed float32 (or
    None) as the fifth word.  Returns ``is_dense`` (every coordinate a finite float32).  Words
    past those are left alone; memory that is not 4-byte aligned is written through a copy."""
    n_strands, n_points, stride = words.shape
    if rgb is not None and rgb.shape != (n_strands, 1) and rgb.shape != (n_strands, n_points):
        raise ValueError(f'rgb must be shaped ({n_strands}, 1 or {n_points}), got {rgb.shape}')
    if rgb is not None and stride < 5:
        raise ValueError(f'records with rgb are 5 words (x y z strand rgb), got {stride}')
    direct = words.flags.c_contiguous and words.flags.aligned and \
        words.dtype == np.float32 and words.flags.writeable
    records = words if direct else np.array(words, dtype=np.float32, order='C')
    per_point = rgb is not None and rgb.shape[1] == n_points and n_points > 1
    rgb = _NO_RGB if rgb is None else _read_only(np.ascontiguousarray(rgb, dtype=np.float32))
    x = _read_only(np.ascontiguousarray(x, dtype=np.float64))
    ids = _read_only(np.ascontiguousarray(ids, dtype='<u4').view('<f4'))
    dense = bool(_fill_records(records, x, ids, rgb, per_point, _EYE, _ZERO))
    if not direct:
        words[...] = records
    return dense


def _read_only(a):
    """``a`` read-only: numba compiles one specialisation per argument type and read-only is
    part of the type, so the inputs always go in read-only (the node's frames are read-only
    views, warm-up data is not)."""
    a = a.view()
    a.flags.writeable = False
    return a


_NO_RGB = _read_only(np.zeros((0, 1), dtype=np.float32))
_EYE, _ZERO = np.eye(3), np.zeros(3)


def _check_inputs(strands, colors, strand_ids, packed_rgb=None):
    """-> (strands (S, N, 3) float64, packed rgb (S, 1|N) float32 or None, ids (S,) uint32)."""
    x = as_strands(strands, finite=False)
    n_strands, n_points = x.shape[:2]
    if packed_rgb is not None:
        if colors is not None:
            raise ValueError('give colors or packed_rgb, not both')
        rgb = as_packed_rgb(packed_rgb, n_strands, n_points)
    else:
        cols = as_colors(colors, n_strands, n_points)
        rgb = None if cols is None else pack_rgb(cols)
    return x, rgb, as_strand_ids(strand_ids, n_strands)


def as_strand_ids(strand_ids, n_strands):
    """The ``strand`` field's values: ``strand_ids`` checked as (S,) integers that fit uint32,
    or 0..S-1 when None -> (S,) little-endian uint32."""
    if strand_ids is None:
        return np.arange(n_strands, dtype='<u4')
    ids = np.asarray(strand_ids)
    if ids.shape != (n_strands,) or ids.dtype.kind not in 'iu':
        raise ValueError(f'strand_ids must be {n_strands} integers, got {ids.dtype} '
                         f'{ids.shape}')
    if n_strands and (ids.min() < 0 or ids.max() > 2 ** 32 - 1):
        raise ValueError('strand_ids must fit uint32')
    return ids.astype('<u4')


def strands_to_points(strands, colors=None, strand_ids=None, packed_rgb=None):
    """Structured point array (S, N) of :func:`cloud_dtype` and ``is_dense``.

    ``strands`` (S, N >= 1, 3) [m], NaN allowed; ``colors`` per strand (S, 3|4) or per point
    (S, N, 3|4) in [0, 1], or instead ``packed_rgb`` (the same packed once with
    :func:`pack_rgb_u32`, see :func:`as_packed_rgb`: a publisher sending the same colours every
    frame saves the packing, 0.5 ms for 10 k strands); ``strand_ids`` (S,) uint32 values for
    the ``strand`` field (default 0..S-1).
    """
    x, rgb, ids = _check_inputs(strands, colors, strand_ids, packed_rgb)
    pts = np.empty(x.shape[:2], dtype=cloud_dtype(rgb is not None))
    words = pts.view('<f4').reshape(x.shape[:2] + (pts.dtype.itemsize // 4,))
    return pts, fill_records(words, x, rgb, ids)


def strands_to_pointcloud2(strands, *, frame_id, stamp_ns=0, colors=None, strand_ids=None,
                           packed_rgb=None):
    """Organized PointCloud2 (height S, width N) of ``strands`` (S, N, 3) [m] in ``frame_id``.

    See :func:`strands_to_points` for ``colors``, ``packed_rgb`` and ``strand_ids``;
    ``stamp_ns`` [ns].
    """
    header = Header(stamp=time_msg(stamp_ns), frame_id=check_frame_id(frame_id))
    pts, dense = strands_to_points(strands, colors, strand_ids, packed_rgb)
    n_strands, n_points = pts.shape
    step = pts.dtype.itemsize
    data = array.array('B')
    data.frombytes(pts.reshape(-1).view(np.uint8))
    return PointCloud2(header=header, height=n_strands, width=n_points,
                       fields=cloud_fields('rgb' in pts.dtype.names), is_bigendian=False,
                       point_step=step, row_step=step * n_points, data=data, is_dense=dense)


def strands_to_pointcloud2_cdr(strands, *, frame_id, stamp_ns=0, colors=None, strand_ids=None,
                               packed_rgb=None):
    """The serialized CDR bytes of :func:`strands_to_pointcloud2` (same arguments).

    Skips the structured array, the ``array.array`` and rclpy's serializer: the points are
    written straight into the message bytes. Padding zeroed (see :mod:`msg_adapters.cdr`).
    """
    stamp, frame_id = split_ns(stamp_ns, 'stamp_ns'), check_frame_id(frame_id)
    x, rgb, ids = _check_inputs(strands, colors, strand_ids, packed_rgb)
    n_strands, n_points = x.shape[:2]
    w, step, nbytes, at_data, at_dense = _cloud_layout(stamp, frame_id, n_strands, n_points,
                                                       rgb is not None)
    buf = MessageBuffer(w.offset)
    put_pieces(buf.body, w.pieces())
    words = buf.body[at_data:at_data + nbytes].view('<f4').reshape(n_strands, n_points, step // 4)
    buf.body[at_dense] = fill_records(words, x, rgb, ids)
    return buf.finish()


def _cloud_layout(stamp, frame_id, n_strands, n_points, with_rgb, with_strand=True):
    """A CdrWriter holding a cloud's message up to its data, and ``(point_step, data size,
    data offset, is_dense offset)`` (body offsets; is_dense written false)."""
    step = cloud_dtype(with_rgb, with_strand).itemsize
    nbytes = step * n_strands * n_points
    w = CdrWriter()
    w.time(*stamp)
    w.string(frame_id)
    w.uint32(n_strands)
    w.uint32(n_points)
    fields = cloud_fields(with_rgb, with_strand)
    w.uint32(len(fields))
    for f in fields:
        w.string(f.name)
        w.uint32(f.offset)
        w.uint8(f.datatype)
        w.uint32(f.count)
    w.boolean(False)                            # is_bigendian
    w.uint32(step)
    w.uint32(step * n_points)
    w.uint32(nbytes)
    at_data = w.hole(nbytes)
    at_dense = w.boolean(False)
    return w, step, nbytes, at_data, at_dense


class CloudBuffer:
    """The CDR bytes of one organized cloud (those of :func:`strands_to_pointcloud2_cdr`),
    kept between frames and rewritten in place.

    A publisher that sends the same strands every frame changes only the stamp and the x y z
    words; :meth:`encode` writes the header, the fields, the strand ids and the colours only
    when they change, and the coordinates through ``write_xyz(words, stride) -> bool``, which
    puts float32 x y z at the start of each record of the flat float32 ``words`` (the
    records' other words are left alone) and says whether all are finite (``is_dense``), e.g.
    :meth:`hair_tracking.simulator.HairSimulator.record_writer`'s.  The buffer is not handed
    out as a new object per frame: it must be published (copied by the middleware) before the
    next :meth:`encode` overwrites it, as :class:`msg_adapters.rcl_serialized.SerializedPublisher`
    does.  A fresh buffer each frame cost its page faults (3.2 MB at 10 k strands x 16 points)
    and a copy of the ids and colours.
    """

    def __init__(self):
        self._layout = None          # (S, N, frame_id, with rgb, with strand) laid out for
        self._msg = None             # the whole message (encapsulation + body), uint8
        self._ids = self._rgb = None     # what the strand / rgb words hold now

    def encode(self, n_strands, n_points, write_xyz, *, frame_id, stamp_ns=0, packed_rgb=None,
               strand_ids=None, strand_field=True):
        """The message (a uint8 array, valid until the next call) of a cloud of ``n_strands``
        x ``n_points`` whose coordinates ``write_xyz`` writes; other arguments as
        :func:`strands_to_pointcloud2_cdr` (``packed_rgb`` the packed colours or None).
        ``strand_field=False`` leaves the ``strand`` field out (``strand_ids`` unused)."""
        stamp, frame_id = split_ns(stamp_ns, 'stamp_ns'), check_frame_id(frame_id)
        n_strands, n_points = int(n_strands), int(n_points)
        if n_strands < 0 or n_points < 1:
            raise ValueError(f'a cloud needs S >= 0 strands of N >= 1 points, got '
                             f'{n_strands} x {n_points}')
        rgb = None if packed_rgb is None else \
            as_packed_rgb(packed_rgb, n_strands, n_points).view('<u4')
        strand_field = bool(strand_field)
        ids = as_strand_ids(strand_ids, n_strands) if strand_field else None
        layout = (n_strands, n_points, frame_id, rgb is not None, strand_field)
        if layout != self._layout:
            w, step, nbytes, at_data, at_dense = _cloud_layout(
                stamp, frame_id, n_strands, n_points, rgb is not None, strand_field)
            msg = np.zeros(len(ENCAPSULATION_LE) + w.offset, dtype=np.uint8)
            msg[:len(ENCAPSULATION_LE)] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
            body = msg[len(ENCAPSULATION_LE):]
            put_pieces(body, w.pieces())
            self._msg, self._body, self._at_dense = msg, body, at_dense
            self._stride = step // 4
            self._words = body[at_data:at_data + nbytes].view('<f4')
            self._records = self._words.view('<u4').reshape(n_strands * n_points, self._stride)
            self._layout, self._ids, self._rgb = layout, None, None
        if ids is not None and (self._ids is None or not np.array_equal(ids, self._ids)):
            self._records[:, 3] = np.repeat(ids, n_points)
            self._ids = ids.copy()
        if rgb is not None and (self._rgb is None or not np.array_equal(rgb, self._rgb)):
            self._records[:, self._stride - 1] = \
                np.broadcast_to(rgb, (n_strands, n_points)).reshape(-1)
            self._rgb = rgb.copy()
        self._body[:8] = np.frombuffer(struct.pack('<iI', *stamp), dtype=np.uint8)
        self._body[self._at_dense] = bool(write_xyz(self._words, self._stride))
        return self._msg


def _field_dtype(msg, names):
    by_name = {f.name: f for f in msg.fields}
    missing = [n for n in names if n not in by_name]
    if missing:
        raise ValueError(f'PointCloud2 has no field(s) {missing}; it has {list(by_name)}')
    formats, offsets = [], []
    for n in names:
        f = by_name[n]
        if f.datatype not in _NP_OF_DATATYPE or f.count != 1:
            raise ValueError(f'PointCloud2 field {n!r}: unsupported datatype {f.datatype} or '
                             f'count {f.count}')
        formats.append(('>' if msg.is_bigendian else '<') + _NP_OF_DATATYPE[f.datatype])
        offsets.append(f.offset)
    return np.dtype({'names': list(names), 'formats': formats, 'offsets': offsets,
                     'itemsize': msg.point_step})


def pointcloud2_to_strands(msg, dtype=np.float64):
    """PointCloud2 -> ``(points (height, width, 3) dtype, strand_ids (height,) uint32)``.

    Reads fields by name and offset (any order, padding, ``row_step`` > ``width * point_step``,
    either byte order). ``strand_ids`` come from the ``strand`` field (which must be constant
    along each row) or are 0..height-1 when the cloud has none. An unorganized cloud comes back
    as one row.
    """
    h, w, step = int(msg.height), int(msg.width), int(msg.point_step)
    if w and step * w > msg.row_step:
        raise ValueError(f'row_step {msg.row_step} < width * point_step = {w * step}')
    raw = np.frombuffer(memoryview(msg.data), dtype=np.uint8)
    if raw.size < h * msg.row_step:
        raise ValueError(f'PointCloud2 data has {raw.size} bytes, expected height * row_step = '
                         f'{h * msg.row_step}')
    names = ['x', 'y', 'z']
    has_strand = any(f.name == 'strand' for f in msg.fields)
    dt = _field_dtype(msg, names + (['strand'] if has_strand else []))
    rows = raw[:h * msg.row_step].reshape(h, msg.row_step)[:, :w * step]
    pts = np.ascontiguousarray(rows).view(dt).reshape(h, w)
    out = np.empty((h, w, 3), dtype=dtype)
    for k, n in enumerate(names):
        out[..., k] = pts[n]
    if not has_strand or not w:
        return out, np.arange(h, dtype=np.uint32)
    ids = pts['strand']
    if (ids != ids[:, :1]).any():
        raise ValueError('PointCloud2 field strand is not constant along rows: not a cloud of '
                         'strands')
    return out, ids[:, 0].astype(np.uint32)
