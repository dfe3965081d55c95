"""The scene: the one description of what is simulated.

A scene is a tree of frozen dataclasses that loads from YAML (or a plain dict) and validates every
field against its allowed values.  Each field's type, default, range and description are a row of
the scene's parameter table (:mod:`hair_tracking.core.scene_params`): the dataclasses below take
their defaults from the rows, and :meth:`Scene.validate` checks every field with its row.  The
simulator is assembled from a scene, so a stage the scene does not ask for is never built (see
:mod:`hair_tracking.simulator`).

Units are SI (metres, seconds, radians unless a name says ``_deg``); the groom and the collider
are given in the head frame, which follows REP-103: x forward (out of the face), y left, z up,
origin at the head centre.
"""
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
import math
import os
from typing import Any, Dict, Optional, Tuple

import yaml

from hair_tracking.core.params import Param
from hair_tracking.core.scene_params import SCENE_PARAMS, SCENE_ROWS

#: Trackers whose guides are some of the strands, each strand placed once per read (no state).
GUIDES_AMONG_STRANDS = ('blend', 'turn')


class SceneError(ValueError):
    """An invalid scene: ``field`` names the offending entry (dotted path)."""

    def __init__(self, field_name: str, message: str):
        super().__init__(f'{field_name}: {message}')
        self.field = field_name


def _section(prefix: str):
    """Class decorator: a frozen dataclass whose fields are the annotated names, each defaulting
    to its row's default (``prefix.name`` in the scene's table), or to a fresh instance where
    the annotation is a section itself."""
    def make(cls):
        for name, kind in cls.__annotations__.items():
            if is_dataclass(kind):
                setattr(cls, name, field(default_factory=kind))
            else:
                setattr(cls, name, SCENE_ROWS[prefix + name].default)
        return dataclass(frozen=True)(cls)
    return make


@_section('groom.scalp.')
class ScalpSpec:
    """Where roots grow: a cap of an ellipsoid around the head centre (head frame)."""

    center: Tuple[float, float, float]
    radii: Tuple[float, float, float]
    max_polar_deg: float
    front_max_polar_deg: float


@_section('groom.')
class GroomSpec:
    """The strands: how many, how long, their rest shape and where their roots grow; or a groom
    file to import (``file``) and how to put it on the head."""

    guides: int
    ghosts_per_guide: int
    guide_nodes: int
    ghost_nodes: int
    detail_nodes: int
    length: float
    length_variation: float
    droop: float
    seed: int
    file: str
    max_strands: int
    units: str
    up_axis: str
    face_axis: str
    fit: str
    file_rotation_deg: Tuple[float, float, float]
    file_offset: Tuple[float, float, float]
    scalp: ScalpSpec


@_section('collider.')
class ColliderSpec:
    """The head collider (head frame)."""

    shape: str
    center: Tuple[float, float, float]
    radius: float
    radii: Tuple[float, float, float]
    margin: float
    friction: float


@_section('body.')
class BodySpec:
    """A bust below the head (colliders.body), on a TF frame or on the neck frame the head
    pose gives."""

    bust: bool
    height: float
    frame: str
    margin: float
    friction: float
    max_push_speed: float


@_section('colliders.extra_1.')
class ColliderSlotSpec:
    """One further collider on a frame (docs/colliders.md); every slot has the same rows."""

    shape: str
    frame: str
    center: Tuple[float, float, float]
    rotation: Tuple[float, float, float, float]
    radius: float
    half_length: float
    radii: Tuple[float, float, float]
    margin: float
    friction: float


@dataclass(frozen=True)
class CollidersSpec:
    """Further colliders, each on a frame: the slots of
    :data:`~hair_tracking.core.scene_params.COLLIDER_SLOTS`."""

    extra_1: ColliderSlotSpec = field(default_factory=ColliderSlotSpec)
    extra_2: ColliderSlotSpec = field(default_factory=ColliderSlotSpec)
    extra_3: ColliderSlotSpec = field(default_factory=ColliderSlotSpec)
    extra_4: ColliderSlotSpec = field(default_factory=ColliderSlotSpec)

    def used(self) -> Tuple[Tuple[str, ColliderSlotSpec], ...]:
        """``(slot, spec)`` of every slot whose shape is not none, in slot order."""
        return tuple((f.name, getattr(self, f.name)) for f in fields(self)
                     if getattr(self, f.name).shape != 'none')


@_section('solver.')
class SolverSpec:
    """The guide solver and its time step."""

    type: str
    dt: float
    iterations: int
    stiffness: float
    compliance: float
    bend_stiffness: float
    bend_compliance: float
    ftl_damping: float
    max_substeps: int
    shock_propagation: float
    shape_stiffness: float
    max_displacement: float
    max_strain: float
    settle_time: float
    settle_speed: float


@_section('volume.')
class VolumeSpec:
    """Hair-hair interaction through a grid on the head (:mod:`hair_tracking.guides.volume`)."""

    enabled: bool
    cell_size: float
    pressure: float
    friction: float


@_section('tracking.')
class TrackingSpec:
    """How the ghosts follow the guides."""

    mode: str
    blend_guides: int
    candidates: int
    com_strength: float
    offset_strength: float
    elastic_weight: bool
    elastic_mode: str
    tip_weight: float
    com_weight: float
    max_weight: float
    length_restore: bool
    collide: bool
    spread: float
    spread_target: float
    every_substep: bool


@_section('head_track.')
class HeadTrackSpec:
    """When the head pose stream counts as a jump that resets the hair."""

    teleport_distance: float
    teleport_angle_deg: float
    max_gap: float


@_section('people.')
class PeopleSpec:
    """Whose hair is simulated: one head, or every face REP-155 perception tracks."""

    source: str
    sellion_offset: Tuple[float, float, float]
    lost_timeout_s: float
    max: int


@_section('output.')
class OutputSpec:
    """The published strands."""

    curve: str
    points_per_strand: int


@_section('')
class Scene:
    """What is simulated: the sections above, gravity (world frame) and damping."""

    groom: GroomSpec
    collider: ColliderSpec
    body: BodySpec
    colliders: CollidersSpec
    solver: SolverSpec
    volume: VolumeSpec
    tracking: TrackingSpec
    head_track: HeadTrackSpec
    people: PeopleSpec
    output: OutputSpec
    gravity: Tuple[float, float, float]
    damping: float

    # ----------------------------------------------------------------- building
    @staticmethod
    def from_dict(data: Dict[str, Any]) -> 'Scene':
        """Build and validate a scene from nested dicts; unknown keys are errors."""
        scene = _build(Scene, data or {}, '')
        scene.validate()
        return scene

    @staticmethod
    def from_yaml(path: str) -> 'Scene':
        if not os.path.isfile(path):
            raise SceneError('scene', f'file not found: {path}')
        with open(path, encoding='utf-8') as f:
            try:
                data = yaml.safe_load(f)
            except yaml.YAMLError as e:
                raise SceneError('scene', f'not valid YAML ({path}): {e}') from None
        if data is not None and not isinstance(data, dict):
            raise SceneError('scene', f'{path} must hold a mapping at the top level')
        return Scene.from_dict(data or {})

    def to_dict(self) -> Dict[str, Any]:
        return asdict(self)

    def with_changes(self, **dotted: Any) -> 'Scene':
        """A copy with ``section__field=value`` (or top-level ``field=value``) changed."""
        data = self.to_dict()
        for key, value in dotted.items():
            node = data
            parts = key.split('__')
            for p in parts[:-1]:
                node = node[p]
            node[parts[-1]] = value
        return Scene.from_dict(data)

    # --------------------------------------------------------------- validation
    def validate(self) -> None:
        """SceneError naming the first field its row does not allow, or a broken cross-field
        rule."""
        for path, value in scene_fields(self).items():
            problem = SCENE_ROWS[path].problem(value, scene_words=True)
            if problem:
                raise SceneError(path, problem)
        g = self.groom
        if g.guides * g.ghosts_per_guide > 2_000_000:
            raise SceneError('groom.ghosts_per_guide',
                             'guides * ghosts_per_guide must be at most 2,000,000')
        if 'auto' not in (g.up_axis, g.face_axis) and g.up_axis[-1] == g.face_axis[-1]:
            raise SceneError('groom.face_axis',
                             f'must lie across groom.up_axis {g.up_axis}, got {g.face_axis}')
        if g.detail_nodes == 1:
            raise SceneError('groom.detail_nodes', 'must be 0 (off) or at least 2, got 1')
        if g.scalp.front_max_polar_deg > g.scalp.max_polar_deg:
            raise SceneError('groom.scalp.front_max_polar_deg',
                             'must not exceed groom.scalp.max_polar_deg')
        for slot, c in self.colliders.used():
            norm = math.sqrt(sum(v * v for v in c.rotation))
            if not 0.999 < norm < 1.001:
                raise SceneError(f'colliders.{slot}.rotation',
                                 f'must be a unit quaternion (x, y, z, w), got {c.rotation}')
            if not c.frame.strip('/') or c.frame.strip('/') == 'torso':
                raise SceneError(f'colliders.{slot}.frame',
                                 'must be head, fixed or a TF frame name (torso is the name the '
                                 f'bust\'s frame has inside the simulator), got {c.frame!r}')


def scene_fields(scene: Optional[Scene] = None) -> Dict[str, Any]:
    """Every leaf field of ``scene`` (default: ``Scene()``) as ``{dotted path: value}``, in the
    order of the fields."""
    out: Dict[str, Any] = {}

    def walk(obj, prefix):
        for f in fields(obj):
            value = getattr(obj, f.name)
            if is_dataclass(value):
                walk(value, prefix + f.name + '.')
            else:
                out[prefix + f.name] = value
    walk(scene if scene is not None else Scene(), '')
    return out


def scene_params(base: Optional[Scene] = None) -> Tuple[Param, ...]:
    """The scene's rows; with ``base`` (a scene file) its values are the defaults."""
    if base is None:
        return SCENE_PARAMS
    values = scene_fields(base)
    return tuple(replace(p, default=values[p.name]) for p in SCENE_PARAMS)


# ------------------------------------------------------------------ internals
def _build(cls, data, prefix):
    if not isinstance(data, dict):
        raise SceneError(prefix.rstrip('.') or 'scene', 'must be a mapping')
    known = {f.name: f for f in fields(cls)}
    for key in data:
        if key not in known:
            raise SceneError(prefix + str(key),
                             f'unknown field (allowed: {", ".join(sorted(known))})')
    kwargs = {}
    for name, f in known.items():
        if name not in data:
            continue
        value = data[name]
        path = prefix + name
        default = getattr(cls(), name)
        if is_dataclass(default):
            kwargs[name] = _build(type(default), value, path + '.')
        else:
            kwargs[name] = _coerce(path, value, SCENE_ROWS[path])
    return cls(**kwargs)


def _coerce(path: str, value: Any, row: Param) -> Any:
    """``value`` of a scene file as the Python type of the field ``row`` describes (SceneError
    if it is not one); a number with an integral value counts as an integer."""
    kind, length = row.kind, row.length
    if kind == 'bool':
        if not isinstance(value, bool):
            raise SceneError(path, f'must be true or false, got {value!r}')
        return value
    if kind == 'int':
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value) or float(value) != int(value):
            raise SceneError(path, f'must be an integer, got {value!r}')
        return int(value)
    if kind == 'double':
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(path, f'must be a number, got {value!r}')
        return float(value)
    if kind == 'string':
        if not isinstance(value, str):
            raise SceneError(path, f'must be a string, got {value!r}')
        return value
    if kind == 'double_array':
        if not isinstance(value, (list, tuple)) or len(value) != length or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
            raise SceneError(path, f'must be a list of {length} numbers, got {value!r}')
        return tuple(float(v) for v in value)
    raise SceneError(path, 'unsupported field type')  # pragma: no cover
