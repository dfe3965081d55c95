"""Share files found through the ament index first, the source tree otherwise."""
import builtins
import os

import pytest

from hair_tracking import resources

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _fake_prefix(tmp_path):
    prefix = tmp_path / 'install'
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'hair_tracking'
    marker.parent.mkdir(parents=True)
    marker.write_text('')
    config = prefix / 'share' / 'hair_tracking' / 'config'
    config.mkdir(parents=True)
    (config / 'scene_long_hair.yaml').write_text('groom: {guides: 3}\n')
    return prefix


@pytest.mark.parametrize('with_module', [True, False])
def test_presets_resolve_in_an_indexed_install_tree(tmp_path, monkeypatch, with_module):
    prefix = _fake_prefix(tmp_path)
    monkeypatch.setenv('AMENT_PREFIX_PATH', os.pathsep.join([str(tmp_path / 'other'),
                                                             str(prefix)]))
    if not with_module:          # the index read directly, as without ament_index_python
        real_import = builtins.__import__

        def no_ament(name, *args, **kwargs):
            if name.startswith('ament_index_python'):
                raise ImportError(name)
            return real_import(name, *args, **kwargs)
        monkeypatch.setattr(builtins, '__import__', no_ament)
    want = prefix / 'share' / 'hair_tracking' / 'config' / 'scene_long_hair.yaml'
    assert resources.config_path('long_hair') == str(want)
    # a file only the source tree has is still found there
    assert resources.share_path('config', 'scene_short_hair.yaml') == \
        os.path.join(ROOT, 'config', 'scene_short_hair.yaml')


def test_source_tree_without_an_index(monkeypatch):
    monkeypatch.delenv('AMENT_PREFIX_PATH', raising=False)
    assert resources.config_dir() == os.path.join(ROOT, 'config')
    assert resources.config_path('long_hair') == os.path.join(ROOT, 'config',
                                                              'scene_long_hair.yaml')
    with pytest.raises(FileNotFoundError, match='no such scene'):
        resources.config_path('no_such_preset')
    with pytest.raises(FileNotFoundError, match='nothing.txt not found'):
        resources.share_path('nothing.txt')
