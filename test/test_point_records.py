"""Strand positions written as float32 records (hair_tracking.core.point_records) and the
simulator's record writer, which reads the ghosts straight from the tracker's layout."""
import numpy as np
import pytest

from hair_tracking.core.point_records import blocks_to_records, points_to_records
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_from_axis_angle
from hair_tracking.simulator import HairSimulator

MS = 1_000_000
SENTINEL = np.uint32(0xA5A5A5A5)


def moved_sim(**kw):
    """A small simulator (head contact on, the paper's tracker and its block layout) driven
    through a turning, moving head."""
    settings = dict(groom__guides=7, groom__ghosts_per_guide=5, groom__guide_nodes=8,
                    groom__ghost_nodes=9, solver__settle_time=0.05, tracking__mode='paper')
    scene = Scene().with_changes(**{**settings, **kw})
    sim = HairSimulator(scene)
    for i in range(12):
        s = 0.02 * i
        sim.push_pose(i * 10 * MS, [0.3 * s, 0.05 * np.sin(9 * s), 1.5],
                      quat_from_axis_angle([0.2, 1.0, 0.1], 1.5 * s))
        sim.advance_to(i * 10 * MS)
    return sim


def records(n_points, stride):
    """A float32 record array whose words all hold the sentinel bit pattern."""
    return np.full(n_points * stride, SENTINEL, dtype=np.uint32).view(np.float32)


def written(words, stride, shape):
    """(x y z as (S, N, 3) float32, the other words as uint32)."""
    rec = words.reshape(shape[0], shape[1], stride)
    return rec[..., :3], rec[..., 3:].view(np.uint32)


@pytest.mark.parametrize('stride', [3, 5, 8])
def test_points_to_records_writes_float32_xyz_and_leaves_the_other_words(stride):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(6, 4, 3))
    words = records(24, stride)
    assert points_to_records(words, stride, x) is True
    xyz, rest = written(words, stride, x.shape)
    np.testing.assert_array_equal(xyz, x.astype(np.float32))
    assert np.all(rest == SENTINEL)


def test_points_to_records_transforms_as_to_head_and_reports_non_finite():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(5, 3, 3))
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    origin = np.array([0.5, -0.25, 2.0])
    words = records(15, 5)
    assert points_to_records(words, 5, x, rot, origin) is True
    expected = (x - origin) @ rot.T
    np.testing.assert_allclose(written(words, 5, x.shape)[0], expected, rtol=1e-6, atol=1e-7)
    for bad in (np.nan, np.inf, 1e39):          # 1e39 is finite in float64, inf in float32
        y = x.copy()
        y[3, 1, 2] = bad
        assert points_to_records(records(15, 5), 5, y) is False


def test_points_to_records_rejects_wrong_buffers():
    x = np.zeros((2, 3, 3))
    with pytest.raises(ValueError, match='records of stride'):
        points_to_records(np.zeros(29, np.float32), 5, x)
    with pytest.raises(ValueError, match='stride >= 3'):
        points_to_records(np.zeros(12, np.float32), 2, x)
    with pytest.raises(TypeError, match='float32'):
        points_to_records(np.zeros(30, np.float64), 5, x)
    with pytest.raises(ValueError, match=r'\(S, N, 3\)'):
        points_to_records(np.zeros(30, np.float32), 5, np.zeros((2, 3, 2)))
    with pytest.raises(ValueError, match='origin'):
        points_to_records(np.zeros(30, np.float32), 5, x, np.eye(3), np.zeros(2))


@pytest.mark.parametrize('head_frame', [False, True])
def test_simulator_writes_the_ghosts_from_the_tracker_layout_as_a_frame_shows_them(head_frame):
    sim = moved_sim()
    tracker = sim.ghost_tracker
    assert tracker is not None
    # the guides' writer does not make the tracker write the ghosts back
    g_writer = sim.record_writer(guides=True, head_frame=head_frame)
    assert g_writer[2](records(g_writer[0] * g_writer[1], 4), 4) is True
    assert not tracker._synced_x
    n_strands, n_points, write = sim.record_writer(head_frame=head_frame)
    assert (n_strands, n_points) == (35, 9)
    words = records(n_strands * n_points, 5)
    assert write(words, 5) is True
    frame = sim.frame(head_frame=head_frame)
    xyz, rest = written(words, 5, (n_strands, n_points))
    if head_frame:      # R^T (x - p) in the kernel, (x - p) @ R in numpy: rounding apart
        np.testing.assert_allclose(xyz, frame.strands, rtol=1e-6, atol=1e-7)
    else:
        np.testing.assert_array_equal(xyz, frame.strands.astype(np.float32))
    assert np.all(rest == SENTINEL)
    # the guides (and the same numbers again once the positions were written out for a read)
    g_strands, g_points, write_g = sim.record_writer(guides=True, head_frame=head_frame)
    g_words = records(g_strands * g_points, 4)
    assert write_g(g_words, 4) is True
    np.testing.assert_allclose(written(g_words, 4, (g_strands, g_points))[0], frame.guides,
                               rtol=1e-6, atol=1e-7)
    tracker.positions()
    assert tracker._synced_x
    again = records(n_strands * n_points, 5)
    assert sim.record_writer(head_frame=head_frame)[2](again, 5) is True
    np.testing.assert_array_equal(again, words)


def test_blocks_to_records_matches_the_write_back_for_every_block_layout():
    sim = moved_sim(groom__ghosts_per_guide=37)            # blocks of several groups
    tr = sim.ghost_tracker
    s, n = sim.ghosts.rest.shape[:2]
    words = records(s * n, 6)
    assert blocks_to_records(words, 6, tr._xb, tr.order, tr._block_rows, n) is True
    np.testing.assert_array_equal(written(words, 6, (s, n))[0],
                                  tr.positions().astype(np.float32))
    xb = tr._xb.copy()
    xb[17] = np.nan
    assert blocks_to_records(records(s * n, 6), 6, xb, tr.order, tr._block_rows, n) is False
    with pytest.raises(ValueError, match='xb must hold'):
        blocks_to_records(words, 6, xb[:-3], tr.order, tr._block_rows, n)


def test_curves_output_is_written_from_the_frame():
    sim = moved_sim(output__curve='catmull_rom', output__points_per_strand=12)
    n_strands, n_points, write = sim.record_writer()
    assert (n_strands, n_points) == (35, 12)
    words = records(n_strands * n_points, 5)
    assert write(words, 5) is True
    np.testing.assert_array_equal(written(words, 5, (n_strands, n_points))[0],
                                  sim.frame().strands.astype(np.float32))


@pytest.mark.parametrize('guides', [False, True])
def test_a_cloud_sends_at_most_cloud_max_strands_evenly_spread_with_their_ids(guides):
    """``cloud_max_strands``: the cloud carries that many strands, the first, the last and
    evenly between, each with its position now, its strand id and its colour in the cloud of
    all; 0 sends every strand."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import PointCloud2

    from msg_adapters.pointcloud import pointcloud2_to_strands
    from hair_tracking.output.frame_encoder import FrameEncoder
    from hair_tracking.output.settings import make_settings
    sim = moved_sim()
    key = 'guide_points' if guides else 'points'
    strands = sim.frame().guides if guides else sim.frame().strands
    clouds = {}
    for most in (0, 4):
        enc = FrameEncoder(make_settings({'cloud_max_strands': most}))
        data = enc.frame(sim, [key], 'world', 5)[key].data
        msg = deserialize_message(bytes(data), PointCloud2)
        pts, ids = pointcloud2_to_strands(msg)
        rgb = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(-1, msg.point_step)[
            :, 16:20].copy().view('<u4').reshape(len(ids), -1)[:, 0]
        clouds[most] = (pts, ids, rgb)
    pts, ids, rgb = clouds[0]
    assert ids.tolist() == list(range(len(strands)))
    np.testing.assert_array_equal(pts, strands.astype(np.float32))
    sub_pts, sub_ids, sub_rgb = clouds[4]
    want = np.linspace(0, len(strands) - 1, 4).round().astype(int)
    assert sub_ids.tolist() == want.tolist() and want[0] == 0 and want[-1] == len(strands) - 1
    np.testing.assert_array_equal(sub_pts, pts[want])
    np.testing.assert_array_equal(sub_rgb, rgb[want])
