"""ament_python package set-up for hair_tracking.

The ROS wheels (rclpy, message packages) are deliberately not in install_requires: on a ROS
installation they come from the distribution, here they are installed by the Makefile.
"""
from glob import glob

from setuptools import find_packages, setup

package_name = 'hair_tracking'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    package_data={package_name: ['data/*']},
    install_requires=['setuptools', 'numpy', 'numba', 'pyyaml', 'rosbags'],
    extras_require={'view': ['viser'],         # hair_sim_view's web page
                    'usd': ['usd-core']},      # groom.file: USD BasisCurves
    zip_safe=True,
    maintainer='hair_tracking developers',
    maintainer_email='hair-tracking@example.invalid',
    description='Real-time hair that follows a head pose: PBD guide strands and ghost strands.',
    license='MIT',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            # each sets numba's cache folder and the stop request up before it imports its
            # executable's module (hair_tracking/executable.py)
            'hair_sim_node = hair_tracking.executable:hair_sim_node',
            'hair_sim_ghosts = hair_tracking.executable:hair_sim_ghosts',
            'hair_sim_bag = hair_tracking.executable:hair_sim_bag',
            'hair_sim_groom = hair_tracking.executable:hair_sim_groom',
            'hair_sim_eval = hair_tracking.executable:hair_sim_eval',
            'hair_sim_demo = hair_tracking.executable:hair_sim_demo',
            'hair_sim_warmup = hair_tracking.executable:hair_sim_warmup',
            'hair_sim_ctl = hair_tracking.executable:hair_sim_ctl',
            'hair_sim_view = hair_tracking.executable:hair_sim_view',
        ],
    },
)
