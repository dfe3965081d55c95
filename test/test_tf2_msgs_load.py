"""The tf2_msgs that make install generates (interfaces/build_tf2_msgs.sh) loads whatever
environment the node's parent process passes on.

The ROS wheels set LD_LIBRARY_PATH once, in a bootstrap that re-executes Python unless its guard
variable ``_ROS_WHEELS_BOOTSTRAP_COMPLETE`` is set; a process started by another ROS-wheels venv
inherits that guard and that venv's library path.  Such a parent is made here: its
LD_LIBRARY_PATH names a folder with every library of this venv's ``lib`` except tf2_msgs' (the
same wheels, no generated tf2_msgs) and the wheels' ``ros_*.libs``.  The node, with a /tf
publisher and a /tf subscription, must start there: the generated libraries find each other and
their typesupports through their RPATH.
"""
import glob
import os
import subprocess
import sys
import sysconfig

import pytest

from node_process import until_ready_then_ctrl_c

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 85
GUARD = '_ROS_WHEELS_BOOTSTRAP_COMPLETE'


def _generated_here() -> bool:
    import tf2_msgs
    return os.path.realpath(tf2_msgs.__file__).startswith(os.path.realpath(sys.prefix) + os.sep)


pytestmark = pytest.mark.skipif(
    not _generated_here(), reason='tf2_msgs of a ROS installation: it loads through the '
                                  "installation's own environment")


def _foreign_library_path(folder) -> str:
    """LD_LIBRARY_PATH of another ROS-wheels venv: the same wheel libraries, no tf2_msgs."""
    lib = os.path.join(sys.prefix, 'lib')
    for path in glob.glob(os.path.join(lib, '*.so*')):
        name = os.path.basename(path)
        if not name.startswith('libtf2_msgs'):
            os.symlink(path, os.path.join(folder, name))
    assert not glob.glob(os.path.join(folder, 'libtf2_msgs*'))
    libs = sorted(glob.glob(os.path.join(sysconfig.get_path('platlib'), 'ros_*.libs')))
    return os.pathsep.join([str(folder)] + libs)


def _start_node(env):
    args = ['-p', 'use_tf:=true', '-p', 'publish_tf:=true', '-p', 'warmup:=false',
            '-p', 'groom.guides:=3', '-p', 'groom.ghosts_per_guide:=2']
    return subprocess.Popen([sys.executable, '-m', 'hair_tracking.ros.node', '--ros-args'] + args,
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def test_node_with_tf_starts_under_a_foreign_library_path(tmp_path):
    folder = tmp_path / 'foreign_lib'
    folder.mkdir()
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    env = dict(os.environ, LD_LIBRARY_PATH=_foreign_library_path(folder), PYTHONPATH=path,
               ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED='1', **{GUARD: '1'})
    proc = _start_node(env)
    text = until_ready_then_ctrl_c(proc)
    assert 'cannot open shared object file' not in text, text
    assert any('ready: 3 guides' in ln for ln in text.splitlines()), text
    assert proc.returncode == 0, text
