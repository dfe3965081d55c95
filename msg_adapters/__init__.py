"""Conversions between ROS 2 messages and numpy arrays; knows nothing of hair.

- :mod:`msg_adapters.pose`: PoseStamped / TransformStamped / ... <-> (t_ns, position, quaternion)
- :mod:`msg_adapters.pointcloud`: strands (S, N, 3) <-> organized PointCloud2 (+ CDR bytes)
- :mod:`msg_adapters.markers`: strands -> MarkerArray message objects
- :mod:`msg_adapters.marker_cdr`: strands -> the same MarkerArray as CDR bytes, fast
- :mod:`msg_adapters.guide_state`: guide strands (G, N, 3) <-> hair_tracking_msgs/GuideState
  (+ CDR bytes); not imported here: its message package is generated (make install) or built
  by colcon beside hair_tracking
- :mod:`msg_adapters.rcl_serialized`: serialized publish / take through rcl, the GIL released
- :mod:`msg_adapters.stamps`, :mod:`msg_adapters.arrays`, :mod:`msg_adapters.cdr`: helpers
"""
from msg_adapters.marker_cdr import strands_to_marker_array_cdr
from msg_adapters.markers import delete_all_marker, strands_to_marker_array
from msg_adapters.pointcloud import (pointcloud2_to_strands, strands_to_pointcloud2,
                                     strands_to_pointcloud2_cdr)
from msg_adapters.pose import (pose_from_msg, pose_msg, pose_stamped_msg, PoseError, PoseSample,
                               transform_stamped_msg)

__all__ = ['delete_all_marker', 'pointcloud2_to_strands', 'pose_from_msg', 'pose_msg',
           'pose_stamped_msg', 'PoseError', 'PoseSample', 'strands_to_marker_array',
           'strands_to_marker_array_cdr', 'strands_to_pointcloud2', 'strands_to_pointcloud2_cdr',
           'transform_stamped_msg']
