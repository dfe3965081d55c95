"""hair_sim_bag render: GIF / PNG frames / contact sheet / diagnostics plot from output bags,
from clouds or markers, head or world frame, and its bad inputs."""
import numpy as np
from PIL import Image
import pytest

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import main
from hair_tracking.bags.offline import diagnostics_bytes, pose_stamped_bytes
from hair_tracking.bags.render import load_diagnostics, load_hair, render
from msg_adapters.marker_cdr import strands_to_marker_array_cdr
from msg_adapters.pointcloud import strands_to_pointcloud2_cdr

S, N = 12, 6


def _strands(k, head_x):
    """Strands hanging from a ring around a head at (head_x, 0, 1.6), swinging with k."""
    ang = np.linspace(0, 2 * np.pi, S, endpoint=False)
    x = np.zeros((S, N, 3))
    for i in range(N):
        x[:, i, 0] = 0.1 * np.cos(ang) + 0.01 * i * np.sin(0.3 * k) + head_x
        x[:, i, 1] = 0.1 * np.sin(ang)
        x[:, i, 2] = 1.6 + 0.1 - 0.04 * i
    return x


def _output_bag(path, frames=30, markers=False, diagnostics=True, head=True):
    with bag_io.BagWriter(path) as w:
        hair = '/hair/markers' if markers else '/hair/points'
        w.add_topic(hair, 'visualization_msgs/msg/MarkerArray' if markers
                    else 'sensor_msgs/msg/PointCloud2')
        if head:
            w.add_topic('/head_pose', 'geometry_msgs/msg/PoseStamped')
        if diagnostics:
            w.add_topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')
        for k in range(frames):
            t = 10 ** 9 + k * 33_333_333
            hx = 0.05 * k
            if head:
                w.write('/head_pose', t, pose_stamped_bytes(t, [hx, 0, 1.6], [0, 0, 0, 1],
                                                            'world'))
            x = _strands(k, hx)
            data = (strands_to_marker_array_cdr(x, frame_id='world', stamp_ns=t,
                                                style='line_strips') if markers else
                    strands_to_pointcloud2_cdr(x, frame_id='world', stamp_ns=t))
            w.write(hair, t, data)
            if diagnostics and k % 5 == 0:
                w.write('/diagnostics', t, diagnostics_bytes(
                    t, 0, 'ok', {'max_stretch': f'{0.001 * k}', 'poses_rejected': '0',
                                 'output_frame': 'world'}))


def test_render_gif_png_and_diagnostics(tmp_path, capsys):
    bag = tmp_path / 'out.mcap'
    _output_bag(bag)
    pics = tmp_path / 'pics'
    assert main(['render', str(bag), '-o', str(pics), '--gif', '--png', '--fps', '10']) == 0
    assert 'rendered' in capsys.readouterr().out
    names = sorted(p.name for p in pics.iterdir())
    assert names == ['diagnostics.png', 'frames', 'hair.gif', 'hair.png']
    frames = sorted((pics / 'frames').iterdir())
    gif = Image.open(pics / 'hair.gif')
    # 30 frames 1/30 s apart, thinned to 10 per second of recording; the GIF shows them at
    # 100 ms each (Pillow merges pictures that came out pixel-identical, adding their times)
    assert len(frames) == 10
    total_ms = 0
    for k in range(gif.n_frames):
        gif.seek(k)
        total_ms += gif.info['duration']
    assert 2 <= gif.n_frames <= 10 and total_ms == 1000
    first = np.asarray(Image.open(frames[0]).convert('RGB')).astype(int)
    last = np.asarray(Image.open(frames[-1]).convert('RGB')).astype(int)
    assert first.shape == last.shape and first.std() > 5       # something is drawn
    assert np.abs(first - last).sum() > 0                      # ... and it moves
    assert Image.open(pics / 'diagnostics.png').size[0] > 500
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.')]


def test_hair_in_head_frame_follows_head_pose(tmp_path):
    bag = tmp_path / 'out.mcap'
    _output_bag(bag, frames=8)
    topic, frames = load_hair(bag)
    assert topic == '/hair/points' and len(frames) == 8
    t, fid, segs, strands = frames[-1]
    np.testing.assert_allclose(strands, _strands(7, 0.35), atol=1e-6)   # float32 cloud
    assert segs.shape == (S * (N - 1), 2, 3)
    series, name = load_diagnostics(bag)
    assert name == 'hair_sim: hair simulation'
    assert [v for _, v in series['max_stretch']] == pytest.approx([0.0, 0.005])
    assert 'output_frame' not in series                         # not a number


def test_render_from_markers_without_head_pose(tmp_path, capsys):
    bag = tmp_path / 'markers.mcap'
    _output_bag(bag, frames=6, markers=True, diagnostics=False, head=False)
    topic, frames = load_hair(bag)
    assert topic == '/hair/markers'
    assert frames[0][2].shape == (S * (N - 1), 2, 3)          # LINE_STRIP segments
    out = render(bag, tmp_path / 'p', fps=100, max_frames=4)
    assert out['frames'] == 4
    assert any('world frame' in n for n in out['notes'])
    assert any('diagnostics' in n for n in out['notes'])
    assert Image.open(tmp_path / 'p' / 'hair.gif').n_frames == 4


def test_render_bad_inputs(tmp_path, capsys):
    poses = tmp_path / 'poses.mcap'
    bag_io.write_head_pose_bag(poses, [10 ** 9, 2 * 10 ** 9], np.zeros((2, 3)),
                               [[0, 0, 0, 1.0]] * 2)
    assert main(['render', str(poses), '-o', str(tmp_path / 'a')]) == 4
    err = capsys.readouterr().err
    assert 'no hair topic' in err and '/head_pose' in err
    assert main(['render', str(tmp_path / 'nope.mcap'), '-o', str(tmp_path / 'b')]) == 3
    good = tmp_path / 'good.mcap'
    _output_bag(good, frames=3)
    (tmp_path / 'c').mkdir()
    assert main(['render', str(good), '-o', str(tmp_path / 'c')]) == 5
    assert main(['render', str(good), '-o', str(tmp_path / 'd'), '--fps', '0']) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ['c', 'good.mcap', 'poses.mcap']


def test_head_outline_comes_from_the_head_marker(tmp_path):
    """The node's /hair/head marker (the collider) sizes the head outline; without it the
    default scene's collider is drawn."""
    from rclpy.serialization import serialize_message
    from msg_adapters.head_marker import collider_marker
    bag = tmp_path / 'out.mcap'
    _output_bag(bag, frames=6, diagnostics=False)
    plain = render(bag, tmp_path / 'plain', gif=False)
    assert plain['head_radii'] == (0.095, 0.08, 0.105)
    with_head = tmp_path / 'head.mcap'
    with bag_io.BagWriter(with_head) as w:
        w.add_topic('/hair/head', 'visualization_msgs/msg/Marker')
        w.add_topic('/hair/points', 'sensor_msgs/msg/PointCloud2')
        w.add_topic('/head_pose', 'geometry_msgs/msg/PoseStamped')
        for k in range(6):
            t = 10 ** 9 + k * 33_333_333
            w.write('/head_pose', t, pose_stamped_bytes(t, [0, 0, 1.6], [0, 0, 0, 1], 'world'))
            w.write('/hair/head', t, bytes(serialize_message(collider_marker(
                'ellipsoid', (0, 0, 0), 0.1, (0.11, 0.09, 0.12), frame_id='world', stamp_ns=t,
                color=(1, 1, 1, 1), head_position=(0, 0, 1.6), head_quaternion=(0, 0, 0, 1)))))
            w.write('/hair/points', t, strands_to_pointcloud2_cdr(_strands(k, 0.0),
                                                                  frame_id='world', stamp_ns=t))
    got = render(with_head, tmp_path / 'head', gif=False)
    np.testing.assert_allclose(got['head_radii'], (0.11, 0.09, 0.12))


def test_thinning_looks_only_at_grid_points_next_to_frames():
    """A message logged at time 0 in a recording at 1e9 s (a recorder without a clock yet)
    is a gap, not a billion seconds of grid points; thinning picks what the whole grid
    would."""
    from hair_tracking.bags.render import _thin
    rng = np.random.default_rng(4)
    for _ in range(50):
        logs = np.sort(rng.integers(0, 3 * 10 ** 9, size=rng.integers(2, 40)))
        step = 1e9 / 10.0
        grid = logs[0] + np.arange(int((logs[-1] - logs[0]) / step) + 1) * step
        right = np.clip(np.searchsorted(logs, grid), 1, len(logs) - 1)
        whole = np.where(grid - logs[right - 1] <= logs[right] - grid, right - 1, right)
        assert _thin(logs, None, 10.0) == set(int(i) for i in whole)
    late = 10 ** 18 + np.arange(60, dtype=np.int64) * 33_333_333
    logs = np.concatenate([[0, 0], late])
    keep = _thin(logs, 120, 10.0)
    assert 0 in keep and 1 not in keep and len(keep) == 1 + 20   # 0, 0.1 .. 1.9 s on


def test_render_of_a_bag_with_a_message_at_time_zero(tmp_path, capsys):
    bag = tmp_path / 'gap.mcap'
    with bag_io.BagWriter(bag) as w:
        w.add_topic('/hair/points', 'sensor_msgs/msg/PointCloud2')
        for k, t in enumerate([0] + [10 ** 18 + k * 33_333_333 for k in range(20)]):
            w.write('/hair/points', t,
                    strands_to_pointcloud2_cdr(_strands(k, 0.0), frame_id='world', stamp_ns=t))
    assert main(['render', str(bag), '-o', str(tmp_path / 'pics'), '--fps', '10']) == 0
    assert 'rendered 8 pictures' in capsys.readouterr().out
    (tmp_path / 'plain').mkdir()                        # the folder has the usual mode
    assert (tmp_path / 'pics').stat().st_mode == (tmp_path / 'plain').stat().st_mode
