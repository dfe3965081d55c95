"""The ``hair_sim`` node's topic names and quality-of-service profiles, shared with the ghost
shards (``hair_sim_ghosts``), and the DiagnosticStatus of a health report."""
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos import qos_profile_sensor_data

from hair_tracking.output.diagnostics import HARDWARE_ID

WARN_THROTTLE_S = 5.0
HEAD_MARKER_TOPIC = 'hair/head'
#: The scene's body (the bust's capsules) as markers.
COLLIDERS_TOPIC = 'hair/colliders'
#: What ghost shards (hair_sim_ghosts) place their ghosts from: the guides' state of each frame
#: and the node's settings (latched).
GUIDE_STATE_TOPIC = 'hair/guides/state'
SCENE_TOPIC = 'hair/scene'
#: The strand outputs of :data:`hair_tracking.output.frame_encoder.OUTPUTS`, by key.
STRAND_TOPICS = {
    'points': 'hair/points',
    'markers': 'hair/markers',
    'guide_points': 'hair/guides/points',
    'guide_markers': 'hair/guides/markers',
}


def latched_qos() -> QoSProfile:
    """Reliable, transient-local, keep-last 1: a late subscriber gets the last message."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def output_qos(depth: int) -> QoSProfile:
    """Reliable, volatile, keep-last ``depth`` (parameter ``output_queue_depth``)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def pose_qos(depth: int) -> QoSProfile:
    """The sensor-data QoS with a queue of ``depth`` (parameter ``pose_queue_depth``), so
    reliable and best-effort publishers both connect."""
    return QoSProfile(history=qos_profile_sensor_data.history, depth=depth,
                      reliability=qos_profile_sensor_data.reliability,
                      durability=qos_profile_sensor_data.durability)


def best_effort_qos() -> QoSProfile:
    """Best effort, volatile, keep-last 100 (``/tf``, the tracked ids): every publisher,
    reliable or not, connects."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)


def tf_static_qos() -> QoSProfile:
    """``/tf_static`` as tf2 publishes it: reliable, transient local, keep-last 100."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def tf_out_qos() -> QoSProfile:
    """What the node broadcasts its head pose on ``/tf`` with: reliable, volatile, 100."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def diagnostic_status(name: str, status) -> DiagnosticStatus:
    """The DiagnosticStatus of a :class:`hair_tracking.output.diagnostics.Status`."""
    return DiagnosticStatus(level=bytes([status.level]), name=name, message=status.message,
                            hardware_id=HARDWARE_ID,
                            values=[KeyValue(key=k, value=v) for k, v in status.values.items()])
