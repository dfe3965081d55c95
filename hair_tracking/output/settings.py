"""The node's own rows of the parameter table, and the typed settings snapshot.

The parameters of the ``hair_sim`` node are its own runtime settings (:data:`NODE_PARAMS`:
``publish_rate_hz``, ``marker_style``, ``cloud_fields`` ...) followed by every scene field under
its dotted path (:data:`hair_tracking.core.scene_params.SCENE_PARAMS`: ``groom.guides``,
``solver.type``, ``gravity`` ...); :func:`table` is the whole table.  The ROS shell
(:mod:`hair_tracking.ros.node`) declares one ROS parameter per row, validates a candidate change
with :func:`apply_changes` (which builds and validates the whole scene, so cross-field rules hold
too) and hands the resulting :class:`Settings` snapshot to the next simulation step;
``hair_sim_bag run`` reads a params file of the node into the same snapshot.  A change of the
groom that imports a file reads it while validating (:func:`check_groom_file`), so a bad file is
refused with the change.  This module imports no ROS package: it is plain data and checks,
testable without DDS.

Units are SI (metres, seconds, radians unless a name says ``_deg``); frames follow REP-103.
"""
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Tuple

from hair_tracking.core.params import Param, ParamError
from hair_tracking.core.scene import Scene, scene_fields, scene_params, SceneError
from hair_tracking.grooms.build import import_groom
from hair_tracking.grooms.polylines import GroomFileError

NODE_NAME = 'hair_sim'

MARKER_STYLES = ('line_list', 'line_strips')
OUTPUT_FRAMES = ('fixed', 'head')
CLOUD_FIELDS = ('xyz_strand_rgb', 'xyz_strand', 'xyz_rgb', 'xyz')

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
    Param('shards', 'int', 0,
          'ghost shards (hair_sim_ghosts processes, launch/hair_sim_shards.launch.py) that '
          'place and publish the ghosts on hair/shard_<k>/points and .../markers; > 0: this '
          'node publishes no ghost cloud or markers of its own (hair/points, hair/markers) '
          'and publishes the guides\' state and the settings for them, as with '
          'publish_guide_state (docs/ros.md)', lo=0, hi=1024, read_only=True),
    Param('publish_guide_state', 'bool', False,
          'publish the guides\' state (hair_tracking_msgs/GuideState) on hair/guides/state '
          'each frame and the settings on hair/scene (latched), what hair_sim_ghosts shards '
          'place their ghosts from; the node\'s own ghosts are then placed from the guides '
          'rounded to float32, as the shards receive them', read_only=True),
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

#: The node's rows by name.
NODE_ROWS: Dict[str, Param] = {p.name: p for p in NODE_PARAMS}


def table(base: Optional[Scene] = None) -> Tuple[Param, ...]:
    """The whole parameter table: the node's rows, then the scene's (defaults from ``base``, a
    scene file, when given)."""
    return NODE_PARAMS + scene_params(base)


def by_name(base: Optional[Scene] = None) -> Dict[str, Param]:
    return {p.name: p for p in table(base)}


# ------------------------------------------------------------------ snapshot
def _default(name: str) -> Any:
    """The default of the node parameter ``name``: its row's."""
    return NODE_ROWS[name].default


RGBA = Tuple[float, float, float, float]


@dataclass(frozen=True)
class Settings:
    """Frozen snapshot of every parameter: the validated scene plus one attribute per node row
    (same name, default and type).

    The node builds a new one for each accepted change (:func:`apply_changes`); a simulation
    step reads the one current at its start, so a change never shows up half-applied.
    """

    scene: Scene = field(default_factory=Scene)
    scene_file: str = _default('scene_file')
    warmup: bool = _default('warmup')
    use_tf: bool = _default('use_tf')
    publish_tf: bool = _default('publish_tf')
    gravity_frame: str = _default('gravity_frame')
    pose_queue_depth: int = _default('pose_queue_depth')
    output_queue_depth: int = _default('output_queue_depth')
    head_frame: str = _default('head_frame')
    head_frame_prefix: str = _default('head_frame_prefix')
    fixed_frame: str = _default('fixed_frame')
    output_frame: str = _default('output_frame')
    publish_rate_hz: float = _default('publish_rate_hz')
    publish_on_pose: bool = _default('publish_on_pose')
    publish_through_rcl: bool = _default('publish_through_rcl')
    cloud_fields: str = _default('cloud_fields')
    publish_guides: bool = _default('publish_guides')
    shards: int = _default('shards')
    publish_guide_state: bool = _default('publish_guide_state')
    marker_style: str = _default('marker_style')
    marker_width: float = _default('marker_width')
    marker_color: RGBA = _default('marker_color')
    guide_color: RGBA = _default('guide_color')
    marker_lifetime_periods: float = _default('marker_lifetime_periods')
    stale_timeout: float = _default('stale_timeout')
    head_marker: bool = _default('head_marker')
    head_color: RGBA = _default('head_color')
    diagnostics_rate_hz: float = _default('diagnostics_rate_hz')
    numba_threads: int = _default('numba_threads')
    load_shedding: bool = _default('load_shedding')
    load_shedding_budget: float = _default('load_shedding_budget')

    def values(self) -> Dict[str, Any]:
        """Every parameter as ``{name: value}`` (arrays as tuples), in the table's order."""
        out = {p.name: getattr(self, p.name) for p in NODE_PARAMS}
        out.update(scene_fields(self.scene))
        return out

    @property
    def publish_period(self) -> float:
        """Seconds between two publications."""
        return 1.0 / self.publish_rate_hz

    @property
    def guide_state(self) -> bool:
        """Whether the node publishes the guides' state for ghost shards."""
        return self.publish_guide_state or self.shards > 0

    @property
    def cloud_rgb(self) -> bool:
        """Whether the clouds carry the rgb field (``cloud_fields``)."""
        return 'rgb' in self.cloud_fields

    @property
    def cloud_strand(self) -> bool:
        """Whether the clouds carry the strand field (``cloud_fields``)."""
        return 'strand' in self.cloud_fields

    @property
    def marker_lifetime(self) -> float:
        """Marker lifetime [s]; 0 = forever."""
        return self.marker_lifetime_periods * self.publish_period


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
    return Settings(scene=scene, **node)


def check_groom_file(scene: Scene) -> None:
    """ParamError naming ``groom.file`` when the scene imports a groom file that cannot be read
    or put on the head (the file is read and imported here, so a bad one is refused before
    anything is rebuilt); nothing for the procedural groom."""
    if scene.groom.file:
        try:
            import_groom(scene.groom)
        except GroomFileError as e:
            raise ParamError('groom.file', str(e)) from None


def apply_changes(settings: Settings, changes: Mapping[str, Any],
                  base: Optional[Scene] = None, allow_read_only: bool = False
                  ) -> Tuple[Settings, bool]:
    """Validate ``changes`` against ``settings``; returns ``(new settings, rebuild needed)``.

    Raises :class:`ParamError` (name + allowed values) for an unknown or read-only parameter,
    a wrong type, a value out of range, a scene that fails validation or a changed groom whose
    file cannot be imported (:func:`check_groom_file`); ``settings`` itself is never modified
    (it is frozen).
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
    if new.scene.groom != settings.scene.groom:
        check_groom_file(new.scene)
    return new, rebuild
