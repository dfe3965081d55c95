"""The ROS user's path: ``colcon build`` of hair_tracking and its message package
hair_tracking_msgs (``interfaces/``, a second base path: colcon does not look for packages inside
a package) into a fresh workspace, source it, serialize a GuideState with the built message
package, run the installed ``hair_sim_node`` with ``scene_file:=long_hair`` (found through the
ament index, since the installed package has no source tree beside it) and receive a cloud over
DDS.

Needs colcon (``make install`` puts colcon-core, colcon-ros and colcon-python-setup-py in the
venv; skipped where no colcon is found).  In the pip-only venv the build is given what a ROS
installation's environment has (the venv on ``AMENT_PREFIX_PATH``) and the wheels' CMake
fix-ups (``interfaces/cmake/wheel_prefix.cmake``), as docs/ros.md says.  The installed copy
compiles its numba kernels afresh (numba's cache is keyed by the source files' paths): about
35 s in all on two cores, so the waits are generous.  Domain id 76.
"""
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 76
COLCON = shutil.which('colcon', path=os.path.dirname(sys.executable)) or shutil.which('colcon')
IGNORED = ('.git', '.venv', 'build', 'install', 'log', 'out', '__pycache__', '.pytest_cache',
           '*.egg-info', '.bench', '.numba_cache')

pytestmark = pytest.mark.skipif(COLCON is None, reason='colcon not installed (make install)')


def _child_env(**extra):
    """The environment without this test's PYTHONPATH (the source tree must not be imported)."""
    env = {k: v for k, v in os.environ.items() if k not in ('PYTHONPATH', 'NUMBA_CACHE_DIR')}
    env['PATH'] = os.path.dirname(sys.executable) + os.pathsep + env.get('PATH', '')
    env.update(extra)
    return env


def _sourced_env(ws):
    """The environment after ``. install/local_setup.sh`` (as a ROS user's shell has it)."""
    out = subprocess.run(['sh', '-c', f'. "{ws}/install/local_setup.sh" && env -0'],
                         env=_child_env(), capture_output=True, timeout=60, check=True)
    pairs = (item.split('=', 1) for item in out.stdout.decode().split('\0') if '=' in item)
    return dict(pairs)


def test_colcon_build_install_and_run_long_hair(tmp_path):
    ws = tmp_path / 'ws'
    shutil.copytree(ROOT, ws / 'src' / 'hair_tracking',
                    ignore=shutil.ignore_patterns(*IGNORED), symlinks=True)
    src = ws / 'src' / 'hair_tracking'
    prefixes = os.pathsep.join(filter(None, [os.environ.get('AMENT_PREFIX_PATH'), sys.prefix]))
    build = subprocess.run(
        [COLCON, 'build', '--base-paths', 'src', 'src/hair_tracking/interfaces',
         '--packages-up-to', 'hair_tracking', '--cmake-args',
         f'-DCMAKE_PROJECT_INCLUDE={src}/interfaces/cmake/wheel_prefix.cmake'],
        cwd=ws, env=_child_env(AMENT_PREFIX_PATH=prefixes), capture_output=True, text=True,
        timeout=900)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    assert 'Finished <<< hair_tracking_msgs' in build.stdout, build.stdout[-3000:]
    share = ws / 'install' / 'hair_tracking' / 'share' / 'hair_tracking'
    for rel in ('package.xml', 'config/hair_sim.yaml', 'config/scene_long_hair.yaml',
                'launch/hair_sim.launch.py', 'rviz/hair_sim.rviz',
                'launch/hair_sim_shards.launch.py', 'rviz/hair_sim_shards.rviz'):
        assert (share / rel).is_file(), rel
    assert (ws / 'install' / 'hair_tracking' / 'lib' / 'hair_tracking' /
            'hair_sim_ghosts').is_file()
    assert not (ws / 'install' / 'tf2_msgs').exists()      # a ROS installation has them
    assert not (ws / 'install' / 'hri_msgs').exists()

    env = _sourced_env(ws)
    _expect_guide_state_package(ws, env)
    env.update(ROS_DOMAIN_ID=str(DOMAIN), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               PYTHONUNBUFFERED='1')
    # what `ros2 run hair_tracking hair_sim_node` runs: <prefix>/lib/<package>/<executable>,
    # the prefix from the ament index of the sourced environment
    prefix = subprocess.run(
        [sys.executable, '-c', 'from ament_index_python.packages import get_package_prefix;'
                               'print(get_package_prefix("hair_tracking"))'],
        env=env, capture_output=True, text=True, timeout=60, check=True).stdout.strip()
    assert prefix == str(ws / 'install' / 'hair_tracking')
    exe = os.path.join(prefix, 'lib', 'hair_tracking', 'hair_sim_node')
    log = open(tmp_path / 'node.log', 'w+')
    node = subprocess.Popen([exe, '--ros-args', '-p', 'scene_file:=long_hair',
                             '-p', 'warmup:=false', '-p', 'numba_threads:=1'],
                            cwd=tmp_path, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        _expect_cloud(node, log, guides=96, ghosts_per_guide=24)
    finally:
        if node.poll() is None:
            node.send_signal(signal.SIGINT)
            try:
                node.wait(timeout=30)
            except subprocess.TimeoutExpired:
                node.kill()
                node.wait()
        log.close()
    text = (tmp_path / 'node.log').read_text()
    assert node.returncode == 0, text[-3000:]


def _expect_guide_state_package(ws, env):
    """The workspace's hair_tracking_msgs: found first, its type support serializes."""
    code = ('import hair_tracking_msgs\n'
            'from ament_index_python.packages import get_package_prefix\n'
            'from hair_tracking_msgs.msg import GuideState\n'
            'from rclpy.serialization import deserialize_message, serialize_message\n'
            'm = GuideState(guides=1, nodes=1, positions=[0.5, 1.5, 2.5])\n'
            'print(get_package_prefix("hair_tracking_msgs"), hair_tracking_msgs.__file__,\n'
            '      deserialize_message(serialize_message(m), GuideState) == m)\n')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-3000:]
    prefix, module, same = out.stdout.split()
    install = ws / 'install' / 'hair_tracking_msgs'
    assert prefix == str(install) and module.startswith(str(install) + os.sep), out.stdout
    assert same == 'True'


def _expect_cloud(node, log, guides, ghosts_per_guide):
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import PointCloud2

    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    probe = rclpy.create_node('colcon_probe', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(probe)
    clouds = []
    probe.create_subscription(PointCloud2, 'hair/points', clouds.append, 5)
    pub = probe.create_publisher(PoseStamped, 'head_pose', 10)

    def node_output():
        log.flush()
        log.seek(0)
        return log.read()[-3000:]
    try:
        # compiling the kernels in the installed copy: generous, bounded waits
        deadline = time.monotonic() + 900
        k = 0
        while not clouds:
            assert time.monotonic() < deadline, 'no cloud in 900 s:\n' + node_output()
            assert node.poll() is None, 'the node exited:\n' + node_output()
            if pub.get_subscription_count() > 0:
                msg = PoseStamped()
                msg.header.frame_id = 'world'
                k += 1
                msg.header.stamp.sec, msg.header.stamp.nanosec = 100, k * 10_000_000
                msg.pose.orientation.w = 1.0
                pub.publish(msg)
            ex.spin_once(timeout_sec=0.2)
        cloud = clouds[-1]
        assert cloud.height == guides * ghosts_per_guide, cloud.height
        assert cloud.header.frame_id == 'world'
        xyz = np.frombuffer(bytes(cloud.data), dtype=np.uint8)
        assert xyz.size == cloud.row_step * cloud.height
    finally:
        ex.shutdown()
        probe.destroy_node()
        rclpy.shutdown(context=ctx)
