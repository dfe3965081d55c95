"""The node's parameters: one declarative table, validation, and the frozen settings snapshot.

Every scene field of :class:`hair_tracking.core.scene.Scene` is a ROS parameter under its dotted
path (``groom.guides``, ``solver.type``, ``gravity`` ...), next to the node's own runtime settings
(``publish_rate_hz``, ``marker_style`` ...).  The table below is the single place that says, for
each parameter, its type, default, description, unit, allowed values, whether it is read-only and
whether a change rebuilds the hair.  Defaults and ranges of scene fields are *read from the scene
module* (``Scene()`` and ``scene.RULES``), so the table cannot drift from it; a test checks that
every scene field has a parameter and every scene parameter a field.

The ROS shell (:mod:`hair_tracking.ros.node`) declares one ROS parameter per :class:`Param` (with a
``ParameterDescriptor`` built from it), validates a candidate change with :func:`apply_changes`
(which builds and validates the whole scene, so cross-field rules hold too) and hands the
resulting :class:`Settings` snapshot to the next simulation step.  This module imports no ROS
package: it is plain data and checks, testable without DDS.

Units are SI (metres, seconds, radians unless a name says ``_deg``); frames follow REP-103.
"""
from dataclasses import dataclass, field, fields, is_dataclass
import inspect
import math
import textwrap
from types import MappingProxyType
from typing import Any, Dict, Iterable, Mapping, Optional, Tuple

import yaml

from hair_tracking.core.scene import RULES, Scene, SceneError

NODE_NAME = 'hair_sim'

KINDS = ('bool', 'int', 'double', 'string', 'double_array')
MARKER_STYLES = ('line_list', 'line_strips')
OUTPUT_FRAMES = ('fixed', 'head')
CLOUD_FIELDS = ('xyz_strand_rgb', 'xyz_strand', 'xyz_rgb', 'xyz')


class ParamError(ValueError):
    """A rejected parameter value; ``name`` is the parameter, the message says what is allowed."""

    def __init__(self, name: str, message: str):
        super().__init__(f'{name}: {message}')
        self.name = name


@dataclass(frozen=True)
class Param:
    """One parameter of the node.

    ``lo``/``hi`` bound a number (each element of an array); ``lo_open`` excludes ``lo`` itself.
    ``choices`` lists the allowed strings.  ``length`` is the fixed length of an array.
    ``read_only`` parameters are set at start (launch file, params file, ``-p``) and never change;
    a change of a ``rebuild`` parameter rebuilds the hair in its rest shape at the current head
    pose (strand counts, nodes, groom shape).  ``scene`` marks a scene field (``name`` is its
    dotted path in :class:`Scene`).
    """

    name: str
    kind: str
    default: Any
    description: str
    unit: str = ''
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    choices: Tuple[str, ...] = ()
    length: Optional[int] = None
    read_only: bool = False
    rebuild: bool = False
    scene: bool = False

    # -------------------------------------------------------------- describing
    def range_text(self) -> str:
        """The allowed values in words, e.g. ``[1, 100000]``, ``one of: ftl, pbd, xpbd``."""
        if self.choices:
            return 'one of: ' + ', '.join(self.choices)
        if self.lo is None and self.hi is None:
            if self.kind == 'double_array':
                return f'{self.length} finite numbers'
            return ''
        lo = _num_text(self.lo, self.kind)
        hi = _num_text(self.hi, self.kind)
        text = ('(' if self.lo_open else '[') + f'{lo}, {hi}]'
        if self.kind == 'double_array':
            return f'{self.length} numbers, each in {text}'
        return text

    def full_description(self) -> str:
        """Description with unit and the consequence of a change (for the ROS descriptor)."""
        text = self.description
        if self.unit:
            text += f' [{self.unit}]'
        if self.read_only:
            text += ' (read-only: set at start)'
        elif self.rebuild:
            text += ' (a change rebuilds the hair at the current head pose)'
        return text

    # -------------------------------------------------------------- checking
    def coerce(self, value: Any) -> Any:
        """``value`` as this parameter's Python type, or ParamError naming the allowed values.

        Integers are accepted for doubles (``-3`` becomes ``-3.0``); bools are never numbers.
        Arrays come back as tuples of floats.
        """
        kind = self.kind
        if kind == 'bool':
            if isinstance(value, bool):
                return value
            raise ParamError(self.name, f'must be true or false, got {value!r}')
        if kind == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ParamError(self.name, f'must be an integer in {self.range_text()}, '
                                            f'got {value!r}')
            value = int(value)
        elif kind == 'double':
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParamError(self.name, f'must be a number in {self.range_text()}, '
                                            f'got {value!r}')
            value = float(value)
        elif kind == 'string':
            if not isinstance(value, str):
                raise ParamError(self.name, f'must be a string, got {value!r}')
        elif kind == 'double_array':
            if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
                raise ParamError(self.name, f'must be a list of {self.range_text()} '
                                            f'(write -3.0, not -3), got {value!r}')
            items = list(value)
            if len(items) != self.length or any(
                    isinstance(v, bool) or not isinstance(v, (int, float)) for v in items):
                raise ParamError(self.name, f'must be a list of {self.range_text()}, '
                                            f'got {value!r}')
            value = tuple(float(v) for v in items)
        self.check(value)
        return value

    def check(self, value: Any) -> None:
        """Range/choice check of an already typed value (ParamError on failure)."""
        if self.choices and value not in self.choices:
            raise ParamError(self.name, f'{value!r} is not {self.range_text()}')
        if self.kind in ('int', 'double', 'double_array'):
            vals = value if isinstance(value, tuple) else (value,)
            for v in vals:
                bad = not math.isfinite(v)
                if self.lo is not None:
                    bad = bad or v < self.lo or (self.lo_open and v == self.lo)
                if self.hi is not None:
                    bad = bad or v > self.hi
                if bad:
                    raise ParamError(self.name, f'{value!r} is outside the allowed range '
                                                f'{self.range_text()}')


def _num_text(v, kind):
    if v is None:
        return 'inf'
    if kind == 'int':
        return str(int(v))
    return repr(float(v))


# ------------------------------------------------------------------ scene fields
# Every scene field: (description, unit, rebuild).  Defaults, types and ranges come from the scene
# module.  All groom fields rebuild the hair (they change strand counts, node counts or the rest
# shape); everything else is applied live to the running hair.
_SCENE_DOCS: Dict[str, Tuple[str, str, bool]] = {
    'groom.guides': ('number of guide strands simulated with PBD/FTL', '', True),
    'groom.ghosts_per_guide': ('ghost strands created per guide (total = guides * this); '
                               '0 shows the guides themselves', '', True),
    'groom.guide_nodes': ('nodes per guide strand, root included', '', True),
    'groom.ghost_nodes': ('nodes per ghost strand, root included', '', True),
    'groom.length': ('mean strand length', 'm', True),
    'groom.length_variation': ('relative spread of strand lengths: uniform in '
                               'length * (1 +- this)', '', True),
    'groom.droop': ('rest shape: 0 straight along the scalp normal, 1 hanging down', '', True),
    'groom.seed': ('random seed of the groom', '', True),
    'groom.scalp.center': ('centre of the scalp ellipsoid, head frame', 'm', True),
    'groom.scalp.radii': ('semi-axes of the scalp ellipsoid, head frame', 'm', True),
    'groom.scalp.max_polar_deg': ('roots grow up to this polar angle from +z', 'deg', True),
    'groom.scalp.front_max_polar_deg': ('... but only up to this on the face side (x > 0); '
                                        'at most groom.scalp.max_polar_deg', 'deg', True),
    'collider.shape': ('head collider shape', '', False),
    'collider.center': ('collider centre, head frame', 'm', False),
    'collider.radius': ('sphere radius', 'm', False),
    'collider.radii': ('ellipsoid semi-axes, head frame', 'm', False),
    'collider.margin': ('hair is kept this far outside the collider surface', 'm', False),
    'collider.friction': ('tangential damping on contact, 0 none .. 1 sticks', '', False),
    'solver.type': ('guide solver: ftl (Follow-The-Leader), pbd, xpbd', '', False),
    'solver.dt': ('fixed simulation substep', 's', False),
    'solver.iterations': ('constraint iterations per substep (pbd, xpbd)', '', False),
    'solver.stiffness': ('PBD stretch stiffness (iteration dependent)', '', False),
    'solver.compliance': ('XPBD stretch compliance; 0 is rigid', 'm/N', False),
    'solver.bend_stiffness': ('PBD/FTL bending stiffness', '', False),
    'solver.bend_compliance': ('XPBD bending compliance', 'm/N', False),
    'solver.ftl_damping': ('FTL velocity correction s_damp', '', False),
    'solver.max_substeps': ('cap of substeps per pose; further due substeps are dropped '
                            '(counted in diagnostics)', '', False),
    'solver.shock_propagation': ('carry strands rigidly with fast head motion, 0 off .. 1',
                                 '', False),
    'solver.max_displacement': ('per-substep displacement clamp; 0 disables', 'm', False),
    'solver.settle_time': ('time simulated with a still head after a (re)build or reset',
                           's', False),
    'tracking.mode': ('ghost tracker: paper (Park & Kim: velocity transfer, weights (4)-(5), '
                      'centre-of-mass tracking, every substep) or blend (each ghost the '
                      'blended points of its tracking.blend_guides nearest guides, chosen among '
                      'the strands, plus its rest offset carried by the head, once per frame; '
                      'see docs/blend.md) or turn (each ghost segment turned as the matching '
                      'segment of the guide with the nearest root, once per frame; exact '
                      'lengths; see docs/turn.md)', '', True),
    'tracking.blend_guides': ('blend: guides blended per ghost (nearest roots)', '', False),
    'tracking.candidates': ('guides with the nearest roots examined per ghost', '', False),
    'tracking.com_strength': ('centre-of-mass tracking strength per substep', '', False),
    'tracking.offset_strength': ('pull of each ghost node to its rest offset', '', False),
    'tracking.elastic_weight': ('use the elastic weight W* (equation 4 of Park & Kim)',
                                '', False),
    'tracking.elastic_mode': ('elastic weight mode: kept (W* = 0.5 v.v0 + 0.5) or '
                              'changed (1 - W*)', '', False),
    'tracking.tip_weight': ('tip weight w_tip (grows linearly from 0 at the root)', '', False),
    'tracking.com_weight': ('centre-of-mass weight w_com per metre of distance / length',
                            '', False),
    'tracking.max_weight': ('clamp of W* + w_tip + w_com (energy safety)', '', False),
    'tracking.length_restore': ('one Follow-The-Leader pass on the ghosts', '', False),
    'tracking.collide': ('ghosts collide with the head collider', '', False),
    'tracking.spread': ('HairControl spread control strength, 0 off', '', False),
    'tracking.spread_target': ('target spread as a multiple of the initial variance', '', False),
    'tracking.every_substep': ('paper: track the ghosts after every guide substep; false '
                               'tracks them once per head pose over all its substeps (2-4x '
                               'cheaper; passes the stability matrix too)', '', False),
    'head_track.teleport_distance': ('a head jump farther than this resets the hair', 'm',
                                     False),
    'head_track.teleport_angle_deg': ('... or a turn larger than this between two poses',
                                      'deg', False),
    'head_track.max_gap': ('poses farther apart than this count as a jump too', 's', False),
    'output.curve': ('smoothing of the output strands', '', False),
    'output.points_per_strand': ('output points per strand when output.curve is not none',
                                 '', False),
    'gravity': ('gravity, in the fixed frame of the head pose (or in gravity_frame)', 'm/s^2',
                False),
    'damping': ('velocity damping rate', '1/s', False),
}


def scene_fields(scene: Optional[Scene] = None) -> Dict[str, Any]:
    """Every leaf field of ``scene`` (default: ``Scene()``) as ``{dotted path: value}``."""
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


def rule_bounds(path: str) -> Dict[str, Any]:
    """The allowed values of a scene field read from ``scene.RULES``.

    Returns ``{}`` (no rule), ``{'choices': (...)}`` or ``{'lo', 'hi', 'lo_open'}``; for a rule
    that only asks for finite numbers (``gravity``) ``{'finite': True}``.  The rules are closures
    made by ``scene._range``/``scene._choice``; their captured values are read with
    :func:`inspect.getclosurevars`, so the range lives in one place only.
    """
    rule = RULES.get(path)
    if rule is None:
        return {}
    captured = inspect.getclosurevars(rule).nonlocals
    if 'options' in captured:
        return {'choices': tuple(captured['options'])}
    if 'lo' in captured and 'hi' in captured:
        return {'lo': captured['lo'], 'hi': captured['hi'],
                'lo_open': bool(captured.get('lo_open', False))}
    return {'finite': True}


def _kind_of(value: Any) -> str:
    if isinstance(value, bool):
        return 'bool'
    if isinstance(value, int):
        return 'int'
    if isinstance(value, float):
        return 'double'
    if isinstance(value, str):
        return 'string'
    if isinstance(value, tuple):
        return 'double_array'
    raise TypeError(f'no parameter kind for {value!r}')  # pragma: no cover


def scene_params(base: Optional[Scene] = None) -> Tuple[Param, ...]:
    """One :class:`Param` per scene field; defaults from ``base`` (default: ``Scene()``)."""
    out = []
    for path, value in scene_fields(base).items():
        if path not in _SCENE_DOCS:
            raise KeyError(f'scene field {path} has no entry in params._SCENE_DOCS')
        desc, unit, rebuild = _SCENE_DOCS[path]
        kind = _kind_of(value)
        bounds = rule_bounds(path)
        kw: Dict[str, Any] = {}
        if 'choices' in bounds:
            kw['choices'] = bounds['choices']
        elif 'lo' in bounds:
            kw.update(lo=bounds['lo'], hi=bounds['hi'], lo_open=bounds['lo_open'])
        elif bounds.get('finite'):
            kw.update(lo=-1e4, hi=1e4)
        if kind == 'double_array':
            kw['length'] = len(value)
        out.append(Param(name=path, kind=kind, default=value, description=desc, unit=unit,
                         rebuild=rebuild, scene=True, **kw))
    return tuple(out)


# ------------------------------------------------------------------ node settings
NODE_PARAMS: Tuple[Param, ...] = (
    Param('scene_file', 'string', '',
          'optional scene YAML (path or preset name such as long_hair) used as the base; '
          'scene parameters given to the node override its values', read_only=True),
    Param('warmup', 'bool', True,
          'compile (or load from the on-disk cache) every numba kernel and encoder before '
          'subscribing, so the first frames are not late', read_only=True),
    Param('use_tf', 'bool', False,
          'also take the head pose from /tf (needs tf2_msgs), selected by head_frame or '
          'head_frame_prefix, and composed with its parents from /tf_static and /tf up to the '
          'root of its tree (the frame the hair is simulated and published in)',
          read_only=True),
    Param('publish_tf', 'bool', True,
          'broadcast each head pose on /tf as robot_state_publisher does: parent the pose\'s '
          'frame_id (else fixed_frame), child its child_frame_id (else head_frame), so rviz '
          'resolves output_frame head and the head marker; poses taken from /tf are not sent '
          'again'),
    Param('gravity_frame', 'string', '',
          'frame in which gravity is given; empty: the fixed frame of the head pose. Else '
          'gravity is rotated into the pose\'s frame through /tf_static and /tf (e.g. world '
          'when a tracker publishes in a camera optical frame, whose z is the viewing '
          'direction)', read_only=True),
    Param('pose_queue_depth', 'int', 1,
          'queue depth of the pose subscriptions (sensor-data QoS keeps the newest ones): 1 '
          'always simulates the newest pose, so a node that falls behind is at most one pose '
          'late (the head between poses is interpolated, no simulated time is lost); more '
          'keeps every pose of a burst, at the cost of latency when the node is behind (the '
          'sensor-data default is 5)', lo=1, hi=1000, read_only=True),
    Param('output_queue_depth', 'int', 2,
          'history depth of the reliable hair outputs: 2 keeps latency low for viewers; a '
          'recorder that must not miss a frame under load wants more', lo=1, hi=1000,
          read_only=True),
    Param('head_frame', 'string', 'head',
          'name of the head frame: the /tf child frame that is the head, and the frame_id of '
          'the output when output_frame is head and the pose message names no child frame'),
    Param('head_frame_prefix', 'string', '',
          'if set, the first /tf child frame starting with this prefix is the head (REP-155 '
          'face trackers publish face_<id>); kept until it goes stale'),
    Param('fixed_frame', 'string', 'world',
          'frame_id of the output when output_frame is fixed and the pose message has an '
          'empty frame_id'),
    Param('output_frame', 'string', 'fixed',
          'frame of the published hair: fixed (the frame_id of the head pose) or head',
          choices=OUTPUT_FRAMES),
    Param('publish_rate_hz', 'double', 30.0,
          'rate of the hair/points and hair/markers outputs (a timer of its own, independent '
          'of the pose rate)', unit='Hz', lo=0.5, hi=1000.0),
    Param('publish_on_pose', 'bool', False,
          'also publish right after a pose was simulated when a publishing period of stream '
          'time (pose stamps) has passed (lower latency; at most publish_rate_hz frames per '
          'second of stream time)'),
    Param('publish_through_rcl', 'bool', False,
          "opt-in: hand the encoded outputs to rcl's serialized publish directly (ctypes, the "
          "GIL released, no extra copy) instead of rclpy's Publisher.publish; same bytes "
          'either way. Used only with the rclpy release it was verified against; anywhere '
          "else the node logs why and keeps rclpy's publish"),
    Param('cloud_fields', 'string', 'xyz_strand_rgb',
          'fields of each point of the hair and guide clouds after x y z (float32): strand '
          '(uint32 strand index) and rgb (packed colour for rviz), or neither. Each row of the '
          'organized cloud is one strand, so xyz loses no structure; it sends 12 bytes a point '
          'instead of 20, for large clouds the cheapest way to lower the latency',
          choices=CLOUD_FIELDS),
    Param('publish_guides', 'bool', False,
          'also publish the guide strands on hair/guides/points and hair/guides/markers'),
    Param('marker_style', 'string', 'line_list',
          'MarkerArray layout: line_list (one marker per namespace, fastest) or line_strips '
          '(one marker per strand)', choices=MARKER_STYLES),
    Param('marker_width', 'double', 0.001, 'line width of the hair markers', unit='m',
          lo=1e-5, hi=0.1),
    Param('marker_color', 'double_array', (0.45, 0.3, 0.15, 1.0),
          'RGBA colour of the hair markers and of the cloud rgb field', lo=0.0, hi=1.0,
          length=4),
    Param('guide_color', 'double_array', (1.0, 0.25, 0.1, 1.0),
          'RGBA colour of the guide markers and guide cloud', lo=0.0, hi=1.0, length=4),
    Param('marker_lifetime_periods', 'double', 3.0,
          'marker lifetime in publishing periods (markers of a dead node vanish); 0 = forever',
          lo=0.0, hi=1000.0),
    Param('stale_timeout', 'double', 0.25,
          'after this long without a head pose the last pose is held and the hair keeps '
          'settling at publish_rate_hz', unit='s', lo=0.01, hi=3600.0),
    Param('head_marker', 'bool', True,
          'publish the head collider (sphere or ellipsoid) as a visualization_msgs/Marker on '
          'hair/head, in the frame of the hair'),
    Param('head_color', 'double_array', (0.85, 0.7, 0.6, 0.5),
          'RGBA colour of the head marker', lo=0.0, hi=1.0, length=4),
    Param('diagnostics_rate_hz', 'double', 1.0,
          'rate of the diagnostics output, sent whether or not anyone subscribes', unit='Hz',
          lo=0.1, hi=100.0),
    Param('numba_threads', 'int', 0,
          'threads of the parallel numba kernels; 0 = all cores (NUMBA_NUM_THREADS). On a '
          'busy machine fewer threads than cores are often faster', lo=0, hi=1024),
    Param('load_shedding', 'bool', True,
          'when simulating and publishing a pose take longer than load_shedding_budget of the '
          'pose period (median of 8 poses), track the ghosts once per pose instead of every '
          'substep until the full schedule fits again; keeps a live stream from queueing up. '
          'Never used by hair_sim_bag run'),
    Param('load_shedding_budget', 'double', 0.7,
          'share of the pose period that simulating and publishing a pose may take before load '
          'shedding starts (it ends below 2/3 of that)', lo=0.05, hi=10.0),
)


def table(base: Optional[Scene] = None) -> Tuple[Param, ...]:
    """The whole parameter table: node settings, then every scene field."""
    return NODE_PARAMS + scene_params(base)


def by_name(base: Optional[Scene] = None) -> Dict[str, Param]:
    return {p.name: p for p in table(base)}


# ------------------------------------------------------------------ snapshot
@dataclass(frozen=True)
class Settings:
    """Frozen snapshot of every parameter: the validated scene plus the node's settings.

    The node builds a new one for each accepted change; a simulation step reads the one current
    at its start, so a change never shows up half-applied.
    """

    scene: Scene
    node: Mapping[str, Any] = field(default_factory=dict)

    def __getattr__(self, name):
        node = object.__getattribute__(self, 'node')
        if name in node:
            return node[name]
        raise AttributeError(name)

    def values(self) -> Dict[str, Any]:
        """Every parameter as ``{name: value}`` (arrays as tuples)."""
        out = dict(self.node)
        out.update(scene_fields(self.scene))
        return out

    @property
    def publish_period(self) -> float:
        """Seconds between two publications."""
        return 1.0 / self.node['publish_rate_hz']

    @property
    def cloud_rgb(self) -> bool:
        """Whether the clouds carry the rgb field (``cloud_fields``)."""
        return 'rgb' in self.node['cloud_fields']

    @property
    def cloud_strand(self) -> bool:
        """Whether the clouds carry the strand field (``cloud_fields``)."""
        return 'strand' in self.node['cloud_fields']

    @property
    def marker_lifetime(self) -> float:
        """Marker lifetime [s]; 0 = forever."""
        return self.node['marker_lifetime_periods'] * self.publish_period


def _nest(flat: Mapping[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for path, value in flat.items():
        node = out
        parts = path.split('.')
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = list(value) if isinstance(value, tuple) else value
    return out


def make_settings(values: Mapping[str, Any], base: Optional[Scene] = None) -> Settings:
    """A validated :class:`Settings` from ``{name: value}``; missing names take their default.

    ``base`` supplies the defaults of the scene fields (a ``scene_file``).  Unknown names, bad
    types and out-of-range values raise :class:`ParamError` naming the parameter and what is
    allowed; cross-field scene rules are checked by ``Scene.validate``.
    """
    params = by_name(base)
    unknown = sorted(set(values) - set(params))
    if unknown:
        raise ParamError(unknown[0], 'unknown parameter (see config/hair_sim.yaml for the list)')
    node, scene_flat = {}, {}
    for name, p in params.items():
        value = p.coerce(values[name]) if name in values else p.default
        (scene_flat if p.scene else node)[name] = value
    try:
        scene = Scene.from_dict(_nest(scene_flat))
    except SceneError as e:
        raise ParamError(e.field, str(e).split(': ', 1)[-1]) from None
    return Settings(scene=scene, node=MappingProxyType(node))


def apply_changes(settings: Settings, changes: Mapping[str, Any],
                  base: Optional[Scene] = None, allow_read_only: bool = False
                  ) -> Tuple[Settings, bool]:
    """Validate ``changes`` against ``settings``; returns ``(new settings, rebuild needed)``.

    Raises :class:`ParamError` (name + allowed values) for an unknown or read-only parameter,
    a wrong type, a value out of range or a scene that fails validation; ``settings`` itself is
    never modified (it is frozen).
    """
    params = by_name(base)
    for name in changes:
        if name not in params:
            raise ParamError(name, 'unknown parameter')
        if params[name].read_only and not allow_read_only:
            raise ParamError(name, 'is read-only (set it at start: params file, launch file '
                                   'or -p name:=value)')
    old = settings.values()
    values = dict(old)
    values.update(changes)
    new = make_settings(values, base)
    new_values = new.values()
    rebuild = any(params[n].rebuild and new_values[n] != old[n] for n in changes)
    return new, rebuild


# ------------------------------------------------------------------ YAML
def render_yaml(node_name: str = NODE_NAME, base: Optional[Scene] = None,
                key: str = '/**') -> str:
    """A ROS 2 params file with every parameter at its default, each line commented.

    Scene parameters are nested by their dotted names (``groom: guides: 64``), which ROS 2
    reads back as ``groom.guides``.  ``key`` is the node-name key: ``/**`` applies to the
    node under any name and namespace (a launch file's ``name=`` or ``namespace=``).
    """
    lines = [
        f'# Parameters of the {node_name} node (hair_tracking).  Generated from the table in',
        '# hair_tracking/core/params.py:',
        '#   python -m hair_tracking.core.params > config/hair_sim.yaml',
        '#   ros2 run hair_tracking hair_sim_node --ros-args --params-file config/hair_sim.yaml',
        '# Doubles are written with a decimal point (1.0, -3.0): ROS 2 types parameters by how',
        '# the value is written.  (ro) read-only, set at start; (rebuild) a change rebuilds the',
        '# hair at the current head pose; every other parameter can be changed live.',
        '# With scene_file set, delete the scene keys below that should come from that file.',
        '# "/**" applies to the node under any name or namespace; a key the node does not',
        '# know is warned about at start.',
        f'{key}:',
        '  ros__parameters:',
    ]
    open_sections: Tuple[str, ...] = ()
    for p in table(base):
        parts = p.name.split('.')
        sections = tuple(parts[:-1])
        common = 0
        while common < min(len(sections), len(open_sections)) and \
                sections[common] == open_sections[common]:
            common += 1
        for depth in range(common, len(sections)):
            lines.append('    ' + '  ' * depth + sections[depth] + ':')
        open_sections = sections
        indent = '    ' + '  ' * len(sections)
        tags = []
        if p.read_only:
            tags.append('(ro)')
        if p.rebuild:
            tags.append('(rebuild)')
        note = p.description
        if p.unit:
            note += f' [{p.unit}]'
        rng = p.range_text()
        if rng:
            note += f'; {rng}'
        for text in textwrap.wrap(' '.join(tags + [note]), 99 - len(indent) - 2):
            lines.append(f'{indent}# {text}')
        lines.append(f'{indent}{parts[-1]}: {_yaml_value(p.default)}')
    return '\n'.join(lines) + '\n'


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, tuple):
        return '[' + ', '.join(repr(float(v)) for v in value) + ']'
    if value == '':
        return "''"
    return yaml.safe_dump(value, default_style=None).strip().splitlines()[0]


def render_markdown(base: Optional[Scene] = None) -> str:
    """The parameter table as a Markdown table (docs/node.md carries it)."""
    rows = ['| parameter | type | default | allowed | change | description |',
            '| --- | --- | --- | --- | --- | --- |']
    for p in table(base):
        change = 'read-only' if p.read_only else ('rebuilds the hair' if p.rebuild else 'live')
        desc = p.description + (f' [{p.unit}]' if p.unit else '')
        rows.append(f'| `{p.name}` | {p.kind} | `{_yaml_value(p.default)}` | '
                    f'{p.range_text().replace("|", "/")} | {change} | {desc} |')
    return '\n'.join(rows) + '\n'


def main(argv=None) -> None:  # pragma: no cover - tiny CLI
    """``python -m hair_tracking.core.params [--markdown]``: the params file (or the docs
    table)."""
    import sys
    args = sys.argv[1:] if argv is None else argv
    print(render_markdown() if '--markdown' in args else render_yaml(), end='')


if __name__ == '__main__':  # pragma: no cover
    main()
