"""The numpy CDR encoder of MarkerArray against rclpy's serializer, rosbags and real DDS."""

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import get_typestore, Stores
from sensor_msgs.msg import CompressedImage
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray, MeshFile

from loopback import publish_and_receive
from msg_adapters import marker_cdr
from msg_adapters.cdr import CdrWriter, ENCAPSULATION_LE
from msg_adapters.marker_cdr import strands_to_marker_array_cdr, write_marker
from msg_adapters.markers import delete_all_marker, strands_to_marker_array

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MARKER_ARRAY = 'visualization_msgs/msg/MarkerArray'


def reference_cdr(msg, typename=MARKER_ARRAY):
    """rclpy's serialization with its padding zeroed.

    Fast-CDR leaves alignment padding uninitialised, so serialize_message may hold arbitrary
    bytes there; rosbags (an independent CDR implementation) reads those bytes back and writes
    them again with zero padding. Everything but padding is rclpy's.
    """
    raw = serialize_message(msg)
    ref = bytes(TYPESTORE.serialize_cdr(TYPESTORE.deserialize_cdr(raw, typename), typename))
    assert len(ref) == len(raw)
    return raw, ref


def assert_same_message(x, style, **kw):
    obj = strands_to_marker_array(x, style=style, **kw)
    fast = strands_to_marker_array_cdr(x, style=style, **kw)
    assert isinstance(fast, bytes)
    raw, ref = reference_cdr(obj)
    assert fast[:4] == ENCAPSULATION_LE
    assert len(fast) == len(raw)
    a, r, z = (np.frombuffer(b, np.uint8) for b in (fast, raw, ref))
    padding = r != z                     # where rclpy wrote uninitialised padding
    assert (a[padding] == 0).all()
    assert fast == ref                   # byte-identical, padding zero
    assert deserialize_message(fast, MarkerArray) == obj
    return obj, fast


def random_strands(rng, n_strands, n_points):
    return rng.normal(scale=0.1, size=(n_strands, n_points, 3))


def test_field_lists_match_installed_messages():
    assert list(Marker.get_fields_and_field_types()) == list(marker_cdr.MARKER_FIELDS)
    # The nested types written inline by write_marker.
    assert list(Header.get_fields_and_field_types()) == ['stamp', 'frame_id']
    assert list(CompressedImage.get_fields_and_field_types()) == ['header', 'format', 'data']
    assert list(MeshFile.get_fields_and_field_types()) == ['filename', 'data']
    assert Marker.LINE_LIST == 5 and Marker.LINE_STRIP == 4 and Marker.DELETEALL == 3


@pytest.mark.parametrize('style', ['line_list', 'line_strips'])
@pytest.mark.parametrize('color_mode', [None, 'strand_rgba', 'strand_rgb', 'point_rgba',
                                        'point_rgb'])
def test_byte_identical_with_and_without_colours(style, color_mode):
    rng = np.random.default_rng(7)
    n_strands, n_points = 7, 5                 # odd strand count, odd point count
    x = random_strands(rng, n_strands, n_points)
    shapes = {'strand_rgba': (n_strands, 4), 'strand_rgb': (n_strands, 3),
              'point_rgba': (n_strands, n_points, 4), 'point_rgb': (n_strands, n_points, 3)}
    colors = None if color_mode is None else rng.random(shapes[color_mode])
    obj, _ = assert_same_message(x, style, frame_id='head', stamp_ns=1_700_000_000_123_456_789,
                                 ns='hair', colors=colors, width=0.0025,
                                 color=(0.2, 0.4, 0.6, 0.8), lifetime_ns=250_000_000,
                                 first_id=11)
    n_colors = [len(m.colors) for m in obj.markers]
    if color_mode is None:
        assert n_colors == [0] * len(obj.markers)
    else:
        assert n_colors == [len(m.points) for m in obj.markers]


@pytest.mark.parametrize('style', ['line_list', 'line_strips'])
@pytest.mark.parametrize('frame_id,ns', [('a', ''), ('ab', 'x'), ('abc', 'xy'), ('abcd', 'xyz'),
                                         ('tête', 'ñ'), ('頭_frame', 'strands_ü'),
                                         ('head_link', 'hair/ghosts')])
@pytest.mark.parametrize('delete_all_first', [False, True])
def test_alignment_with_odd_length_strings(style, frame_id, ns, delete_all_first):
    rng = np.random.default_rng(len(frame_id) * 31 + len(ns))
    for n_strands in (1, 2, 3, 5):
        x = random_strands(rng, n_strands, 3)
        assert_same_message(x, style, frame_id=frame_id, ns=ns, stamp_ns=12_345,
                            colors=rng.random((n_strands, 3)), delete_all_first=delete_all_first)


@pytest.mark.parametrize('style', ['line_list', 'line_strips'])
@pytest.mark.parametrize('n_strands,n_points', [(0, 2), (0, 16), (1, 2), (2, 2), (3, 2),
                                                (9, 16), (64, 7), (33, 32)])
def test_sizes_including_empty(style, n_strands, n_points):
    rng = np.random.default_rng(n_strands * 100 + n_points)
    x = random_strands(rng, n_strands, n_points)
    obj, fast = assert_same_message(x, style, frame_id='map',
                                    colors=rng.random((n_strands, n_points, 4)))
    expected = (1 if style == 'line_list' else n_strands)
    assert len(deserialize_message(fast, MarkerArray).markers) == expected


def test_every_marker_layout_phase():
    """Frame id lengths 1..16 shift each marker by every offset modulo 8 (strip layouts)."""
    rng = np.random.default_rng(3)
    for length in range(1, 17):
        x = random_strands(rng, 6, 3)
        assert_same_message(x, 'line_strips', frame_id='f' * length, ns='n' * (length % 5))


def test_points_and_ids_land_in_place():
    """Decoded fast bytes carry the input points, ids and colours (not just equal templates)."""
    rng = np.random.default_rng(5)
    x = random_strands(rng, 4, 6)
    cols = rng.random((4, 6, 4)).astype(np.float32)
    msg = deserialize_message(
        strands_to_marker_array_cdr(x, frame_id='w', style='line_strips', colors=cols,
                                    first_id=40), MarkerArray)
    for s, m in enumerate(msg.markers):
        assert m.id == 40 + s and m.type == Marker.LINE_STRIP
        got = np.array([[p.x, p.y, p.z] for p in m.points])
        np.testing.assert_array_equal(got, x[s])
        got = np.array([[c.r, c.g, c.b, c.a] for c in m.colors], dtype=np.float32)
        np.testing.assert_array_equal(got, cols[s])


def test_delete_all_first_marker():
    x = random_strands(np.random.default_rng(1), 2, 3)
    msg = deserialize_message(
        strands_to_marker_array_cdr(x, frame_id='odom', ns='h', delete_all_first=True,
                                    stamp_ns=7), MarkerArray)
    assert msg.markers[0] == delete_all_marker('odom', 7, 'h')
    assert [m.action for m in msg.markers] == [Marker.DELETEALL, Marker.ADD]
    only = strands_to_marker_array_cdr(np.empty((0, 2, 3)), frame_id='odom', ns='h',
                                       style='line_strips', delete_all_first=True, stamp_ns=7)
    assert deserialize_message(only, MarkerArray) == MarkerArray(
        markers=[delete_all_marker('odom', 7, 'h')])


def test_write_marker_matches_default_marker():
    """The generic marker writer equals rclpy for a marker with default fields."""
    w = CdrWriter()
    w.uint32(1)
    write_marker(w, stamp=(3, 4), frame_id='fr', ns='n', action=Marker.DELETEALL)
    body = w.template()
    m = Marker(header=Header(frame_id='fr'), ns='n', action=Marker.DELETEALL)
    m.header.stamp.sec, m.header.stamp.nanosec = 3, 4
    _, ref = reference_cdr(MarkerArray(markers=[m]))
    assert ENCAPSULATION_LE + body == ref


def test_copying_fallback_gives_the_same_bytes(monkeypatch):
    """Where CPython's in-place bytes construction is unavailable, the copy path is used."""
    from msg_adapters import cdr
    x = random_strands(np.random.default_rng(9), 5, 4)
    for style in ('line_list', 'line_strips'):
        fast = strands_to_marker_array_cdr(x, frame_id='m', style=style)
        with monkeypatch.context() as m:
            m.setattr(cdr, '_ALLOC', None)
            copied = strands_to_marker_array_cdr(x, frame_id='m', style=style)
        assert type(copied) is bytes and copied == fast


def test_same_validation_as_object_path():
    x = np.zeros((2, 3, 3))
    x[1, 2, 0] = np.nan
    for fn in (strands_to_marker_array, strands_to_marker_array_cdr):
        with pytest.raises(ValueError, match=r'strands\[1, 2, 0\] is nan'):
            fn(x, frame_id='m')
        with pytest.raises(ValueError, match='style'):
            fn(np.zeros((2, 3, 3)), frame_id='m', style='spheres')
        with pytest.raises(ValueError, match='NUL'):
            fn(np.zeros((2, 3, 3)), frame_id='m', ns='a\x00b')


def test_publish_bytes_over_dds():
    """Publisher.publish(bytes) -> a subscriber in the same process gets an equal MarkerArray."""
    rng = np.random.default_rng(11)
    x = random_strands(rng, 300, 16)       # ~350 kB: fragmented by the transport
    big = dict(frame_id='head', ns='hair', style='line_list', colors=rng.random((300, 4)),
               stamp_ns=42_000_000_123, lifetime_ns=300_000_000)
    small = dict(frame_id='h', ns='odd', style='line_strips', colors=rng.random((3, 16, 3)))
    expected = [strands_to_marker_array(x, **big), strands_to_marker_array(x[:3], **small)]
    payloads = [strands_to_marker_array_cdr(x, **big),
                strands_to_marker_array_cdr(x[:3], **small)]
    assert publish_and_receive(MarkerArray, payloads, 71) == expected


def test_the_node_draws_at_most_marker_max_strands_evenly_spread():
    from hair_tracking.output.frame_encoder import FrameEncoder
    from hair_tracking.output.settings import make_settings
    strands = np.random.default_rng(0).normal(size=(10, 5, 3))
    enc = FrameEncoder(make_settings({'marker_max_strands': 4, 'marker_style': 'line_strips'}))
    msg = deserialize_message(bytes(enc.markers(strands, 'world', 7).data), MarkerArray)
    drawn = [m for m in msg.markers if m.action == Marker.ADD]
    assert len(drawn) == 4
    for m, s in zip(drawn, (0, 3, 6, 9)):                    # the first, the last, between
        got = np.array([[p.x, p.y, p.z] for p in m.points])
        np.testing.assert_allclose(got, strands[s], rtol=1e-6, atol=1e-6)
    every = FrameEncoder(make_settings({'marker_max_strands': 0,
                                        'marker_style': 'line_strips'}))
    msg = deserialize_message(bytes(every.markers(strands, 'world', 7).data), MarkerArray)
    assert len([m for m in msg.markers if m.action == Marker.ADD]) == 10
