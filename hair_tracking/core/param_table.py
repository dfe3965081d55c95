"""The one parameter table of the ``hair_sim`` node: its own runtime settings
(:data:`NODE_PARAMS`: ``publish_rate_hz``, ``marker_style``, ``cloud_fields`` ...) followed by
every scene field under its dotted path (:data:`hair_tracking.core.scene_params.SCENE_PARAMS`:
``groom.guides``, ``solver.type``, ``gravity`` ...); :func:`table` is the whole table.

Everything else is derived from these rows: the typed settings snapshot
(:class:`hair_tracking.output.settings.Settings`, one attribute per node row), the node's ROS
parameters and their descriptors (:mod:`hair_tracking.ros.parameters`), ``config/hair_sim.yaml``,
``config/scene_default.yaml`` and the table in ``docs/node.md``
(:mod:`hair_tracking.output.param_files`).  No ROS here.

Units are SI (metres, seconds, radians unless a name says ``_deg``); frames follow REP-103.
"""
from typing import Dict, Optional, Tuple

from hair_tracking.core.params import Param
from hair_tracking.core.scene import Scene, scene_params

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
    Param('marker_max_strands', 'int', 10000,
          'the markers draw at most this many strands, evenly spread over the scalp (a full '
          'head of 100 000 would make some 70 MB of markers a frame; the cloud carries every '
          'strand, or cloud_max_strands); 0: all', lo=0, hi=2_000_000),
    Param('cloud_max_strands', 'int', 50000,
          'the hair clouds carry at most this many strands, evenly spread over the scalp, '
          'each with its strand id and colour (at 16 points a strand, 50 000 strands make a '
          '16 MB cloud, some 480 MB/s at 30 Hz); 0: all', lo=0, hi=2_000_000),
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
