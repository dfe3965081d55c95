"""Scene loading and validation."""
import glob
import os

import pytest

from hair_tracking.core.scene import Scene, SceneError

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config')


def test_defaults_are_valid():
    Scene().validate()


@pytest.mark.parametrize('path', sorted(glob.glob(os.path.join(CONFIG, 'scene_*.yaml'))))
def test_presets_load(path):
    scene = Scene.from_yaml(path)
    assert scene.groom.guides >= 1


def test_presets_exist():
    names = {os.path.basename(p) for p in glob.glob(os.path.join(CONFIG, 'scene_*.yaml'))}
    assert {'scene_default.yaml', 'scene_short_hair.yaml', 'scene_long_hair.yaml',
            'scene_stiff_extreme.yaml'} <= names


def test_yaml_values_are_used(tmp_path):
    p = tmp_path / 's.yaml'
    p.write_text('groom: {guides: 7, length: 0.5}\nsolver: {type: pbd, iterations: 9}\n')
    s = Scene.from_yaml(str(p))
    assert (s.groom.guides, s.groom.length, s.solver.type, s.solver.iterations) == \
        (7, 0.5, 'pbd', 9)


@pytest.mark.parametrize('data, field, words', [
    ({'groom': {'guides': 0}}, 'groom.guides', 'allowed range'),
    ({'groom': {'length': -1.0}}, 'groom.length', 'allowed range'),
    ({'solver': {'type': 'euler'}}, 'solver.type', 'ftl, pbd, xpbd'),
    ({'solver': {'dt': 0.0}}, 'solver.dt', 'allowed range'),
    ({'solver': {'stiffness': 0.0}}, 'solver.stiffness', '(0.0, 1.0]'),
    ({'collider': {'shape': 'cube'}}, 'collider.shape', 'none, sphere, ellipsoid'),
    ({'collider': {'radii': [0.1, 0.1]}}, 'collider.radii', 'list of 3 numbers'),
    ({'groom': {'guides': 2.5}}, 'groom.guides', 'integer'),
    ({'groom': {'guides': float('nan')}}, 'groom.guides', 'integer'),
    ({'groom': {'seed': float('inf')}}, 'groom.seed', 'integer'),
    ({'groom': {'guidez': 3}}, 'groom.guidez', 'unknown field'),
    ({'tracking': {'elastic_weight': 'yes'}}, 'tracking.elastic_weight', 'true or false'),
    ({'gravity': [0.0, float('nan'), 0.0]}, 'gravity', 'finite'),
    ({'damping': float('inf')}, 'damping', 'allowed range'),
    ({'groom': {'scalp': {'max_polar_deg': 30.0}}}, 'groom.scalp.front_max_polar_deg',
     'must not exceed'),
])
def test_invalid_fields_are_named(data, field, words):
    with pytest.raises(SceneError) as err:
        Scene.from_dict(data)
    assert err.value.field == field
    assert words in str(err.value)


def test_bad_files(tmp_path):
    with pytest.raises(SceneError, match='file not found'):
        Scene.from_yaml(str(tmp_path / 'missing.yaml'))
    p = tmp_path / 'bad.yaml'
    p.write_text('groom: [1, 2\n')
    with pytest.raises(SceneError, match='not valid YAML'):
        Scene.from_yaml(str(p))
    p.write_text('- 1\n- 2\n')
    with pytest.raises(SceneError, match='mapping'):
        Scene.from_yaml(str(p))


def test_with_changes_validates():
    s = Scene().with_changes(solver__type='xpbd', damping=2.0)
    assert s.solver.type == 'xpbd' and s.damping == 2.0
    with pytest.raises(SceneError):
        Scene().with_changes(solver__iterations=0)


def test_round_trip_dict():
    s = Scene().with_changes(groom__guides=5, output__curve='bezier')
    assert Scene.from_dict(s.to_dict()) == s
