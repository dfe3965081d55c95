"""The declarative parameter table (no ROS): sync with the scene, validation, YAML."""
import dataclasses
import math
import os

import pytest
import yaml

from hair_tracking.core import params
from hair_tracking.core.params import apply_changes, make_settings, ParamError
from hair_tracking.core.scene import RULES, Scene, SceneError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_every_scene_field_has_exactly_one_parameter():
    fields = params.scene_fields()
    scene_names = [p.name for p in params.scene_params()]
    assert sorted(scene_names) == sorted(fields)
    assert set(params._SCENE_DOCS) == set(fields)
    names = [p.name for p in params.table()]
    assert len(names) == len(set(names)), 'duplicate parameter names'
    assert not set(p.name for p in params.NODE_PARAMS) & set(fields)


def test_scene_defaults_and_kinds_come_from_the_scene():
    fields = params.scene_fields(Scene())
    for p in params.scene_params():
        assert p.default == fields[p.name]
        assert p.kind in params.KINDS
        assert p.scene
    for p in params.table():
        if p.kind == 'double':
            assert type(p.default) is float, p.name      # 10.0, never 10 (rclpy types by value)
        if p.kind == 'int':
            assert type(p.default) is int, p.name
        if p.kind == 'double_array':
            assert p.length == len(p.default)
            assert all(type(v) is float for v in p.default), p.name
        p.check(p.default)                               # every default is allowed


@pytest.mark.parametrize('path', sorted(RULES))
def test_ranges_read_from_rules_match_what_the_rules_accept(path):
    bounds = params.rule_bounds(path)
    assert bounds, f'rule of {path} could not be read'
    rule = RULES[path]
    if 'choices' in bounds:
        for c in bounds['choices']:
            rule(path, c)
        with pytest.raises(SceneError):
            rule(path, 'no_such_choice')
        return
    if bounds.get('finite'):
        rule(path, (1.0, -2.0, 3.0))
        with pytest.raises(SceneError):
            rule(path, (math.nan, 0.0, 0.0))
        return
    lo, hi = bounds['lo'], bounds['hi']
    step = max(1e-9, 1e-6 * (hi - lo))
    rule(path, hi)
    with pytest.raises(SceneError):
        rule(path, hi + max(step, 1.0 if isinstance(hi, int) else step))
    with pytest.raises(SceneError):
        rule(path, lo - max(step, 1.0 if isinstance(lo, int) else step))
    if bounds['lo_open']:
        with pytest.raises(SceneError):
            rule(path, lo)
    else:
        rule(path, lo)
    # the table carries the same bounds
    p = params.by_name()[path]
    assert (p.lo, p.hi, p.lo_open) == (lo, hi, bounds['lo_open'])


def test_rebuild_policy_is_the_groom_and_read_only_are_start_settings():
    table = params.by_name()
    rebuild = {n for n, p in table.items() if p.rebuild}
    # the groom, and the tracker mode (the blend's guides are some of the strands)
    assert rebuild == {n for n in table if n.startswith('groom.')} | {'tracking.mode'}
    assert {n for n, p in table.items() if p.read_only} == {'scene_file', 'warmup', 'use_tf',
                                                            'gravity_frame',
                                                            'pose_queue_depth',
                                                            'output_queue_depth'}
    assert not any(p.rebuild and p.read_only for p in table.values())
    for p in table.values():
        assert p.description and p.full_description().startswith(p.description)


def test_defaults_make_the_default_scene():
    s = make_settings({})
    assert s.scene == Scene()
    assert s.publish_rate_hz == 30.0 and s.marker_style == 'line_list'
    assert s.publish_period == pytest.approx(1 / 30)
    assert s.marker_lifetime == pytest.approx(3 / 30)
    values = s.values()
    assert set(values) == set(params.by_name())
    assert make_settings(values) == s


def test_valid_change_gives_a_new_snapshot_and_leaves_the_old_one():
    old = make_settings({})
    new, rebuild = apply_changes(old, {'solver.type': 'pbd', 'damping': 2})
    assert new.scene.solver.type == 'pbd'
    assert new.scene.damping == 2.0 and type(new.scene.damping) is float
    assert not rebuild
    assert old.scene.solver.type == 'ftl' and old.scene.damping == 1.0
    with pytest.raises((dataclasses.FrozenInstanceError, TypeError, AttributeError)):
        old.scene = new.scene
    with pytest.raises(TypeError):
        old.node['publish_rate_hz'] = 1.0


def test_shape_changes_ask_for_a_rebuild_only_when_the_value_changes():
    old = make_settings({})
    new, rebuild = apply_changes(old, {'groom.guides': 5})
    assert rebuild and new.scene.groom.guides == 5
    same, rebuild = apply_changes(old, {'groom.guides': old.scene.groom.guides})
    assert not rebuild and same == old
    _, rebuild = apply_changes(old, {'output.points_per_strand': 8, 'marker_width': 0.01})
    assert not rebuild


@pytest.mark.parametrize('change, words', [
    ({'groom.guides': 0}, ['groom.guides', '[1, 100000]']),
    ({'solver.type': 'rk4'}, ['solver.type', 'ftl', 'pbd', 'xpbd']),
    ({'solver.stiffness': 0.0}, ['solver.stiffness', '(0.0, 1.0]']),
    ({'damping': -1.0}, ['damping', '[0.0, 1000.0]']),
    ({'publish_rate_hz': 0.0}, ['publish_rate_hz', '[0.5, 1000.0]']),
    ({'marker_style': 'points'}, ['marker_style', 'line_list', 'line_strips']),
    ({'output_frame': 'map'}, ['output_frame', 'fixed', 'head']),
    ({'marker_color': [1.0, 0.0, 0.0]}, ['marker_color', '4 numbers']),
    ({'marker_color': [1.0, 0.0, 0.0, 2.0]}, ['marker_color', '[0.0, 1.0]']),
    ({'gravity': '[0.0, 0.0, -3]'}, ['gravity', '-3.0']),
    ({'gravity': [0.0, 0.0, math.inf]}, ['gravity']),
    ({'groom.guides': 2.5}, ['groom.guides', 'integer']),
    ({'groom.guides': True}, ['groom.guides', 'integer']),
    ({'tracking.collide': 1}, ['tracking.collide', 'true or false']),
    ({'groom.scalp.front_max_polar_deg': 150.0}, ['groom.scalp.front_max_polar_deg',
                                                  'groom.scalp.max_polar_deg']),
    ({'groom.guides': 100_000, 'groom.ghosts_per_guide': 100}, ['groom.ghosts_per_guide',
                                                                '2,000,000']),
    ({'warmup': False}, ['warmup', 'read-only']),
    ({'no.such': 1}, ['no.such', 'unknown']),
])
def test_invalid_change_is_rejected_with_its_reason_and_changes_nothing(change, words):
    old = make_settings({})
    before = old.values()
    with pytest.raises(ParamError) as err:
        apply_changes(old, change)
    for w in words:
        assert w in str(err.value), (w, str(err.value))
    assert err.value.name == words[0]
    assert old.values() == before


def test_read_only_may_be_set_at_start():
    s = make_settings({'warmup': False, 'scene_file': 'long_hair'})
    assert s.warmup is False and s.scene_file == 'long_hair'
    new, _ = apply_changes(s, {'warmup': True}, allow_read_only=True)
    assert new.warmup is True


def test_base_scene_supplies_the_scene_defaults():
    base = Scene.from_dict({'groom': {'guides': 7}, 'solver': {'type': 'pbd'}})
    table = params.by_name(base)
    assert table['groom.guides'].default == 7
    s = make_settings({'damping': 3.0}, base)
    assert s.scene.groom.guides == 7 and s.scene.solver.type == 'pbd'
    assert s.scene.damping == 3.0
    s2 = make_settings({'groom.guides': 9}, base)
    assert s2.scene.groom.guides == 9


def test_rendered_yaml_lists_every_parameter_with_typed_defaults():
    text = params.render_yaml()
    data = yaml.safe_load(text)
    flat = {}

    def walk(d, prefix):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, prefix + k + '.')
            else:
                flat[prefix + k] = v
    walk(data['/**']['ros__parameters'], '')
    table = params.by_name()
    assert set(flat) == set(table)
    for name, value in flat.items():
        p = table[name]
        if p.kind == 'double_array':
            assert tuple(value) == p.default
            assert all(type(v) is float for v in value), name
        else:
            assert value == p.default, name
            assert type(value) is type(p.default), name
    assert make_settings({k: v for k, v in flat.items()}).scene == Scene()


def test_shipped_config_is_the_rendered_table():
    with open(os.path.join(ROOT, 'config', 'hair_sim.yaml'), encoding='utf-8') as f:
        shipped = f.read()
    assert shipped == params.render_yaml(), \
        'config/hair_sim.yaml is out of date: python -m hair_tracking.core.params > ' \
        'config/hair_sim.yaml'


def test_docs_carry_the_current_table():
    with open(os.path.join(ROOT, 'docs', 'node.md'), encoding='utf-8') as f:
        doc = f.read()
    assert params.render_markdown() in doc, \
        'docs/node.md is out of date: paste python -m hair_tracking.core.params --markdown'
