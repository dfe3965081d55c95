"""Start the hair_sim node as the guides node and N ghost shards (hair_sim_ghosts), on one
machine or spread over several (docs/ros.md).

    ros2 launch hair_tracking hair_sim_shards.launch.py shards:=2
    ros2 launch hair_tracking hair_sim_shards.launch.py shards:=4 shard_ids:=0,1 rviz:=true
    ros2 launch hair_tracking hair_sim_shards.launch.py shards:=4 shard_ids:=2,3 guides:=false

Arguments (``ros2 launch hair_tracking hair_sim_shards.launch.py --show-args``):

* ``shards``: how many shards share the ghosts (>= 1); the guides node gets ``shards:=N`` and
  publishes no ghosts of its own, shard ``k`` publishes ``hair/shard_<k>/points`` and
  ``.../markers``.
* ``shard_ids``: which shards this launch starts, comma-separated (empty: all of them); with
  ``guides:=false`` the rest of a machine's share: start the guides node on one machine and
  the shards anywhere on the same ROS domain.
* ``guides``: also start the guides node (hair_sim_node).
* ``params_file``, ``scene``, ``namespace``, ``use_sim_time``: as in hair_sim.launch.py (the
  shards take the scene and every other setting from the guides node).
* ``rviz``: also start rviz2 with ``rviz/hair_sim_shards.rviz`` (four shards' clouds).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = 'hair_tracking'
EXECUTABLE = 'hair_sim_node'
NODE_NAME = 'hair_sim'
SHARD_EXECUTABLE = 'hair_sim_ghosts'
SHARD_NODE_NAME = 'hair_sim_ghosts'
RVIZ_CONFIG = ('rviz', 'hair_sim_shards.rviz')
# argument: (default, description)
ARGUMENTS = {
    'shards': ('2', 'ghost shards that share the ghosts (>= 1)'),
    'shard_ids': ('', 'the shards this launch starts, comma-separated (empty: all)'),
    'guides': ('true', 'also start the guides node (hair_sim_node)'),
    'params_file': ('', 'params file of the guides node (empty: parameter defaults)'),
    'scene': ('', 'scene preset (default, long_hair, short_hair, stiff_extreme) or scene YAML '
                  'path: sets the scene_file parameter'),
    'namespace': ('', 'namespace of the nodes and their topics'),
    'use_sim_time': ('false', 'use /clock as the node clock'),
    'rviz': ('false', 'also start rviz2 with the package rviz configuration of the shards'),
}
# node parameters this file sets (checked against the node's parameter table)
SETS_PARAMETERS = ('scene_file', 'use_sim_time', 'shards')
# shard parameters this file sets (checked against hair_sim_ghosts)
SETS_SHARD_PARAMETERS = ('shard', 'shards', 'use_sim_time')


def _truth(text: str) -> bool:
    value = text.strip().lower()
    if value not in ('true', 'false', '1', '0', 'yes', 'no', 'on', 'off'):
        raise ValueError(f'expected true or false, got {text!r}')
    return value in ('true', '1', 'yes', 'on')


def _shard_ids(text: str, shards: int):
    if shards < 1:
        raise ValueError(f'shards must be >= 1, got {shards}')
    if not text.strip():
        return list(range(shards))
    ids = [int(v) for v in text.split(',') if v.strip()]
    for k in ids:
        if not 0 <= k < shards:
            raise ValueError(f'shard_ids: shard {k} of {shards} does not exist')
    return ids


def _nodes(context):
    shards = int(LaunchConfiguration('shards').perform(context))
    ids = _shard_ids(LaunchConfiguration('shard_ids').perform(context), shards)
    namespace = LaunchConfiguration('namespace').perform(context)
    sim_time = _truth(LaunchConfiguration('use_sim_time').perform(context))
    actions = []
    if _truth(LaunchConfiguration('guides').perform(context)):
        params_file = LaunchConfiguration('params_file').perform(context)
        scene = LaunchConfiguration('scene').perform(context)
        parameters = []
        if params_file:
            parameters.append(os.path.abspath(os.path.expanduser(params_file)))
        overrides = {'use_sim_time': sim_time, 'shards': shards}
        if scene:
            overrides['scene_file'] = scene
        parameters.append(overrides)
        actions.append(Node(package=PACKAGE, executable=EXECUTABLE, name=NODE_NAME,
                            namespace=namespace, parameters=parameters, output='screen',
                            emulate_tty=True))
    for k in ids:
        actions.append(Node(package=PACKAGE, executable=SHARD_EXECUTABLE,
                            name=f'{SHARD_NODE_NAME}_{k}', namespace=namespace,
                            parameters=[{'shard': k, 'shards': shards,
                                         'use_sim_time': sim_time}],
                            output='screen', emulate_tty=True))
    return actions


def generate_launch_description():
    share = get_package_share_directory(PACKAGE)
    actions = [DeclareLaunchArgument(name, default_value=default, description=text)
               for name, (default, text) in ARGUMENTS.items()]
    actions.append(OpaqueFunction(function=_nodes))
    actions.append(Node(package='rviz2', executable='rviz2', name='rviz2',
                        arguments=['-d', os.path.join(share, *RVIZ_CONFIG)],
                        parameters=[{'use_sim_time': LaunchConfiguration('use_sim_time')}],
                        condition=IfCondition(LaunchConfiguration('rviz')), output='screen'))
    return LaunchDescription(actions)
