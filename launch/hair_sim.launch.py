"""Start the hair_sim node (and optionally rviz2) the ROS 2 way.

    ros2 launch hair_tracking hair_sim.launch.py
    ros2 launch hair_tracking hair_sim.launch.py scene:=long_hair rviz:=true
    ros2 launch hair_tracking hair_sim.launch.py namespace:=left \
        params_file:=/path/to/my_params.yaml use_sim_time:=true

Arguments (``ros2 launch hair_tracking hair_sim.launch.py --show-args``):

* ``params_file``: a params file of the node (keyed ``/**:`` or by the node name); empty (the
  default) gives none: the parameters keep their defaults.  The package's
  ``config/hair_sim.yaml`` lists every parameter at its default and is a starting point.
* ``scene``: a scene preset (``default``, ``long_hair``, ``short_hair``, ``stiff_extreme``) or
  the path of a scene YAML; it sets ``scene_file``.  Values in ``params_file`` override the
  scene's, so a params file meant to be used with a scene names only what it changes.
* ``namespace``: the node's namespace (its topics become ``<ns>/head_pose``,
  ``<ns>/hair/points`` ...; ``/tf`` and ``/diagnostics`` stay global).
* ``use_sim_time``: take time from ``/clock`` (a bag played with ``--clock``).
* ``rviz``: also start rviz2 with the package's ``rviz/hair_sim.rviz`` (hair cloud and markers,
  the head marker, TF; fixed frame ``world``).
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
RVIZ_CONFIG = ('rviz', 'hair_sim.rviz')
# argument: (default, description)
ARGUMENTS = {
    'params_file': ('', 'params file of the node (empty: parameter defaults)'),
    'scene': ('', 'scene preset (default, long_hair, short_hair, stiff_extreme) or scene YAML '
                  'path: sets the scene_file parameter'),
    'namespace': ('', 'namespace of the node and its topics'),
    'use_sim_time': ('false', 'use /clock as the node clock'),
    'rviz': ('false', 'also start rviz2 with the package rviz configuration'),
}
# node parameters this file sets (checked against the node's parameter table)
SETS_PARAMETERS = ('scene_file', 'use_sim_time')


def _truth(text: str) -> bool:
    value = text.strip().lower()
    if value not in ('true', 'false', '1', '0', 'yes', 'no', 'on', 'off'):
        raise ValueError(f'expected true or false, got {text!r}')
    return value in ('true', '1', 'yes', 'on')


def _hair_sim(context):
    params_file = LaunchConfiguration('params_file').perform(context)
    scene = LaunchConfiguration('scene').perform(context)
    parameters = []
    if params_file:
        parameters.append(os.path.abspath(os.path.expanduser(params_file)))
    overrides = {'use_sim_time': _truth(LaunchConfiguration('use_sim_time').perform(context))}
    if scene:
        overrides['scene_file'] = scene
    parameters.append(overrides)
    return [Node(package=PACKAGE, executable=EXECUTABLE, name=NODE_NAME,
                 namespace=LaunchConfiguration('namespace').perform(context),
                 parameters=parameters, output='screen', emulate_tty=True)]


def generate_launch_description():
    share = get_package_share_directory(PACKAGE)
    actions = [DeclareLaunchArgument(name, default_value=default, description=text)
               for name, (default, text) in ARGUMENTS.items()]
    actions.append(OpaqueFunction(function=_hair_sim))
    actions.append(Node(package='rviz2', executable='rviz2', name='rviz2',
                        arguments=['-d', os.path.join(share, *RVIZ_CONFIG)],
                        parameters=[{'use_sim_time': LaunchConfiguration('use_sim_time')}],
                        condition=IfCondition(LaunchConfiguration('rviz')), output='screen'))
    return LaunchDescription(actions)
