"""package.xml is what rosdep reads: it must declare, by rosdep key, everything the package's
modules import and everything its launch files start (and nothing else)."""
import ast
import glob
import os
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FIRST_PARTY = {'hair_tracking', 'msg_adapters'}

#: top-level import name -> the rosdep key of what provides it
ROSDEP_KEYS = {
    'ament_index_python': 'ament_index_python',
    'builtin_interfaces': 'builtin_interfaces',
    'diagnostic_msgs': 'diagnostic_msgs',
    'geometry_msgs': 'geometry_msgs',
    'hair_tracking_msgs': 'hair_tracking_msgs',
    'hri_msgs': 'hri_msgs',
    'launch': 'launch',
    'launch_ros': 'launch_ros',
    'matplotlib': 'python3-matplotlib',
    'numba': 'python3-numba',
    'numpy': 'python3-numpy',
    'PIL': 'python3-pil',
    'plyfile': 'python3-plyfile-pip',
    'rcl_interfaces': 'rcl_interfaces',
    'rclpy': 'rclpy',
    'rosbags': 'python3-rosbags-pip',
    # the MCAP chunk codecs rosbags itself depends on (lz4, zstd: compression.zstd from
    # Python 3.14, backports.zstd before)
    'lz4': 'python3-rosbags-pip',
    'backports': 'python3-rosbags-pip',
    'compression': 'python3-rosbags-pip',
    'rosgraph_msgs': 'rosgraph_msgs',
    'sensor_msgs': 'sensor_msgs',
    'std_msgs': 'std_msgs',
    'std_srvs': 'std_srvs',
    'tf2_msgs': 'tf2_msgs',
    'visualization_msgs': 'visualization_msgs',
    'yaml': 'python3-yaml',
}
#: imports the package works without (it says so when they are missing), not declared
OPTIONAL = {
    'pypbd': 'the peer library of the evaluation and the benchmarks (make bench, make eval)',
    'viser': "hair_sim_view's browser viewer (pip install viser)",
    'pxr': 'USD grooms (usd-core, the optional extra [usd])',
}


def _sources():
    files = glob.glob(os.path.join(ROOT, 'hair_tracking', '**', '*.py'), recursive=True)
    files += glob.glob(os.path.join(ROOT, 'msg_adapters', '**', '*.py'), recursive=True)
    return sorted(files) + _launch_files()


def _launch_files():
    return sorted(glob.glob(os.path.join(ROOT, 'launch', '*.py')))


def _imports(path):
    """{top-level name of an absolute import} in the file."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split('.')[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names.add(node.module.split('.')[0])
    return names


def _started_packages(path):
    """Packages the launch file starts: ``Node(package='...')`` with a literal name."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', None) == 'Node':
            for kw in node.keywords:
                if kw.arg == 'package' and isinstance(kw.value, ast.Constant):
                    found.add(kw.value.value)
    return found


def _declared():
    root = ET.parse(os.path.join(ROOT, 'package.xml')).getroot()
    return {e.text.strip() for tag in ('depend', 'exec_depend') for e in root.iter(tag)}


def _needed():
    """{rosdep key: why} of the package's modules and launch files."""
    needed, unknown = {}, []
    for path in _sources():
        rel = os.path.relpath(path, ROOT)
        for name in sorted(_imports(path) - FIRST_PARTY - set(sys.stdlib_module_names)):
            if name in ROSDEP_KEYS:
                needed.setdefault(ROSDEP_KEYS[name], f'{rel} imports {name}')
            elif name not in OPTIONAL:
                unknown.append(f'{rel} imports {name}')
    for path in _launch_files():
        for package in _started_packages(path) - {'hair_tracking'}:
            needed.setdefault(package, f'{os.path.relpath(path, ROOT)} starts it')
    if _launch_files():
        needed.setdefault('ros2launch', 'the package ships launch files (ros2 launch)')
    return needed, unknown


def test_every_import_has_a_rosdep_key():
    _, unknown = _needed()
    assert not unknown, ('imports without a rosdep key: ' + '; '.join(unknown) + '. Add each '
                         'to ROSDEP_KEYS in test/test_package_xml.py with the rosdep key of its '
                         'package (or to OPTIONAL if the package works without it) and declare '
                         'the key in package.xml')


def test_package_xml_declares_what_the_package_uses_and_nothing_else():
    needed, _ = _needed()
    declared = _declared()
    missing = {key: why for key, why in needed.items() if key not in declared}
    assert not missing, f'package.xml lacks <exec_depend> of: {missing}'
    unused = sorted(declared - set(needed))
    assert not unused, f'package.xml declares what nothing imports or starts: {unused}'


def test_the_launch_files_start_rviz_and_import_launch():
    paths = _launch_files()
    assert {os.path.basename(p) for p in paths} == {'hair_sim.launch.py',
                                                    'hair_sim_shards.launch.py'}
    for path in paths:
        assert _started_packages(path) == {'rviz2'}      # the nodes go by the PACKAGE constant
        assert {'launch', 'launch_ros', 'ament_index_python'} <= _imports(path)
    needed, _ = _needed()
    assert {'rviz2', 'launch', 'launch_ros', 'ros2launch'} <= set(needed)
