"""Where the package's installed files are: scene presets (config/) and bundled data."""
import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))


def config_dir() -> str:
    """The config/ folder: the source tree's, else the installed share/hair_tracking/config."""
    for candidate in (os.path.join(os.path.dirname(_HERE), 'config'),
                      os.path.join(sys.prefix, 'share', 'hair_tracking', 'config')):
        if os.path.isdir(candidate):
            return candidate
    raise FileNotFoundError('hair_tracking config/ folder not found (source tree or install)')


def config_path(name: str) -> str:
    """Path of a config file; ``name`` may be a path already, or a preset name like 'long_hair'."""
    if os.path.isfile(name):
        return name
    for candidate in (name, name + '.yaml', 'scene_' + name + '.yaml'):
        path = os.path.join(config_dir(), candidate)
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(f'no such scene or config file: {name} (looked in {config_dir()})')


def data_path(name: str) -> str:
    return os.path.join(_HERE, 'data', name)
