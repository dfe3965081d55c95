"""The declarative parameter table (no ROS): the scene and the settings derived from its rows,
validation, snapshots."""
import dataclasses
import math
import re
import typing

import pytest

from hair_tracking.core.params import KINDS, ParamError
from hair_tracking.core.scene import Scene, scene_fields, scene_params, SceneError
from hair_tracking.core.scene_params import SCENE_PARAMS
from hair_tracking.core import param_table as params
from hair_tracking.core.param_table import NODE_PARAMS
from hair_tracking.output.settings import apply_changes, make_settings, Settings

#: The Python type a row's kind reads as.
TYPES = {'bool': bool, 'int': int, 'double': float, 'string': str, 'double_array': tuple}


def _nest(flat):
    """``{dotted name: value}`` as the nested mapping of a scene file."""
    out = {}
    for path, value in flat.items():
        node = out
        *sections, name = path.split('.')
        for part in sections:
            node = node.setdefault(part, {})
        node[name] = value
    return out


#: Other fields set while a field's range is checked, so that no cross-field rule interferes.
CONTEXT = {'groom.scalp.max_polar_deg': {'groom.scalp.front_max_polar_deg': 0.0},
           'groom.scalp.front_max_polar_deg': {'groom.scalp.max_polar_deg': 180.0}}


def test_every_scene_field_has_exactly_one_row_in_field_order():
    fields = scene_fields()
    assert [p.name for p in SCENE_PARAMS] == list(fields)
    names = [p.name for p in params.table()]
    assert len(names) == len(set(names)), 'duplicate parameter names'
    assert not set(p.name for p in NODE_PARAMS) & set(fields)
    assert all(p.scene for p in SCENE_PARAMS) and not any(p.scene for p in NODE_PARAMS)


def test_the_scene_dataclasses_take_their_defaults_and_types_from_the_rows():
    fields = scene_fields(Scene())
    for p in SCENE_PARAMS:
        assert fields[p.name] == p.default and type(fields[p.name]) is type(p.default), p.name
    hints = {}

    def walk(cls, prefix):
        for f in dataclasses.fields(cls):
            hint = typing.get_type_hints(cls)[f.name]
            if dataclasses.is_dataclass(hint):
                walk(hint, prefix + f.name + '.')
            else:
                hints[prefix + f.name] = typing.get_origin(hint) or hint
    walk(Scene, '')
    assert hints == {p.name: TYPES[p.kind] for p in SCENE_PARAMS}


def test_settings_has_one_typed_attribute_per_node_row():
    fields = dataclasses.fields(Settings)
    assert [f.name for f in fields] == ['scene'] + [p.name for p in NODE_PARAMS]
    hints = typing.get_type_hints(Settings)
    default = Settings()
    assert default.scene == Scene()
    for p in NODE_PARAMS:
        assert (typing.get_origin(hints[p.name]) or hints[p.name]) is TYPES[p.kind], p.name
        assert getattr(default, p.name) == p.default, p.name
    assert make_settings({}) == default


def test_rows_are_well_formed():
    for p in params.table():
        assert p.kind in KINDS
        if p.kind == 'double':
            assert type(p.default) is float, p.name      # 10.0, never 10 (rclpy types by value)
        if p.kind == 'int':
            assert type(p.default) is int, p.name
        if p.kind == 'double_array':
            assert p.length == len(p.default)
            assert all(type(v) is float for v in p.default), p.name
        if p.choices:
            assert p.kind == 'string' and p.lo is None and p.hi is None, p.name
        p.check(p.default)                               # every default is allowed


@pytest.mark.parametrize('row', [p for p in SCENE_PARAMS if p.lo is not None or p.choices],
                         ids=lambda p: p.name)
def test_the_scene_and_the_node_check_the_range_of_the_row(row):
    """Scene.from_dict (a scene file) and make_settings (the node) accept and refuse the same
    values: the ends of the row's range and just beyond them."""
    def accepted(value):
        element = (lambda v: (v,) * row.length) if row.kind == 'double_array' else (lambda v: v)
        values = dict(CONTEXT.get(row.name, {}), **{row.name: element(value)})
        try:
            Scene.from_dict(_nest(values))
            scene = True
        except SceneError as e:
            assert e.field == row.name
            scene = False
        try:
            make_settings(values)
            node = True
        except ParamError as e:
            assert e.name == row.name
            node = False
        return scene, node

    if row.choices:
        for c in row.choices:
            assert accepted(c) == (True, True)
        assert accepted('no_such_choice') == (False, False)
        return
    lo, hi = row.lo, row.hi
    step = 1 if row.kind == 'int' else max(1e-9, 1e-6 * (hi - lo))
    assert accepted(hi + step) == (False, False)
    assert accepted(lo - step) == (False, False)
    if row.magnitude_only:                    # the scene refuses the bounds themselves
        assert accepted(hi) == (False, False) and accepted(math.nan) == (False, False)
        assert accepted(hi / 2) == (True, True)
        return
    if row.kind != 'int':
        assert accepted(math.nan) == (False, False)
    assert accepted(hi) == (True, True)
    assert accepted(lo) == ((False, False) if row.lo_open else (True, True))


def test_rebuild_policy_is_the_groom_and_read_only_are_start_settings():
    table = params.by_name()
    rebuild = {n for n, p in table.items() if p.rebuild}
    # the groom, and the tracker mode (the blend's guides are some of the strands)
    assert rebuild == {n for n in table if n.startswith('groom.')} | {'tracking.mode'}
    assert {n for n, p in table.items() if p.read_only} == {'scene_file', 'warmup', 'use_tf',
                                                            'gravity_frame',
                                                            'pose_queue_depth',
                                                            'output_queue_depth', 'shards',
                                                            'publish_guide_state',
                                                            'people.source', 'people.max'}
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
    with pytest.raises(dataclasses.FrozenInstanceError):
        old.publish_rate_hz = 1.0


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
    ({'groom.gost_nodes': 8}, ['groom.gost_nodes', "unknown parameter; did you mean "
                                                   "'groom.ghost_nodes'?"]),
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
    assert {p.name: p.default for p in scene_params(base)} == scene_fields(base)
    s = make_settings({'damping': 3.0}, base)
    assert s.scene.groom.guides == 7 and s.scene.solver.type == 'pbd'
    assert s.scene.damping == 3.0
    s2 = make_settings({'groom.guides': 9}, base)
    assert s2.scene.groom.guides == 9


def test_a_typo_is_answered_alike_at_start_live_and_on_the_command_line(tmp_path, capsys):
    from hair_tracking.bags.cli import main
    hint = "groom.gost_nodes: unknown parameter; did you mean 'groom.ghost_nodes'?"
    with pytest.raises(ParamError, match=re.escape(hint)):
        make_settings({'groom.gost_nodes': 8})
    assert main(['run', '-o', str(tmp_path / 'out.mcap'), '--set', 'groom.gost_nodes=8']) == 2
    assert hint in capsys.readouterr().err
