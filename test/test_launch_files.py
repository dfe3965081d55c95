"""launch/hair_sim.launch.py and rviz/hair_sim.rviz, checked without the launch package (no
wheel of ros2launch/launch_ros exists here, so the launch file is never run in these tests):
it compiles, names an executable the package installs, a node name and parameters the node
has, and a share file that is installed; the rviz configuration shows the topics the node
publishes.  The install tree itself is checked in test_colcon.py.
"""
import ast
import os

import yaml

from console_scripts import console_scripts
from hair_tracking.core import param_table as params
from hair_tracking.ros.topics import HEAD_MARKER_TOPIC

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAUNCH = os.path.join(ROOT, 'launch', 'hair_sim.launch.py')
RVIZ = os.path.join(ROOT, 'rviz', 'hair_sim.rviz')


def _constants(path):
    """Module-level ``NAME = literal`` assignments of a Python file."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    out = {}
    for stmt in tree.body:
        if isinstance(stmt, ast.Assign) and len(stmt.targets) == 1 \
                and isinstance(stmt.targets[0], ast.Name):
            try:
                out[stmt.targets[0].id] = ast.literal_eval(stmt.value)
            except ValueError:
                pass
    return out, tree


def test_launch_file_compiles_and_names_what_exists():
    with open(LAUNCH, encoding='utf-8') as f:
        compile(f.read(), LAUNCH, 'exec')
    consts, tree = _constants(LAUNCH)
    assert consts['PACKAGE'] == 'hair_tracking'
    assert consts['EXECUTABLE'] in console_scripts()
    assert consts['NODE_NAME'] == params.NODE_NAME
    assert os.path.isfile(os.path.join(ROOT, *consts['RVIZ_CONFIG']))
    table = params.by_name()
    for name in consts['SETS_PARAMETERS']:
        assert name in table or name == 'use_sim_time', name
    assert set(consts['ARGUMENTS']) == {'params_file', 'scene', 'namespace', 'use_sim_time',
                                        'rviz'}
    # every preset the scene argument's help names is shipped
    for preset in ('default', 'long_hair', 'short_hair', 'stiff_extreme'):
        assert os.path.isfile(os.path.join(ROOT, 'config', f'scene_{preset}.yaml'))
    # the launch file's strings that look like parameter names are the node's
    names = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
             and isinstance(n.value, str) and n.value in ('scene_file', 'use_sim_time')}
    assert names == {'scene_file', 'use_sim_time'}
    assert 'generate_launch_description' in {n.name for n in tree.body
                                             if isinstance(n, ast.FunctionDef)}


def test_launch_and_rviz_files_are_installed_by_setup_py():
    with open(os.path.join(ROOT, 'setup.py'), encoding='utf-8') as f:
        text = f.read()
    assert "('share/' + package_name + '/launch', glob('launch/*.launch.py'))" in text
    assert "('share/' + package_name + '/rviz', glob('rviz/*.rviz'))" in text


def test_rviz_config_shows_the_node_topics():
    with open(RVIZ, encoding='utf-8') as f:
        cfg = yaml.safe_load(f)
    manager = cfg['Visualization Manager']
    displays = {d['Class']: d for d in manager['Displays']}
    assert displays['rviz_default_plugins/PointCloud2']['Topic']['Value'] == '/hair/points'
    assert displays['rviz_default_plugins/MarkerArray']['Topic']['Value'] == '/hair/markers'
    assert displays['rviz_default_plugins/Marker']['Topic']['Value'] == '/' + HEAD_MARKER_TOPIC
    assert 'rviz_default_plugins/TF' in displays
    assert manager['Global Options']['Fixed Frame'] == params.by_name()['fixed_frame'].default


def test_colcon_ignores_the_interfaces_a_ros_installation_has():
    # interfaces/tf2_msgs and hri_msgs are built by make install for the pip-only venv; a colcon
    # workspace must not build them over a ROS installation's own; hair_tracking_msgs is the
    # package's own, which colcon builds (docs/ros.md)
    ignored = {name for name in os.listdir(os.path.join(ROOT, 'interfaces'))
               if os.path.isfile(os.path.join(ROOT, 'interfaces', name, 'COLCON_IGNORE'))}
    assert ignored == {'tf2_msgs', 'hri_msgs'}
    assert os.path.isfile(os.path.join(ROOT, 'interfaces', 'hair_tracking_msgs', 'package.xml'))


SHARDS_LAUNCH = os.path.join(ROOT, 'launch', 'hair_sim_shards.launch.py')
SHARDS_RVIZ = os.path.join(ROOT, 'rviz', 'hair_sim_shards.rviz')


def test_shards_launch_file_compiles_and_names_what_exists():
    """launch/hair_sim_shards.launch.py: the guides node and hair_sim_ghosts, the parameters
    it sets are theirs, its shard list is checked."""
    from hair_tracking.ros import ghosts

    with open(SHARDS_LAUNCH, encoding='utf-8') as f:
        code = f.read()
    compile(code, SHARDS_LAUNCH, 'exec')
    consts, tree = _constants(SHARDS_LAUNCH)
    assert consts['PACKAGE'] == 'hair_tracking'
    assert consts['EXECUTABLE'] in console_scripts()
    assert consts['SHARD_EXECUTABLE'] in console_scripts()
    assert consts['NODE_NAME'] == params.NODE_NAME
    assert consts['SHARD_NODE_NAME'] == ghosts.NODE_NAME
    assert os.path.isfile(os.path.join(ROOT, *consts['RVIZ_CONFIG']))
    table = params.by_name()
    for name in consts['SETS_PARAMETERS']:
        assert name in table or name == 'use_sim_time', name
    with open(os.path.join(ROOT, 'hair_tracking', 'ros', 'ghosts.py'), encoding='utf-8') as f:
        shard_source = f.read()
    for name in consts['SETS_SHARD_PARAMETERS']:
        assert f"declare_parameter('{name}'" in shard_source or name == 'use_sim_time', name
    assert {'shards', 'shard_ids', 'guides', 'rviz'} <= set(consts['ARGUMENTS'])
    assert 'generate_launch_description' in {n.name for n in tree.body
                                             if isinstance(n, ast.FunctionDef)}
    # its shard list, run without the launch package
    funcs = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    scope = {}
    exec(compile(ast.Module(body=[funcs['_shard_ids']], type_ignores=[]), SHARDS_LAUNCH,
                 'exec'), scope)
    assert scope['_shard_ids']('', 3) == [0, 1, 2]
    assert scope['_shard_ids']('2, 3', 4) == [2, 3]
    for bad in (('4', 4), ('', 0)):
        try:
            scope['_shard_ids'](*bad)
        except ValueError:
            continue
        raise AssertionError(f'{bad} accepted')


def test_shards_rviz_config_shows_the_shard_topics():
    from hair_tracking.ros.ghosts import shard_topic

    with open(SHARDS_RVIZ, encoding='utf-8') as f:
        cfg = yaml.safe_load(f)
    topics = {d['Topic']['Value'] for d in cfg['Visualization Manager']['Displays']
              if 'Topic' in d}
    for k in range(4):
        assert '/' + shard_topic(k, 'points') in topics
        assert '/' + shard_topic(k, 'markers') in topics
