"""hair_sim_view: the strands and the head drawn from the node's topics, looked at in a real
headless Chromium.

A real ``hair_sim_node`` (domain 78, with the body's bust) gets a still head pose; viewers
serve pages from it: one on the node's topics, one whose cloud topic nobody publishes (the
control), and, without the head, one with the bust's colliders and one without (its
control).  The page of the first must show many pixels of the cloud's own hair colours, the
control's none, though both show the head (coloured blue by the node's ``head_color`` here,
so that it is told apart from the hair, as the bust is).  Needs viser, Playwright for Python
and Debian's chromium (``make install``); the browser tests are skipped without them.  Every
wait is bounded.
"""
import io
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from hair_tracking.ros import view_geometry
from msg_adapters.pointcloud import strands_to_pointcloud2

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 78
HEAD_COLOR = (0.1, 0.3, 0.9)            # blue: nothing like hair
CHROMIUM = shutil.which('chromium') or shutil.which('chromium-browser')
HAIR_PIXELS_MIN = 2000                  # the default scene fills about 50 000 at 800 x 600
HEAD_PIXELS_MIN = 2000
WAIT_S = 90.0


def _env():
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    return dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED='1', PYTHONPATH=path)


def _missing():
    try:
        import playwright.sync_api  # noqa: F401
        import viser  # noqa: F401
    except ImportError as e:
        return f'{e.name} not installed (make install)'
    return None if CHROMIUM else 'chromium not installed (make install)'


needs_browser = pytest.mark.skipif(_missing() is not None, reason=str(_missing()))


# ==================================================================== messages -> geometry
def test_cloud_segments_join_each_strands_points_in_its_colour():
    x = np.zeros((3, 4, 3))
    x[..., 2] = np.arange(4) * 0.1
    x[:, :, 0] = np.arange(3)[:, None]
    x[1, 2] = np.nan                           # strand 1 loses the two segments at point 2
    packed = np.array([0x102030, 0x405060, 0x708090], dtype=np.uint32)
    msg = strands_to_pointcloud2(x, frame_id='world', packed_rgb=packed)
    seg, col = view_geometry.cloud_segments(msg)
    assert seg.shape == (3 * 3 - 2, 2, 3) and seg.dtype == np.float32
    np.testing.assert_allclose(seg[0], [[0, 0, 0], [0, 0, 0.1]], atol=1e-7)
    np.testing.assert_array_equal(col[0], [[0x10, 0x20, 0x30]] * 2)
    np.testing.assert_array_equal(col[-1], [[0x70, 0x80, 0x90]] * 2)
    assert np.isfinite(seg).all()
    seg, col = view_geometry.cloud_segments(msg, max_strands=2)       # every 2nd strand: 0 and 2
    assert seg.shape[0] == 6 and set(seg[:, 0, 0]) == {0.0, 2.0}
    no_rgb = strands_to_pointcloud2(x[:, :1], frame_id='world')
    assert view_geometry.cloud_segments(no_rgb)[0].shape == (0, 2, 3)
    assert view_geometry.cloud_colors(no_rgb) is None
    assert view_geometry.strand_stride(10, 0) == 1 and view_geometry.strand_stride(10, 3) == 4


def test_cloud_colors_read_the_rgb_field_by_its_offset():
    step = 24                                   # padding, rgb before xyz: read by name
    fields = [PointField(name='rgb', offset=4, datatype=PointField.UINT32, count=1)] + \
        [PointField(name=n, offset=8 + 4 * i, datatype=PointField.FLOAT32, count=1)
         for i, n in enumerate('xyz')]
    rec = np.zeros((2, 3), dtype=np.dtype({'names': ['rgb', 'x'], 'formats': ['<u4', '<f4'],
                                           'offsets': [4, 8], 'itemsize': step}))
    rec['rgb'] = [[0xFF0000, 0x00FF00, 0x0000FF], [1, 2, 3]]
    msg = PointCloud2(header=Header(frame_id='w'), height=2, width=3, fields=fields,
                      point_step=step, row_step=3 * step, data=rec.tobytes())
    c = view_geometry.cloud_colors(msg)
    np.testing.assert_array_equal(c[0], [[255, 0, 0], [0, 255, 0], [0, 0, 255]])
    np.testing.assert_array_equal(c[1, :, 2], [1, 2, 3])


def test_srgb_colours_are_linearised_for_the_vertex_colours():
    lin = view_geometry.srgb_to_linear_u8(np.array([0, 38, 77, 115, 128, 255], dtype=np.uint8))
    assert lin.tolist() == [0, 5, 19, 44, 55, 255]


def test_head_shape_of_the_nodes_marker():
    from msg_adapters.head_marker import collider_marker
    m = collider_marker('ellipsoid', (0.0, 0.0, 0.02), 0.1, (0.09, 0.075, 0.11),
                        frame_id='world', stamp_ns=0, color=(0.85, 0.7, 0.6, 0.5),
                        head_position=(1.0, 2.0, 1.5), head_quaternion=(0.0, 0.0, 0.0, 1.0))
    s = view_geometry.head_shape(m)
    np.testing.assert_allclose(s.position, (1.0, 2.0, 1.52))
    np.testing.assert_allclose(s.semi_axes, (0.09, 0.075, 0.11))
    assert s.wxyz == (1.0, 0.0, 0.0, 0.0) and s.rgb == (217, 178, 153)
    assert view_geometry.head_shape(collider_marker('none', (0, 0, 0), 0.1, (0.1,) * 3,
                                                    frame_id='w', stamp_ns=0,
                                                    color=(1,) * 4)) is None
    assert view_geometry.head_shape(Marker(type=Marker.CUBE)) is None
    look_at, eye = view_geometry.framing(np.zeros((0, 2, 3)), s)
    np.testing.assert_allclose(look_at, s.position)
    assert (eye - look_at)[0] > 0 and (eye - look_at)[2] > 0


def test_collider_solids_of_the_nodes_capsules():
    from msg_adapters.capsule_markers import capsule_markers
    q = (0.0, np.sin(0.25), 0.0, np.cos(0.25))             # x y z w: 0.5 rad about y
    markers = capsule_markers([(0.1, 0.2, 1.3)], [q], [0.05], [0.12], frame_id='world',
                              stamp_ns=0, color=(0.1, 0.3, 0.9, 1.0))
    solids = view_geometry.collider_solids(MarkerArray(
        markers=markers + [Marker(type=Marker.CUBE), Marker(action=Marker.DELETEALL)]))
    assert [s.kind for s in solids] == ['cylinder', 'sphere', 'sphere']
    cyl, end0, end1 = solids
    np.testing.assert_allclose(cyl.position, (0.1, 0.2, 1.3))
    np.testing.assert_allclose(cyl.size, (0.05, 0.05, 0.24))
    np.testing.assert_allclose(cyl.wxyz, (q[3], q[0], q[1], q[2]))
    axis = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    np.testing.assert_allclose(end0.position, np.array(cyl.position) - 0.12 * axis, atol=1e-12)
    np.testing.assert_allclose(end1.position, np.array(cyl.position) + 0.12 * axis, atol=1e-12)
    np.testing.assert_allclose(end0.size, (0.05,) * 3)
    assert cyl.rgb == (26, 76, 230)
    latest = view_geometry.Latest()
    latest.add_colliders(MarkerArray(markers=markers))
    assert latest and latest.take_colliders().markers == markers
    assert not latest and latest.take_colliders() is None


def test_latest_pairs_the_cloud_with_the_head_of_its_stamp():
    latest = view_geometry.Latest()
    assert not latest and latest.take() == (None, None)

    def stamped(msg, ns):
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 10 ** 9)
        return msg
    for t in (1, 2, 3):
        latest.add_head(stamped(Marker(id=t), t))
    latest.add_cloud(stamped(PointCloud2(), 2))
    head, cloud = latest.take()
    assert head.id == 2 and cloud.header.stamp.nanosec == 2
    assert latest and latest.take() == (latest._heads[-1], None)     # then the newer head
    assert not latest and latest.take() == (None, None)
    latest.add_cloud(stamped(PointCloud2(), 9))           # its head has not come
    head, cloud = latest.take()
    assert head is None and cloud.header.stamp.nanosec == 9    # the head drawn stays
    latest.add_head(stamped(Marker(id=4), 4))
    assert latest.take()[0].id == 4 and not latest


# ==================================================================== the executable
def test_help_names_the_address_and_that_it_only_subscribes():
    out = subprocess.run([sys.executable, '-m', 'hair_tracking.ros.view', '--help'], cwd=ROOT,
                         env=_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    text = ' '.join(out.stdout.split())
    assert '127.0.0.1' in text and 'changes nothing in the node' in text
    for option in ('--host', '--port', '--points-topic', '--head-topic', '--rate',
                   '--max-strands'):
        assert option in text


def test_without_viser_it_says_how_to_install_it():
    code = ('import sys; sys.modules["viser"] = None\n'
            'from hair_tracking.ros.view import main\n'
            'sys.exit(main(["hair_sim_view"]))')
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, env=_env(),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and 'pip install viser' in out.stderr, out.stderr


def test_bad_options_exit_2():
    out = subprocess.run([sys.executable, '-m', 'hair_tracking.ros.view', '--rate', '0'],
                         cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and '--rate' in out.stderr


def test_the_node_and_the_simulation_do_not_import_viser():
    code = ('import sys, hair_tracking.ros.node, hair_tracking.simulator, '
            'hair_tracking.ros.view; print("viser" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, env=_env(),
                         capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == 'False', out.stderr


# ==================================================================== in a browser
class Proc:
    """A child process whose output lines are read by a thread (waits never block)."""

    def __init__(self, args):
        self.proc = subprocess.Popen([sys.executable, *args], cwd=ROOT, env=_env(),
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True)
        self.lines, self.seen = queue.Queue(), []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def wait_for(self, text, timeout=WAIT_S):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                break
            if line is None:
                break
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f'no {text!r} within {timeout:g} s:\n{"".join(self.seen)}')

    def stop(self, timeout=30):
        """SIGINT (Ctrl-C); -> exit status and everything printed."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=10)
        while True:
            try:
                line = self.lines.get(timeout=5)
            except queue.Empty:
                break
            if line is None:
                break
            self.seen.append(line)
        return self.proc.returncode, ''.join(self.seen)


def _free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def _start_view(*args):
    p = Proc(['-m', 'hair_tracking.ros.view', '--port', str(_free_port()), '--rate', '10',
              *args])
    line = p.wait_for('serving http://')
    return p, line.split('serving ')[1].split()[0]


def _feed_a_pose_until_a_cloud():
    """A still head at (0, 0, 1.6) in world, sent until the node publishes hair (the node then
    holds the pose); -> the cloud's distinct colours (K, 3) uint8."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    try:
        node = rclpy.create_node('view_test_feeder', context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        got = []
        node.create_subscription(PointCloud2, 'hair/points', got.append, 2)
        pub = node.create_publisher(PoseStamped, 'head_pose', 10)
        deadline = time.monotonic() + WAIT_S
        while not got and time.monotonic() < deadline:
            msg = PoseStamped()
            msg.header.frame_id = 'world'
            msg.pose.position.z = 1.6
            msg.pose.orientation.w = 1.0
            pub.publish(msg)
            ex.spin_once(timeout_sec=0.1)
        assert got, 'no cloud from the node'
        ex.shutdown(timeout_sec=1.0)
        node.destroy_node()
        return np.unique(view_geometry.cloud_colors(got[-1]).reshape(-1, 3), axis=0)
    finally:
        rclpy.try_shutdown(context=ctx)


@pytest.fixture(scope='module')
def hair_colors():
    """A running hair_sim node (blue head and bust) with a pose; -> the colours of its
    strands."""
    if _missing():
        pytest.skip(_missing())
    node = Proc(['-m', 'hair_tracking.ros.node', '--ros-args', '-p',
                 f'head_color:=[{HEAD_COLOR[0]}, {HEAD_COLOR[1]}, {HEAD_COLOR[2]}, 1.0]',
                 '-p', 'body.bust:=true'])
    try:
        node.wait_for('ready:', timeout=300)      # minutes only with an empty numba cache
        yield _feed_a_pose_until_a_cloud()
    finally:
        node.stop()


@pytest.fixture(scope='module')
def browser():
    if _missing():
        pytest.skip(_missing())
    from playwright.sync_api import sync_playwright
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                              args=['--use-angle=swiftshader', '--enable-unsafe-swiftshader',
                                    '--ignore-gpu-blocklist'])
        yield b
        b.close()


def _pixels(png, hair_colors):
    """(pixels within 40 of a colour of the hair, pixels of the blue head) of a screenshot."""
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(png)).convert('RGB'), dtype=np.float32)
    colors = hair_colors.astype(np.float32)
    if len(colors) > 32:               # shades of one colour: 32 of them span it
        order = np.argsort(colors.sum(axis=1))
        colors = colors[order[np.linspace(0, len(order) - 1, 32).astype(int)]]
    near = np.zeros(img.shape[:2], dtype=bool)
    for c in colors:
        near |= np.linalg.norm(img - c, axis=-1) < 40
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    head = (b > r + 60) & (b > g + 30)
    return int(near.sum()), int(head.sum())


def _shoot_until(browser, url, hair_colors, done):
    """Screenshots of the page until ``done(hair, head)`` or the deadline; -> the last
    (png, hair pixels, head pixels)."""
    page = browser.new_page(viewport={'width': 800, 'height': 600})
    try:
        page.goto(url, timeout=WAIT_S * 1000)
        deadline = time.monotonic() + WAIT_S
        while True:
            png = page.screenshot()
            hair, head = _pixels(png, hair_colors)
            if done(hair, head) or time.monotonic() > deadline:
                return png, hair, head
            time.sleep(0.5)
    finally:
        page.close()


@needs_browser
def test_the_page_draws_the_live_strands_and_the_head(hair_colors, browser, tmp_path):
    live, url = _start_view()
    try:
        png, hair, head = _shoot_until(
            browser, url, hair_colors,
            lambda hair, head: hair >= HAIR_PIXELS_MIN and head >= HEAD_PIXELS_MIN)
        (tmp_path / 'live_view.png').write_bytes(png)
        assert hair >= HAIR_PIXELS_MIN and head >= HEAD_PIXELS_MIN, \
            (hair, head, str(tmp_path / 'live_view.png'))
    finally:
        code, out = live.stop()
    assert code == 0 and 'Traceback' not in out, out
    assert 'drawing 512 strands x 16 points' in out, out


@needs_browser
def test_a_page_without_hair_has_no_hair_coloured_pixels(hair_colors, browser, tmp_path):
    """The control: the same page from a cloud topic nobody publishes shows the head and not
    one strand, so the pixel count above measures the strands."""
    control, url = _start_view('--points-topic', '/hair_sim_view_test/nobody')
    try:
        png, hair, head = _shoot_until(browser, url, hair_colors,
                                       lambda hair, head: head >= HEAD_PIXELS_MIN)
        (tmp_path / 'control.png').write_bytes(png)
        assert head >= HEAD_PIXELS_MIN, (head, str(tmp_path / 'control.png'))
        assert hair < 50, (hair, str(tmp_path / 'control.png'))
    finally:
        code, out = control.stop()
    assert code == 0 and 'Traceback' not in out, out


@needs_browser
def test_the_page_draws_the_bust(hair_colors, browser, tmp_path):
    """The node's bust (hair/colliders, blue as the head) without the head: drawn; the same
    page without the colliders' topic (the control) has no more blue than the view's axes
    (about 100 pixels)."""
    for topic, drawn in (('hair/colliders', True), ('', False)):
        live, url = _start_view('--head-topic', '', '--colliders-topic', topic)
        try:
            png, hair, blue = _shoot_until(
                browser, url, hair_colors,
                lambda hair, blue: hair >= HAIR_PIXELS_MIN and (blue >= HEAD_PIXELS_MIN
                                                                or not drawn))
            (tmp_path / f'bust_{drawn}.png').write_bytes(png)
            if drawn:
                assert blue >= HEAD_PIXELS_MIN, (blue, str(tmp_path / 'bust_True.png'))
            else:
                assert blue < HEAD_PIXELS_MIN / 4, (blue, str(tmp_path / 'bust_False.png'))
        finally:
            code, out = live.stop()
        assert code == 0 and 'Traceback' not in out, out
