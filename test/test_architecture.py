"""The folder tree is the architecture: imports point one way, down the layers, and the
simulation layers import no ROS package (read from the sources' import statements, so an import
inside a function counts too)."""
import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, 'hair_tracking')
ADAPTERS = os.path.join(ROOT, 'msg_adapters')

#: Layers from the bottom up: a module may import its own layer and the ones below it only.
#: The top-level helpers (resources, executable, shutdown) are leaves any layer may use; the
#: console entry points at the end of executable.py import the executables' modules inside
#: their functions.
LAYERS = ['core', 'motion', 'colliders', 'grooms', 'guides', 'ghosts', 'simulator', 'people',
          'output', 'bags', 'evaluation', 'ros']
LEAVES = {'resources', 'executable', 'shutdown'}
#: Layers that simulate or describe head motion: numpy, numba and yaml only, no ROS messages,
#: no rclpy, no adapters.
SIMULATION = {'core', 'motion', 'colliders', 'grooms', 'guides', 'ghosts', 'simulator',
              'people'}
#: Layers that join no ROS graph (no rclpy): they run without a ROS installation's middleware.
NO_GRAPH = SIMULATION | {'output', 'bags', 'evaluation'}
ROS_ROOTS = {'rclpy', 'rosidl_runtime_py', 'rosgraph_msgs', 'std_msgs', 'geometry_msgs',
             'sensor_msgs', 'visualization_msgs', 'diagnostic_msgs', 'std_srvs', 'tf2_msgs',
             'hri_msgs', 'hair_tracking_msgs', 'rcl_interfaces', 'builtin_interfaces',
             'msg_adapters', 'rosbags'}
#: At most this many modules at the top of hair_tracking/ (besides __init__.py).
MAX_TOP_MODULES = 4
#: All that msg_adapters (ROS messages <-> numpy, nothing of hair) may use of hair_tracking: the
#: quaternion maths and the one point-record writer.
ADAPTERS_MAY_USE = ('hair_tracking.core.transforms', 'hair_tracking.core.point_records')
#: Optional packages (not installed with the package) and the only modules that import them.
OPTIONAL = {'viser': {'hair_tracking.ros.view'}, 'pxr': {'hair_tracking.grooms.usd'}}


def modules():
    """(dotted name, path) of every module of the package."""
    for folder, _, files in os.walk(PACKAGE):
        for f in sorted(files):
            if f.endswith('.py'):
                path = os.path.join(folder, f)
                rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, '.')
                yield rel[:-len('.__init__')] if rel.endswith('.__init__') else rel, path


def imports(path, name):
    """Absolute dotted names imported by a module (relative imports resolved)."""
    with open(path, encoding='utf-8') as f:
        tree = ast.parse(f.read(), path)
    package = name if path.endswith('__init__.py') else name.rpartition('.')[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:
                parts = package.split('.')
                base = '.'.join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            for a in node.names:
                yield f'{base}.{a.name}' if base else a.name


def layer(name):
    """The layer of a ``hair_tracking`` module, None for the leaves and the package itself."""
    parts = name.split('.')
    if len(parts) < 2 or parts[1] in LEAVES:
        return None
    return parts[1]


def test_the_tree_has_the_layers_and_few_top_level_modules():
    for sub in LAYERS:
        if sub != 'simulator':
            assert os.path.isfile(os.path.join(PACKAGE, sub, '__init__.py')), sub
    top = sorted(f for f in os.listdir(PACKAGE) if f.endswith('.py') and f != '__init__.py')
    assert len(top) <= MAX_TOP_MODULES, top


@pytest.mark.parametrize('name,path', list(modules()), ids=lambda v: str(v))
def test_imports_point_down_the_layers(name, path):
    own = layer(name)
    for target in imports(path, name):
        root = target.split('.')[0]
        if own in SIMULATION:
            assert root not in ROS_ROOTS, f'{name} imports {target}: no ROS in simulation layers'
        if own in NO_GRAPH:
            assert root != 'rclpy', f'{name} imports {target}: only ros/ joins a ROS graph'
        if root != 'hair_tracking' or own is None:
            continue
        theirs = layer(target)
        if theirs is None:
            continue
        assert LAYERS.index(theirs) <= LAYERS.index(own), \
            f'{name} ({own}) imports {target} ({theirs}), a layer above it'


def test_msg_adapters_use_nothing_of_hair_but_the_quaternion_maths_and_the_record_writer():
    found = []
    for f in sorted(os.listdir(ADAPTERS)):
        if f.endswith('.py'):
            name = 'msg_adapters' if f == '__init__.py' else 'msg_adapters.' + f[:-3]
            found += [(name, t) for t in imports(os.path.join(ADAPTERS, f), name)
                      if t.split('.')[0] == 'hair_tracking']
    for name, target in found:
        assert target.rpartition('.')[0] in ADAPTERS_MAY_USE, \
            f'{name} imports {target}: msg_adapters know nothing of hair'
    assert found                        # the check looks at the modules that do use it


def test_optional_packages_are_imported_only_where_they_are_used():
    """viser (the browser viewer's library) stays out of the node and the simulation, usd-core
    (pxr) in the USD reader."""
    users = {root: set() for root in OPTIONAL}
    for name, path in modules():
        for target in imports(path, name):
            root = target.split('.')[0]
            if root in OPTIONAL:
                assert name in OPTIONAL[root], f'{name} imports the optional {root}'
                users[root].add(name)
    assert users == OPTIONAL            # the check looks at the modules that do use them


def test_the_import_check_catches_an_upward_import(tmp_path):
    bad = tmp_path / 'bad.py'
    bad.write_text('def f():\n    from hair_tracking.ros import node\n    import rclpy\n')
    found = list(imports(str(bad), 'hair_tracking.ghosts.bad'))
    assert 'hair_tracking.ros.node' in found and 'rclpy' in found
    assert LAYERS.index(layer('hair_tracking.ros.node')) > LAYERS.index('ghosts')
    assert 'bags' in NO_GRAPH and 'ros' not in NO_GRAPH


def test_the_numba_cache_key_covers_every_subpackage(tmp_path, monkeypatch):
    """numba checks only the defining file's timestamp, so the package keys its cache by a hash
    of all its sources: an edit in any subpackage must change that key."""
    import shutil

    from hair_tracking import executable
    copy = tmp_path / 'hair_tracking'
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns('__pycache__', 'data'))
    monkeypatch.setattr(executable, '_PACKAGE', str(copy))
    before = executable.source_hash()
    for sub in ('ghosts', 'guides', 'grooms', 'core'):
        kernel = next(p for p in sorted((copy / sub).iterdir()) if p.name != '__init__.py')
        kernel.write_text(kernel.read_text() + '\n# edited\n')
        after = executable.source_hash()
        assert after != before, sub
        before = after
