"""Strands <-> organized PointCloud2: layout, round trip, CDR fast path, DDS."""
import struct

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import PointCloud2, PointField

from loopback import publish_and_receive
from msg_adapters.pointcloud import (CloudBuffer, pack_rgb, pack_rgb_u32, pointcloud2_to_strands,
                                     strands_to_pointcloud2, strands_to_pointcloud2_cdr)

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
CLOUD = 'sensor_msgs/msg/PointCloud2'


def reference_rgb(c):
    """Plain reference of the PCL packed colour of one RGB(A) triple in [0, 1]."""
    r, g, b = (int(round(v * 255.0)) for v in c[:3])
    return struct.unpack('<f', struct.pack('<I', (r << 16) | (g << 8) | b))[0]


def reference_data(x, cols, ids):
    out = bytearray()
    for s in range(x.shape[0]):
        for i in range(x.shape[1]):
            out += struct.pack('<fffI', *x[s, i], ids[s])
            if cols is not None:
                c = cols[s] if cols.ndim == 2 else cols[s, i]
                out += struct.pack('<f', reference_rgb(c))
    return bytes(out)


@pytest.mark.parametrize('color_mode', [None, 'strand', 'point'])
def test_layout_and_data(color_mode):
    rng = np.random.default_rng(2)
    x = rng.normal(size=(3, 5, 3))
    cols = {None: None, 'strand': rng.random((3, 4)), 'point': rng.random((3, 5, 3))}[color_mode]
    msg = strands_to_pointcloud2(x, frame_id='head', stamp_ns=3_000_000_007, colors=cols)
    step = 16 if cols is None else 20
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (3, 5, step, 5 * step)
    assert (msg.is_bigendian, msg.is_dense) == (False, True)
    assert (msg.header.frame_id, msg.header.stamp.sec, msg.header.stamp.nanosec) == ('head', 3, 7)
    names = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    expected = [('x', 0, PointField.FLOAT32, 1), ('y', 4, PointField.FLOAT32, 1),
                ('z', 8, PointField.FLOAT32, 1), ('strand', 12, PointField.UINT32, 1)]
    if cols is not None:
        expected.append(('rgb', 16, PointField.FLOAT32, 1))
    assert names == expected
    assert bytes(msg.data) == reference_data(x, cols, [0, 1, 2])


def test_pack_rgb_matches_reference():
    rng = np.random.default_rng(4)
    c = np.vstack([rng.random((50, 4)), [[0, 0, 0, 0], [1, 1, 1, 1], [1, 0, 0, 1]]])
    packed = pack_rgb(c)
    assert packed.dtype == np.float32
    np.testing.assert_array_equal(packed.view(np.uint32),
                                  np.float32([reference_rgb(v) for v in c]).view(np.uint32))
    assert pack_rgb([1.0, 0.0, 0.0]).view(np.uint32) == 0xFF0000


def test_round_trip_with_ids_and_nan():
    rng = np.random.default_rng(6)
    x = rng.normal(size=(4, 7, 3))
    x[2, 3, 1] = np.nan
    msg = strands_to_pointcloud2(x, frame_id='w', strand_ids=np.array([5, 9, 2**32 - 1, 0]))
    assert msg.is_dense is False
    y32, ids = pointcloud2_to_strands(msg, dtype=np.float32)
    np.testing.assert_array_equal(y32, x.astype(np.float32))          # NaN == NaN here
    np.testing.assert_array_equal(ids, [5, 9, 2**32 - 1, 0])
    y64, _ = pointcloud2_to_strands(msg)
    assert y64.dtype == np.float64 and y64.shape == (4, 7, 3)
    np.testing.assert_array_equal(y64, x.astype(np.float32).astype(np.float64))


def test_reader_handles_foreign_layouts():
    """Reordered fields, padding, row padding, big-endian, no strand field, one row."""
    rng = np.random.default_rng(8)
    pts = rng.normal(size=(2, 3, 3))
    dt = np.dtype({'names': ['z', 'x', 'y', 'strand'], 'formats': ['>f8', '>f8', '>f8', '>u2'],
                   'offsets': [0, 8, 24, 32], 'itemsize': 40})
    rows = np.zeros((2, 3 * 40 + 8), dtype=np.uint8)
    arr = rows[:, :120].view(dt)
    arr['x'], arr['y'], arr['z'] = pts[..., 0], pts[..., 1], pts[..., 2]
    arr['strand'] = [[7], [3]]
    msg = PointCloud2(height=2, width=3, is_bigendian=True, point_step=40, row_step=128,
                      fields=[PointField(name='z', offset=0, datatype=PointField.FLOAT64, count=1),
                              PointField(name='x', offset=8, datatype=PointField.FLOAT64, count=1),
                              PointField(name='y', offset=24, datatype=PointField.FLOAT64,
                                         count=1),
                              PointField(name='strand', offset=32, datatype=PointField.UINT16,
                                         count=1)])
    msg.data = rows.tobytes()
    y, ids = pointcloud2_to_strands(msg)
    np.testing.assert_array_equal(y, pts)
    np.testing.assert_array_equal(ids, [7, 3])
    msg.fields = msg.fields[:3]
    np.testing.assert_array_equal(pointcloud2_to_strands(msg)[1], [0, 1])


def test_reader_takes_rosbags_clouds_as_rclpy_ones():
    """A cloud deserialized by rosbags (a bag's) decodes to what the rclpy message gives."""
    rng = np.random.default_rng(12)
    strands = rng.normal(size=(4, 6, 3))
    cdr = strands_to_pointcloud2_cdr(strands, frame_id='w', colors=rng.uniform(size=(4, 3)),
                                     strand_ids=np.array([5, 1, 9, 2]))
    from_rclpy = pointcloud2_to_strands(deserialize_message(bytes(cdr), PointCloud2))
    from_bag = pointcloud2_to_strands(TYPESTORE.deserialize_cdr(bytes(cdr), CLOUD))
    for a, b in zip(from_bag, from_rclpy):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(from_bag[0], strands.astype(np.float32))
    np.testing.assert_array_equal(from_bag[1], [5, 1, 9, 2])


def test_reader_errors():
    msg = strands_to_pointcloud2(np.zeros((2, 3, 3)), frame_id='w')
    bad = PointCloud2(height=msg.height, width=msg.width, point_step=msg.point_step,
                      row_step=msg.row_step, fields=msg.fields[1:], data=msg.data)
    with pytest.raises(ValueError, match=r"no field\(s\) \['x'\]"):
        pointcloud2_to_strands(bad)
    bad = PointCloud2(height=msg.height, width=msg.width, point_step=msg.point_step,
                      row_step=msg.row_step, fields=msg.fields, data=msg.data[:-1])
    with pytest.raises(ValueError, match='data has'):
        pointcloud2_to_strands(bad)
    mixed = strands_to_pointcloud2(np.zeros((1, 4, 3)), frame_id='w')
    mixed.data[12] = 1                      # strand id of point 0 differs from the rest
    with pytest.raises(ValueError, match='not constant'):
        pointcloud2_to_strands(mixed)


def test_builder_errors():
    with pytest.raises(ValueError, match=r'\(S, N, 3\)'):
        strands_to_pointcloud2(np.zeros((3, 3)), frame_id='w')
    with pytest.raises(ValueError, match='frame_id'):
        strands_to_pointcloud2(np.zeros((1, 2, 3)), frame_id='')
    with pytest.raises(ValueError, match='colors'):
        strands_to_pointcloud2(np.zeros((1, 2, 3)), frame_id='w', colors=np.zeros((2, 3)))
    with pytest.raises(ValueError, match='strand_ids'):
        strands_to_pointcloud2(np.zeros((2, 2, 3)), frame_id='w', strand_ids=[1])
    with pytest.raises(ValueError, match='uint32'):
        strands_to_pointcloud2(np.zeros((1, 2, 3)), frame_id='w', strand_ids=[-1])


def reference_cdr(msg):
    """rclpy's bytes with Fast-CDR's uninitialised padding rewritten as zeros (by rosbags)."""
    raw = serialize_message(msg)
    return raw, bytes(TYPESTORE.serialize_cdr(TYPESTORE.deserialize_cdr(raw, CLOUD), CLOUD))


@pytest.mark.parametrize('shape', [(0, 1), (0, 16), (1, 1), (3, 5), (17, 16)])
@pytest.mark.parametrize('with_colors', [False, True])
@pytest.mark.parametrize('frame_id', ['h', 'head', 'hé', 'frame_odd'])
def test_cdr_fast_path_byte_identical(shape, with_colors, frame_id):
    rng = np.random.default_rng(sum(shape) + len(frame_id))
    x = rng.normal(size=shape + (3,))
    if x.size:
        x.flat[0] = np.nan
    kw = dict(frame_id=frame_id, stamp_ns=99_000_000_001,
              colors=rng.random(shape[:1] + (3,)) if with_colors else None)
    msg = strands_to_pointcloud2(x, **kw)
    fast = strands_to_pointcloud2_cdr(x, **kw)
    raw, ref = reference_cdr(msg)
    assert len(fast) == len(raw)
    a, r, z = (np.frombuffer(b, np.uint8) for b in (fast, raw, ref))
    assert (a[r != z] == 0).all()
    assert fast == ref
    assert deserialize_message(fast, PointCloud2) == msg


def test_publish_cloud_bytes_over_dds():
    rng = np.random.default_rng(12)
    x = rng.normal(size=(1000, 16, 3))                 # 320 kB
    kw = dict(frame_id='head', stamp_ns=5, colors=rng.random((1000, 3)))
    expected = strands_to_pointcloud2(x, **kw)
    got = publish_and_receive(PointCloud2, [strands_to_pointcloud2_cdr(x, **kw)], 72)
    assert got[0] == expected
    y, ids = pointcloud2_to_strands(got[0])
    np.testing.assert_array_equal(y, x.astype(np.float32))
    np.testing.assert_array_equal(ids, np.arange(1000))


def _fill_numpy(words, x, rgb, ids):
    """The records of :func:`msg_adapters.pointcloud.fill_records` with numpy alone."""
    words[..., :3] = x
    words[..., 3:4].view('<u4')[..., 0] = ids[:, None]
    if rgb is not None:
        words[..., 4] = rgb
    return bool(np.isfinite(words[..., :3]).all())


@pytest.mark.parametrize('rgb_mode', ['none', 'strand', 'point'])
def test_compiled_fill_matches_numpy_fill(rgb_mode):
    """The record writer and plain numpy write the same bytes and the same ``is_dense``, with
    NaN, Inf, a coordinate too large for float32 (finite as float64, Inf once written),
    per-strand and per-point colours and ids beyond 2^23 (their bits go through float32 words
    unchanged); memory that is not 4-byte aligned gets the same bytes."""
    from msg_adapters.pointcloud import fill_records
    rng = np.random.default_rng(7)
    s, n = 37, 5
    x = rng.normal(size=(s, n, 3))
    ids = rng.integers(0, 2 ** 32 - 1, size=s, dtype=np.uint64).astype('<u4')
    rgb = None if rgb_mode == 'none' else pack_rgb(
        rng.random((s, 1 if rgb_mode == 'strand' else n, 3)))
    record = 4 if rgb is None else 5
    for bad in (None, (3, 2, 1, np.nan), (0, 0, 0, np.inf), (5, 4, 2, -1e39)):
        xx = x.copy()
        if bad is not None:
            xx[bad[:3]] = bad[3]
        fast = np.full((s, n, record), -1.0, dtype='<f4')
        slow = np.full((s, n, record), -2.0, dtype='<f4')
        with np.errstate(over='ignore'):
            dense = fill_records(fast, xx, rgb, ids)
            assert dense == _fill_numpy(slow, xx, rgb, ids) == (bad is None)
        assert fast.tobytes() == slow.tobytes()
    raw = np.zeros(s * n * record * 4 + 1, dtype=np.uint8)
    odd = raw[1:].view('<f4').reshape(s, n, record)       # not 4-byte aligned
    assert not odd.flags.aligned
    assert fill_records(odd, x, rgb, ids)
    ref = np.empty_like(fast)
    _fill_numpy(ref, x, rgb, ids)
    assert odd.tobytes() == ref.tobytes()
    with pytest.raises(ValueError, match='rgb must be shaped'):
        fill_records(fast, x, np.zeros((s, n + 1), dtype='<f4'), ids)


def test_one_finiteness_rule_for_every_cloud():
    """A coordinate finite as float64 but beyond float32 is not dense, whether the cloud is
    written from strands (``strands_to_pointcloud2_cdr``) or through a writer into a
    :class:`CloudBuffer` (the node's path): one record writer."""
    from hair_tracking.core.point_records import points_to_records
    x = np.zeros((2, 3, 3))
    x[1, 2, 0] = 1e39
    msg = deserialize_message(strands_to_pointcloud2_cdr(x, frame_id='m'), PointCloud2)
    buf = CloudBuffer().encode(2, 3, lambda words, stride: points_to_records(words, stride, x),
                               frame_id='m')
    assert not msg.is_dense
    assert not deserialize_message(bytes(buf), PointCloud2).is_dense
    x[1, 2, 0] = 1e38
    assert deserialize_message(strands_to_pointcloud2_cdr(x, frame_id='m'), PointCloud2).is_dense


def test_compiled_fill_other_record_sizes():
    """Records wider than the cloud's own get the same words and keep the extra words;
    colours need 5-word records."""
    from msg_adapters.pointcloud import fill_records
    rng = np.random.default_rng(8)
    s, n = 11, 3
    x = rng.normal(size=(s, n, 3))
    x[4, 1, 2] = np.nan
    ids = np.arange(s, dtype='<u4') * 3
    for record in (5, 7):
        fast = np.full((s, n, record), 9.0, dtype='<f4')
        slow = fast.copy()
        assert not fill_records(fast, x, None, ids)
        assert not _fill_numpy(slow, x, None, ids)
        assert fast.tobytes() == slow.tobytes()
        assert np.all(fast[..., 4:] == 9.0)
    with pytest.raises(ValueError, match='5 words'):
        fill_records(np.zeros((s, n, 4), dtype='<f4'), x, np.zeros((s, 1), dtype='<f4'), ids)


@pytest.mark.parametrize('per_point', [False, True])
def test_packed_rgb_gives_the_same_cloud_as_colors(per_point):
    """Colours packed once (``pack_rgb_u32``, what the node caches) and passed as
    ``packed_rgb`` give the same bytes as ``colors`` on both paths; wrong shapes or types and
    both arguments at once are rejected with what was expected."""
    from msg_adapters.pointcloud import pack_rgb_u32
    rng = np.random.default_rng(9)
    s, n = 255, 4
    x = rng.normal(size=(s, n, 3))
    cols = rng.random((s, n, 4) if per_point else (s, 4))
    edge = (np.arange(s) + 0.5) / 255.0     # halfway between two 8-bit levels: float32 or
    cols[..., 1] = edge[:, None] if per_point else edge     # float64 rounding decides
    packed = pack_rgb_u32(cols)
    assert packed.dtype == np.uint32 and packed.shape == cols.shape[:-1]
    kw = dict(frame_id='map', stamp_ns=1_500_000_000)
    assert strands_to_pointcloud2_cdr(x, packed_rgb=packed, **kw) == \
        strands_to_pointcloud2_cdr(x, colors=cols, **kw)
    a = strands_to_pointcloud2(x, packed_rgb=packed, **kw)
    b = strands_to_pointcloud2(x, colors=cols, **kw)
    assert bytes(a.data) == bytes(b.data) and a.fields == b.fields
    with pytest.raises(ValueError, match='not both'):
        strands_to_pointcloud2_cdr(x, colors=cols, packed_rgb=packed, **kw)
    for bad in (packed.astype(np.int32), packed[:-1], packed.astype(np.uint64)):
        with pytest.raises(ValueError, match='packed_rgb must be uint32'):
            strands_to_pointcloud2_cdr(x, packed_rgb=bad, **kw)
    with pytest.raises(ValueError, match=r'\[0, 1\]'):
        pack_rgb_u32(np.full((2, 3), 1.5))


def test_compiled_fill_has_one_specialisation_for_read_only_and_writable_inputs():
    """Read-only inputs (the node's frames are read-only views) and writable ones (warm-up
    data) use the same compiled code: a second specialisation would be compiled in the middle
    of the first published frame."""
    from msg_adapters import pointcloud
    rng = np.random.default_rng(10)
    s, n = 6, 4
    words = np.zeros((s, n, 5), dtype='<f4')
    ids = np.arange(s, dtype='<u4')
    seen = set()
    for writable in (True, False):
        x = rng.normal(size=(s, n, 3))
        rgb = rng.random((s, 1)).astype('<f4')
        for a in (x, rgb, ids):
            a.flags.writeable = writable
        assert pointcloud.fill_records(words, x, rgb, ids)
        seen.add(len(pointcloud._fill_records.signatures))
    assert len(seen) == 1


def _xyz_writer(x):
    """A CloudBuffer ``write_xyz`` for (S, N, 3) float64 ``x``."""
    def write(words, stride):
        rec = words.reshape(-1, stride)
        rec[:, :3] = x.reshape(-1, 3)
        return bool(np.isfinite(rec[:, :3]).all())
    return write


def test_cloud_buffer_gives_the_bytes_of_the_cdr_path_frame_after_frame():
    rng = np.random.default_rng(21)
    buf = CloudBuffer()
    seen = set()
    # (strands, points, frame_id, colour mode, ids): reuse the layout, then change each part
    frames = [(4, 6, 'odom', 'strand', None), (4, 6, 'odom', 'strand', None),
              (4, 6, 'odom', 'strand', None), (4, 6, 'map', 'strand', None),
              (4, 6, 'map', 'point', None), (4, 6, 'map', None, None),
              (4, 6, 'map', 'strand', [7, 3, 2 ** 32 - 1, 0]), (5, 6, 'map', 'strand', None),
              (5, 3, 'map', 'strand', None), (0, 3, 'map', 'strand', None),
              (2, 1, 'hé', 'strand', None)]
    colours = rng.random((4, 3))
    for k, (s, n, frame_id, mode, ids) in enumerate(frames):
        x = rng.normal(size=(s, n, 3))
        if k == 2:
            x[1, 2, 0] = np.nan                         # is_dense false, then true again
        if k == 3:
            colours = rng.random((4, 3))                # same layout, new colours
        cols = {None: None, 'strand': colours[:s] if s <= 4 else rng.random((s, 3)),
                'point': rng.random((s, n, 3))}[mode]
        packed = None if cols is None else pack_rgb_u32(cols)
        stamp = 1_000_000_000 * k + 17 * k
        data = buf.encode(s, n, _xyz_writer(x), frame_id=frame_id, stamp_ns=stamp,
                          packed_rgb=packed, strand_ids=ids)
        ref = strands_to_pointcloud2_cdr(x, frame_id=frame_id, stamp_ns=stamp, colors=cols,
                                         strand_ids=ids)
        assert isinstance(data, np.ndarray) and data.dtype == np.uint8
        assert data.tobytes() == ref, f'frame {k}'
        seen.add(data.ctypes.data)
        assert deserialize_message(data.tobytes(), PointCloud2).is_dense == (k != 2)
    assert len(seen) < len(frames)          # the buffer was reused while the layout held


@pytest.mark.parametrize('with_strand, with_rgb, step',
                         [(False, False, 12), (False, True, 16), (True, False, 16),
                          (True, True, 20)])
def test_cloud_buffer_leaves_out_the_fields_not_asked_for(with_strand, with_rgb, step):
    """Without ``strand`` (and ``rgb``) each point is x y z (and rgb at offset 12); rclpy reads
    the message, the rows give back the strands, and the layout changes in the same buffer
    from the full one and back."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(3, 4, 3))
    cols = rng.random((3, 3))
    buf = CloudBuffer()
    full = buf.encode(3, 4, _xyz_writer(x), frame_id='w', packed_rgb=pack_rgb_u32(cols))
    assert full.tobytes() == strands_to_pointcloud2_cdr(x, frame_id='w', colors=cols)
    data = buf.encode(3, 4, _xyz_writer(x), frame_id='w', stamp_ns=9,
                      packed_rgb=pack_rgb_u32(cols) if with_rgb else None,
                      strand_field=with_strand)
    msg = deserialize_message(data.tobytes(), PointCloud2)
    names = ['x', 'y', 'z'] + (['strand'] if with_strand else []) + (['rgb'] if with_rgb else [])
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        (n, 4 * k, PointField.UINT32 if n == 'strand' else PointField.FLOAT32, 1)
        for k, n in enumerate(names)]
    assert (msg.point_step, msg.row_step, msg.height, msg.width) == (step, 4 * step, 3, 4)
    assert len(msg.data) == 12 * step and msg.is_dense
    pts, ids = pointcloud2_to_strands(msg)
    assert np.array_equal(pts, x.astype(np.float32)) and np.array_equal(ids, [0, 1, 2])
    if with_rgb:
        rgb = np.frombuffer(bytes(msg.data), '<f4').reshape(3, 4, step // 4)[..., -1]
        expect = [[reference_rgb(c)] * 4 for c in cols]
        assert np.array_equal(rgb.view('<u4'), np.array(expect, '<f4').view('<u4'))
    again = buf.encode(3, 4, _xyz_writer(x), frame_id='w', packed_rgb=pack_rgb_u32(cols))
    assert again.tobytes() == full.tobytes()


def test_cloud_buffer_checks_its_inputs():
    buf = CloudBuffer()
    write = _xyz_writer(np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match='packed_rgb'):
        buf.encode(2, 3, write, frame_id='w', packed_rgb=np.zeros(3, np.uint32))
    with pytest.raises(ValueError, match='strand_ids'):
        buf.encode(2, 3, write, frame_id='w', strand_ids=[1])
    with pytest.raises(ValueError, match='N >= 1'):
        buf.encode(2, 0, write, frame_id='w')
    with pytest.raises(ValueError, match='stamp_ns'):
        buf.encode(2, 3, write, frame_id='w', stamp_ns=-1)
