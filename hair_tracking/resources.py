"""Where the package's installed files are: scene presets (config/), launch/, rviz/, bundled data.

The share folder is looked up the way ROS packages find theirs: through the ament index
(``ament_index_python.get_package_share_directory``; without that module, the index's marker
file ``share/ament_index/resource_index/packages/hair_tracking`` is looked for in every prefix
of ``AMENT_PREFIX_PATH`` directly).  A colcon install tree, a ROS package and a sourced
workspace resolve this way.  Where the package is not in the index (the source tree, an
editable pip install) the source tree's folders are used, then ``sys.prefix/share/hair_tracking``
(a plain pip install).
"""
import os
import sys
from typing import Optional

PACKAGE = 'hair_tracking'
_HERE = os.path.dirname(os.path.abspath(__file__))
_SOURCE_ROOT = os.path.dirname(_HERE)


def _ament_share_dir(package: str = PACKAGE) -> Optional[str]:
    """The package's share folder from the ament index, or None when it is not indexed."""
    try:
        from ament_index_python.packages import get_package_share_directory
    except ImportError:
        get_package_share_directory = None
    if get_package_share_directory is not None:
        try:
            return get_package_share_directory(package)
        except (LookupError, OSError, ValueError):     # not indexed, or no AMENT_PREFIX_PATH
            return None
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        marker = os.path.join(prefix, 'share', 'ament_index', 'resource_index', 'packages',
                              package)
        if prefix and os.path.isfile(marker):
            return os.path.join(prefix, 'share', package)
    return None


def share_candidates():
    """The folders that may hold config/, launch/ and rviz/, in the order they are tried."""
    found = []
    ament = _ament_share_dir()
    if ament:
        found.append(ament)
    found.append(_SOURCE_ROOT)
    found.append(os.path.join(sys.prefix, 'share', PACKAGE))
    return found


def share_path(*parts: str) -> str:
    """Path of an installed share file or folder, e.g. ``share_path('rviz', 'hair_sim.rviz')``.

    Raises FileNotFoundError naming the folders looked in.
    """
    tried = []
    for base in share_candidates():
        path = os.path.join(base, *parts)
        if os.path.exists(path):
            return path
        tried.append(base)
    raise FileNotFoundError(f'{PACKAGE}: {os.path.join(*parts)} not found in '
                            + ', '.join(tried))


def config_dir() -> str:
    """The config/ folder (ament index, else the source tree, else sys.prefix/share)."""
    return share_path('config')


def config_path(name: str) -> str:
    """Path of a config file; ``name`` may be a path already, or a preset name like 'long_hair'."""
    if os.path.isfile(name):
        return name
    folder = config_dir()
    for candidate in (name, name + '.yaml', 'scene_' + name + '.yaml'):
        path = os.path.join(folder, candidate)
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(f'no such scene or config file: {name} (looked in {folder})')


def data_path(name: str) -> str:
    return os.path.join(_HERE, 'data', name)


def message_definition(package: str, name: str) -> Optional[str]:
    """The text of ``<package>/msg/<name>.msg`` (an interface package this project builds:
    ``interfaces/``), from the package's share folder in the ament index, ``sys.prefix``'s
    share folder (the venv ``make install`` builds into) or the source tree; None when none
    holds it."""
    places = [_ament_share_dir(package), os.path.join(sys.prefix, 'share', package),
              os.path.join(_SOURCE_ROOT, 'interfaces', package)]
    for base in places:
        path = os.path.join(base, 'msg', f'{name}.msg') if base else ''
        if path and os.path.isfile(path):
            with open(path, encoding='utf-8') as f:
                return f.read()
    return None
