"""The recorded head motion the tests read: excerpts in test/data of the MIT-licensed recordings
(sources, licences and the command that derived them: test/data/ATTRIBUTION.md)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'scripts'))
from make_head_motion_data import (FIXTURES, VR_EXCERPT, VR_WINDOW_S, WALK_EXCERPT,  # noqa: E402
                                   WALK_FRAMES)

#: CMU 131_01 walk, BVH: frames WALK_FRAMES of the recording (3.0-6.0 s), no right leg or arm
WALK_BVH = os.path.join(FIXTURES, WALK_EXCERPT)
#: the recording's frame (and the bundled CSV's row) the excerpt starts at
WALK_FIRST_FRAME = WALK_FRAMES[0]
#: VR360 user 1 headset trace, the rows stamped VR_WINDOW_S
VR_TRACE = os.path.join(FIXTURES, VR_EXCERPT)
VR_START_S = VR_WINDOW_S[0]


def write_walk_bag(path, seconds: float):
    """Write the first ``seconds`` of the bundled walk bag's head poses to ``path`` (a
    head-pose bag) and return ``path``."""
    from hair_tracking.bags import io as bag_io
    hp = bag_io.read_head_poses(bag_io.bundled_bag(), duration_s=seconds)
    bag_io.write_head_pose_bag(path, hp.t_ns, hp.position, hp.quaternion)
    return path
