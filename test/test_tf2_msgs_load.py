"""The interface packages that make install generates (interfaces/build_interfaces.sh:
tf2_msgs, hri_msgs, hair_tracking_msgs) load whatever environment the parent process passes on.

The ROS wheels set LD_LIBRARY_PATH once, in a bootstrap that re-executes Python unless its guard
variable ``_ROS_WHEELS_BOOTSTRAP_COMPLETE`` is set; a process started by another ROS-wheels venv
inherits that guard and that venv's library path.  Such a parent is made here: its
LD_LIBRARY_PATH names a folder with every library of this venv's ``lib`` except the generated
packages' (the same wheels, nothing generated) and the wheels' ``ros_*.libs``.  The node, with a
/tf publisher and a /tf subscription, must start there, and a process must send and receive an
hri_msgs/IdsList and a hair_tracking_msgs/GuideState over DDS: the generated libraries find each
other and their typesupports through their RPATH.  A package that comes from elsewhere (a ROS
installation) loads through that installation's environment: its test is skipped.
"""
import glob
import importlib
import os
import subprocess
import sys
import sysconfig

import pytest

from node_process import until_ready_then_ctrl_c

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 85
DOMAIN_MESSAGES = 86
GUARD = '_ROS_WHEELS_BOOTSTRAP_COMPLETE'
GENERATED = ('tf2_msgs', 'hri_msgs', 'hair_tracking_msgs')


def _generated_here(package) -> bool:
    try:
        module = importlib.import_module(package)
    except ImportError:
        return False
    return os.path.realpath(module.__file__).startswith(os.path.realpath(sys.prefix) + os.sep)


def _skip_unless_generated_here(package):
    if not _generated_here(package):
        pytest.skip(f'{package} is not generated into this venv (make install), or comes from a '
                    "ROS installation and loads through the installation's own environment")


def _foreign_env(tmp_path) -> dict:
    """The environment of a child of another ROS-wheels venv: LD_LIBRARY_PATH with the same
    wheel libraries, none of the generated packages', and the bootstrap guard set."""
    folder = tmp_path / 'foreign_lib'
    folder.mkdir()
    prefixes = tuple(f'lib{package}__' for package in GENERATED)
    for path in glob.glob(os.path.join(sys.prefix, 'lib', '*.so*')):
        name = os.path.basename(path)
        if not name.startswith(prefixes):
            os.symlink(path, os.path.join(folder, name))
    assert not [p for p in os.listdir(folder) if p.startswith(prefixes)]
    libs = sorted(glob.glob(os.path.join(sysconfig.get_path('platlib'), 'ros_*.libs')))
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    return dict(os.environ, LD_LIBRARY_PATH=os.pathsep.join([str(folder)] + libs),
                PYTHONPATH=path, PYTHONUNBUFFERED='1', **{GUARD: '1'})


def _start_node(env):
    args = ['-p', 'use_tf:=true', '-p', 'publish_tf:=true', '-p', 'warmup:=false',
            '-p', 'groom.guides:=3', '-p', 'groom.ghosts_per_guide:=2']
    return subprocess.Popen([sys.executable, '-m', 'hair_tracking.ros.node', '--ros-args'] + args,
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def test_node_with_tf_starts_under_a_foreign_library_path(tmp_path):
    _skip_unless_generated_here('tf2_msgs')
    env = dict(_foreign_env(tmp_path), ROS_DOMAIN_ID=str(DOMAIN))
    proc = _start_node(env)
    text = until_ready_then_ctrl_c(proc)
    assert 'cannot open shared object file' not in text, text
    assert any('ready: 3 guides' in ln for ln in text.splitlines()), text
    assert proc.returncode == 0, text


#: A child process that publishes one message of a generated type and takes it back over DDS
#: (its typesupports: the C dispatch and the Fast DDS one the RMW asks for), and prints the type
#: hash its publisher announces.
_ROUND_TRIP = """
import sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from {package}.msg import {name} as T
sent = T({fields})
ctx = rclpy.Context()
rclpy.init(context=ctx, domain_id={domain})
ex = SingleThreadedExecutor(context=ctx)
node = rclpy.create_node('interfaces_load', context=ctx)
ex.add_node(node)
got = []
node.create_subscription(T, 'interfaces_load', got.append, 10)
pub = node.create_publisher(T, 'interfaces_load', 10)
deadline = time.monotonic() + 20
while time.monotonic() < deadline and not got:
    if pub.get_subscription_count():
        pub.publish(sent)
    ex.spin_once(timeout_sec=0.1)
(info,) = node.get_publishers_info_by_topic('/interfaces_load')
print('received equal' if got and got[0] == sent else 'nothing received', info.topic_type_hash)
ex.shutdown()
rclpy.try_shutdown(context=ctx)
"""


@pytest.mark.parametrize('package,name,fields', [
    ('hri_msgs', 'IdsList', "ids=['f3k9', 'a0b1']"),
    ('hair_tracking_msgs', 'GuideState',
     "guides=1, nodes=2, positions=[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], scene_fingerprint=2**63"),
])
def test_generated_messages_go_over_dds_under_a_foreign_library_path(
        tmp_path, package, name, fields):
    _skip_unless_generated_here(package)
    code = _ROUND_TRIP.format(package=package, name=name, fields=fields, domain=DOMAIN_MESSAGES)
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, env=_foreign_env(tmp_path),
                         capture_output=True, text=True, timeout=120)
    text = out.stdout + out.stderr
    assert 'cannot open shared object file' not in text, text
    assert out.returncode == 0, text
    assert out.stdout.strip() == f'received equal {_definition_hash(package, name)}', text


def _definition_hash(package, name):
    """RIHS01 type hash of interfaces/PACKAGE/msg/NAME.msg, by rosbags (its own implementation of
    the hash): the generated type is that definition, as DDS peers compare it."""
    from rosbags.typesys import get_typestore, Stores
    from rosbags.typesys.msg import get_types_from_msg
    store = get_typestore(Stores.ROS2_JAZZY)
    with open(os.path.join(ROOT, 'interfaces', package, 'msg', name + '.msg'),
              encoding='utf-8') as f:
        store.register(get_types_from_msg(f.read(), f'{package}/msg/{name}'))
    return store.hash_rihs01(f'{package}/msg/{name}')
