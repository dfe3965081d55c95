"""The scene: the one description of what is simulated.

A scene is a tree of frozen dataclasses that loads from YAML (or a plain dict) and validates every
field against its allowed range.  The simulator is assembled from it, so a stage the scene does not
ask for is never built (see :mod:`hair_tracking.simulator`).

Units are SI (metres, seconds, radians unless a name says ``_deg``); the groom and the collider
are given in the head frame, which follows REP-103: x forward (out of the face), y left, z up,
origin at the head centre.
"""
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
import math
import os
from typing import Any, Dict, Tuple

import yaml


class SceneError(ValueError):
    """An invalid scene: ``field`` names the offending entry (dotted path)."""

    def __init__(self, field_name: str, message: str):
        super().__init__(f'{field_name}: {message}')
        self.field = field_name


SOLVERS = ('ftl', 'pbd', 'xpbd')
COLLIDERS = ('none', 'sphere', 'ellipsoid')
ELASTIC_MODES = ('kept', 'changed')
CURVES = ('none', 'bezier', 'catmull_rom')
TRACKING_MODES = ('paper', 'blend', 'turn')
#: Trackers whose guides are some of the strands, each strand placed once per read (no state).
GUIDES_AMONG_STRANDS = ('blend', 'turn')


@dataclass(frozen=True)
class ScalpSpec:
    """Where roots grow: a cap of an ellipsoid around the head centre (head frame)."""

    center: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    radii: Tuple[float, float, float] = (0.095, 0.08, 0.105)
    max_polar_deg: float = 105.0        # roots at polar angle (from +z) up to this ...
    front_max_polar_deg: float = 45.0   # ... but only up to this on the face side (x > 0)


@dataclass(frozen=True)
class GroomSpec:
    guides: int = 64                  # number of guide (target) strands
    ghosts_per_guide: int = 8         # ghost strands created per guide (total = guides * this)
    guide_nodes: int = 16             # nodes per guide strand (root included)
    ghost_nodes: int = 16             # nodes per ghost strand (may differ from guide_nodes)
    length: float = 0.25              # mean strand length [m]
    length_variation: float = 0.1     # relative spread of lengths: uniform in length*(1 +- this)
    droop: float = 0.6                # 0: straight along the scalp normal, 1: hangs down
    seed: int = 1                     # random seed of the groom
    scalp: ScalpSpec = field(default_factory=ScalpSpec)


@dataclass(frozen=True)
class ColliderSpec:
    shape: str = 'ellipsoid'          # none | sphere | ellipsoid
    center: Tuple[float, float, float] = (0.0, 0.0, 0.0)   # head frame [m]
    radius: float = 0.1               # sphere radius [m]
    radii: Tuple[float, float, float] = (0.095, 0.08, 0.105)  # ellipsoid semi-axes [m]
    margin: float = 0.004             # hair is kept this far outside the surface [m]
    friction: float = 0.3             # Coulomb-like tangential damping on contact, 0..1


@dataclass(frozen=True)
class SolverSpec:
    type: str = 'ftl'                 # ftl | pbd | xpbd
    dt: float = 1.0 / 240.0           # fixed substep [s]
    iterations: int = 4               # constraint iterations per substep (pbd, xpbd)
    stiffness: float = 1.0            # PBD stretch stiffness 0..1 (iteration dependent)
    compliance: float = 0.0           # XPBD stretch compliance [m/N]; 0 = rigid
    bend_stiffness: float = 0.3       # PBD/FTL bending stiffness 0..1
    bend_compliance: float = 1e-4     # XPBD bending compliance [m/N]
    ftl_damping: float = 0.9          # FTL velocity correction s_damp, 0..1
    max_substeps: int = 32            # cap of substeps per advance_to() call
    shock_propagation: float = 0.0    # 0..1: carry strands rigidly with fast head motion
    max_displacement: float = 0.05    # per-substep displacement clamp [m]; 0 disables
    settle_time: float = 0.5          # seconds simulated with a still head after a (re)set


@dataclass(frozen=True)
class TrackingSpec:
    mode: str = 'blend'               # blend, turn (guides among the strands) or paper
    blend_guides: int = 3             # blend: guides per ghost (nearest roots, Shepard weights)
    candidates: int = 8               # guides with nearest roots examined by equation (1)
    com_strength: float = 0.5         # centre-of-mass tracking strength per substep, 0..1
    offset_strength: float = 0.05     # pull of each ghost node to its rest offset, 0..1
    elastic_weight: bool = True       # W* of equation (4)
    elastic_mode: str = 'kept'        # kept: W* = 0.5 v.v0 + 0.5 ; changed: 1 - W*
    tip_weight: float = 0.3           # w_tip at the tip (grows linearly from 0 at the root)
    com_weight: float = 0.3           # w_com per metre of distance from the group centre / length
    max_weight: float = 1.5           # clamp of W* + w_tip + w_com (energy safety)
    length_restore: bool = True       # one Follow-The-Leader pass on ghosts
    collide: bool = True              # ghosts collide with the head collider (if any)
    spread: float = 0.0               # HairControl spread control strength 0..1 (0 = off)
    spread_target: float = 1.0        # target variance as a multiple of the initial variance
    every_substep: bool = True        # track after every guide substep (false: once per pose)


@dataclass(frozen=True)
class HeadTrackSpec:
    teleport_distance: float = 0.5    # a jump farther than this [m] resets the hair
    teleport_angle_deg: float = 90.0  # ... or a rotation larger than this between samples
    max_gap: float = 0.5              # samples farther apart than this [s] count as a jump too


@dataclass(frozen=True)
class OutputSpec:
    curve: str = 'none'               # none | bezier | catmull_rom
    points_per_strand: int = 16       # output points per strand when curve != none


@dataclass(frozen=True)
class Scene:
    groom: GroomSpec = field(default_factory=GroomSpec)
    collider: ColliderSpec = field(default_factory=ColliderSpec)
    solver: SolverSpec = field(default_factory=SolverSpec)
    tracking: TrackingSpec = field(default_factory=TrackingSpec)
    head_track: HeadTrackSpec = field(default_factory=HeadTrackSpec)
    output: OutputSpec = field(default_factory=OutputSpec)
    gravity: Tuple[float, float, float] = (0.0, 0.0, -9.81)   # world frame [m/s^2]
    damping: float = 1.0              # velocity damping rate [1/s]

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
        for path, value in _walk(self):
            rule = RULES.get(path)
            if rule is not None:
                rule(path, value)
        g = self.groom
        if g.guides * g.ghosts_per_guide > 2_000_000:
            raise SceneError('groom.ghosts_per_guide',
                             'guides * ghosts_per_guide must be at most 2,000,000')
        if g.scalp.front_max_polar_deg > g.scalp.max_polar_deg:
            raise SceneError('groom.scalp.front_max_polar_deg',
                             'must not exceed groom.scalp.max_polar_deg')


def replace_section(scene: Scene, section: str, **changes: Any) -> Scene:
    """A copy of ``scene`` with fields of one section replaced, validated."""
    new = replace(scene, **{section: replace(getattr(scene, section), **changes)})
    new.validate()
    return new


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
            kwargs[name] = _coerce(path, value, default)
    return cls(**kwargs)


def _coerce(path, value, default):
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise SceneError(path, f'must be true or false, got {value!r}')
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                float(value) != int(value):
            raise SceneError(path, f'must be an integer, got {value!r}')
        return int(value)
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise SceneError(path, f'must be a number, got {value!r}')
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise SceneError(path, f'must be a string, got {value!r}')
        return value
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or len(value) != len(default) or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
            raise SceneError(path, f'must be a list of {len(default)} numbers, got {value!r}')
        return tuple(float(v) for v in value)
    raise SceneError(path, 'unsupported field type')  # pragma: no cover


def _walk(obj, prefix=''):
    for f in fields(obj):
        value = getattr(obj, f.name)
        if is_dataclass(value):
            yield from _walk(value, prefix + f.name + '.')
        else:
            yield prefix + f.name, value


def _range(lo, hi, lo_open=False):
    def check(path, value):
        vals = value if isinstance(value, tuple) else (value,)
        for v in vals:
            if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
                bracket = '(' if lo_open else '['
                raise SceneError(path, f'{value!r} is outside the allowed range '
                                       f'{bracket}{lo}, {hi}]')
    return check


def _choice(options):
    def check(path, value):
        if value not in options:
            raise SceneError(path, f'{value!r} is not one of {", ".join(options)}')
    return check


def _finite(path, value):
    vals = value if isinstance(value, tuple) else (value,)
    if not all(math.isfinite(v) and abs(v) < 1e4 for v in vals):
        raise SceneError(path, f'{value!r} must be finite numbers of magnitude below 1e4')


#: Allowed values of every constrained scene field (dotted path -> check).
RULES = {
    'groom.guides': _range(1, 100_000),
    'groom.ghosts_per_guide': _range(0, 10_000),
    'groom.guide_nodes': _range(3, 256),
    'groom.ghost_nodes': _range(3, 256),
    'groom.length': _range(0.001, 5.0),
    'groom.length_variation': _range(0.0, 0.9),
    'groom.droop': _range(0.0, 1.0),
    'groom.seed': _range(0, 2**31 - 1),
    'groom.scalp.center': _range(-1.0, 1.0),
    'groom.scalp.radii': _range(0.01, 1.0),
    'groom.scalp.max_polar_deg': _range(1.0, 180.0),
    'groom.scalp.front_max_polar_deg': _range(0.0, 180.0),
    'collider.shape': _choice(COLLIDERS),
    'collider.center': _range(-1.0, 1.0),
    'collider.radius': _range(0.01, 1.0),
    'collider.radii': _range(0.01, 1.0),
    'collider.margin': _range(0.0, 0.1),
    'collider.friction': _range(0.0, 1.0),
    'solver.type': _choice(SOLVERS),
    'solver.dt': _range(1e-5, 0.1),
    'solver.iterations': _range(1, 1000),
    'solver.stiffness': _range(0.0, 1.0, lo_open=True),
    'solver.compliance': _range(0.0, 1.0),
    'solver.bend_stiffness': _range(0.0, 1.0),
    'solver.bend_compliance': _range(0.0, 1e3),
    'solver.ftl_damping': _range(0.0, 1.0),
    'solver.max_substeps': _range(1, 10_000),
    'solver.shock_propagation': _range(0.0, 1.0),
    'solver.max_displacement': _range(0.0, 10.0),
    'solver.settle_time': _range(0.0, 60.0),
    'tracking.mode': _choice(TRACKING_MODES),
    'tracking.blend_guides': _range(1, 8),
    'tracking.candidates': _range(1, 1024),
    'tracking.com_strength': _range(0.0, 1.0),
    'tracking.offset_strength': _range(0.0, 1.0),
    'tracking.elastic_mode': _choice(ELASTIC_MODES),
    'tracking.tip_weight': _range(0.0, 5.0),
    'tracking.com_weight': _range(0.0, 50.0),
    'tracking.max_weight': _range(0.0, 10.0),
    'tracking.spread': _range(0.0, 1.0),
    'tracking.spread_target': _range(0.01, 100.0),
    'head_track.teleport_distance': _range(0.0, 1e3, lo_open=True),
    'head_track.teleport_angle_deg': _range(0.0, 180.0, lo_open=True),
    'head_track.max_gap': _range(0.0, 3600.0, lo_open=True),
    'output.curve': _choice(CURVES),
    'output.points_per_strand': _range(2, 1024),
    'gravity': _finite,
    'damping': _range(0.0, 1000.0),
}
