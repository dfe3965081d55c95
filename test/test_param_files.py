"""The files generated from the parameter table (config/hair_sim.yaml, config/scene_default.yaml,
the table in docs/node.md) are what the table makes now, and read back as the table says."""
import os

import pytest
import yaml

from hair_tracking.core.scene import Scene
from hair_tracking.output import param_files
from hair_tracking.core.param_table import by_name
from hair_tracking.output.settings import make_settings

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize('rel', sorted(param_files.generated(ROOT)))
def test_committed_files_are_the_generated_ones(rel):
    with open(os.path.join(ROOT, rel), encoding='utf-8') as f:
        committed = f.read()
    assert committed == param_files.generated(ROOT)[rel], \
        f'{rel} is out of date: run {param_files.COMMAND} from the repository root'


def _flat(d, prefix=''):
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flat(v, prefix + k + '.'))
        else:
            out[prefix + k] = v
    return out


def test_params_file_lists_every_parameter_with_typed_defaults():
    flat = _flat(yaml.safe_load(param_files.render_yaml())['/**']['ros__parameters'])
    table = by_name()
    assert list(flat) == list(table)
    for name, value in flat.items():
        p = table[name]
        if p.kind == 'double_array':
            assert tuple(value) == p.default
            assert all(type(v) is float for v in value), name
        else:
            assert value == p.default, name
            assert type(value) is type(p.default), name
    assert make_settings(flat) == make_settings({})


def test_the_default_scene_file_is_the_default_scene():
    text = param_files.render_scene_yaml()
    assert Scene.from_dict(yaml.safe_load(text)) == Scene()
    assert Scene.from_yaml(os.path.join(ROOT, 'config', 'scene_default.yaml')) == Scene()


def test_the_docs_table_is_spliced_between_its_markers():
    doc = f'intro\n{param_files.DOCS_BEGIN}old table\n{param_files.DOCS_END}outro\n'
    new = param_files.with_table(doc)
    assert new == (f'intro\n{param_files.DOCS_BEGIN}{param_files.render_markdown()}'
                   f'{param_files.DOCS_END}outro\n')
    assert param_files.with_table(new) == new
    with pytest.raises(ValueError, match='markers'):
        param_files.with_table('no markers here\n')


def test_the_command_writes_the_files_and_refuses_a_wrong_root(tmp_path, capsys):
    (tmp_path / 'docs').mkdir()
    (tmp_path / 'config').mkdir()
    (tmp_path / 'docs' / 'node.md').write_text(
        f'# node\n{param_files.DOCS_BEGIN}{param_files.DOCS_END}', encoding='utf-8')
    assert param_files.main(['--root', str(tmp_path)]) == 0
    for rel, text in param_files.generated(ROOT).items():
        if rel != param_files.DOCS:
            assert (tmp_path / rel).read_text(encoding='utf-8') == text
    assert param_files.render_markdown() in (tmp_path / 'docs' / 'node.md').read_text()
    assert param_files.main(['--root', str(tmp_path)]) == 0
    assert capsys.readouterr().out.count('up to date') == 3
    assert param_files.main(['--root', str(tmp_path / 'nowhere')]) == 2
    assert 'repository root' in capsys.readouterr().err
