"""Head-pose stream hygiene and interpolation.

``HeadTrack`` takes timestamped poses as they arrive (from a topic, a bag or a file), cleans them
and answers "where was the head at time t" with linear interpolation of the position and slerp of
the orientation.  What it checks, and what the simulator does about it:

* NaN/Inf numbers, a zero or non-finite quaternion, wrong shapes -> the pose is rejected and
  counted (``PoseResult.REJECTED``); nothing else changes.
* quaternions are normalised and kept sign-continuous (q and -q are the same rotation; the stored
  stream never flips, so slerp never takes the long way round).
* time going backwards (a bag played in a loop, a restarted tracker) -> ``RESET_BACKWARDS``:
  history is dropped and the simulator carries the hair rigidly to the new pose.
* a jump farther than ``teleport_distance`` or turning more than ``teleport_angle_deg`` between two
  samples, or a gap longer than ``max_gap`` -> ``RESET_TELEPORT``, handled the same way.
* times after the newest sample hold the newest pose (a stale stream lets the hair settle).

``StreamClock`` maps a live stream's stamps onto the simulator's time: the same, except after a
stale stretch in which the hair settled past the stream's newest stamp (stamps slower than the
node clock), where the stream continues one substep after the hair instead of freezing it.
"""
from collections import deque
import enum
import math
from typing import Optional

import numpy as np

from hair_tracking.core.model import HeadPose
from hair_tracking.core.scene import HeadTrackSpec
from hair_tracking.core.transforms import matrix_of_quat, quat_dot, slerp_floats


class PoseResult(enum.Enum):
    ACCEPTED = 'accepted'
    REJECTED = 'rejected'
    RESET_BACKWARDS = 'reset_backwards'
    RESET_TELEPORT = 'reset_teleport'

    @property
    def is_reset(self) -> bool:
        return self in (PoseResult.RESET_BACKWARDS, PoseResult.RESET_TELEPORT)


IDENTITY = HeadPose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.eye(3))


class HeadTrack:
    """Recent head poses with hygiene, reset detection and interpolation (see module doc)."""

    def __init__(self, spec: HeadTrackSpec = HeadTrackSpec(), history: int = 256):
        self.spec = spec
        self._t = deque(maxlen=history)      # int ns
        self._p = deque(maxlen=history)      # (x, y, z) floats
        self._q = deque(maxlen=history)      # (x, y, z, w) floats, unit, sign-continuous
        self.counters = {'accepted': 0, 'rejected': 0, 'reset_backwards': 0,
                         'reset_teleport': 0}
        self.last_rejection = ''

    # ----------------------------------------------------------------- input
    def push(self, t_ns: int, position, quaternion) -> PoseResult:
        """Add one pose; returns what happened to it (see module doc)."""
        pose = _parse_pose(t_ns, position, quaternion)
        if isinstance(pose, str):
            self.counters['rejected'] += 1
            self.last_rejection = pose
            return PoseResult.REJECTED
        t_ns = int(t_ns)
        p, q = pose
        result = PoseResult.ACCEPTED
        if self._t:
            d = quat_dot(q, self._q[-1])
            if d < 0.0:
                q, d = tuple(-c for c in q), -d
            t_last = self._t[-1]
            if t_ns < t_last:
                result = PoseResult.RESET_BACKWARDS
            elif (math.dist(p, self._p[-1]) > self.spec.teleport_distance
                  or math.degrees(2.0 * math.acos(min(1.0, d))) > self.spec.teleport_angle_deg
                  or (t_ns - t_last) * 1e-9 > self.spec.max_gap):
                result = PoseResult.RESET_TELEPORT
            elif t_ns == t_last:            # a repeated stamp updates the newest sample
                self._p[-1], self._q[-1] = p, q
                self.counters['accepted'] += 1
                return result
        if result.is_reset:
            self.counters[result.value] += 1
            self.clear()
        else:
            self.counters['accepted'] += 1
        self._t.append(t_ns)
        self._p.append(p)
        self._q.append(q)
        return result

    def clear(self) -> None:
        self._t.clear()
        self._p.clear()
        self._q.clear()

    # ---------------------------------------------------------------- output
    @property
    def empty(self) -> bool:
        return not self._t

    @property
    def first_time(self) -> int:
        return self._t[0]

    @property
    def last_time(self) -> int:
        return self._t[-1]

    def latest(self) -> HeadPose:
        if not self._t:
            return IDENTITY
        return head_pose(self._p[-1], self._q[-1])

    def sample(self, t_ns: int) -> HeadPose:
        """Head pose at ``t_ns``: interpolated between samples, held outside them."""
        if not self._t:
            return IDENTITY
        ts = self._t
        if t_ns <= ts[0]:
            return head_pose(self._p[0], self._q[0])
        if t_ns >= ts[-1]:
            return head_pose(self._p[-1], self._q[-1])
        i = _bisect(ts, t_ns)           # ts[i-1] <= t < ts[i]
        u = (t_ns - ts[i - 1]) / (ts[i] - ts[i - 1])
        a, b = self._p[i - 1], self._p[i]
        return head_pose(tuple((1.0 - u) * a[k] + u * b[k] for k in range(3)),
                         slerp_floats(self._q[i - 1], self._q[i], u))


class StreamClock:
    """Stream stamps -> simulator time (see the module doc).

    ``offset_ns`` is added to a stream stamp to give the simulator's time (and subtracted from
    the simulator's time to stamp an output); :meth:`sim_time` proposes it for a pose, and
    :meth:`accept` keeps it once the pose was taken.
    """

    def __init__(self):
        self.offset_ns = 0
        self.last_stamp_ns = None       # the newest accepted stream stamp

    def sim_time(self, t_ns: int, sim_time_ns, dt_ns: int):
        """``(simulator time, offset)`` for a pose stamped ``t_ns`` when the simulator is at
        ``sim_time_ns`` (None before the first pose) with substeps of ``dt_ns``."""
        offset, last = self.offset_ns, self.last_stamp_ns
        if last is not None and t_ns < last:
            offset = 0                   # backwards: the simulator resets to this stamp
        elif last is not None and sim_time_ns > last + offset and \
                t_ns + offset <= sim_time_ns:
            offset = sim_time_ns + dt_ns - t_ns
        return t_ns + offset, offset

    def accept(self, t_ns: int, offset: int) -> None:
        """The pose stamped ``t_ns`` was taken at ``t_ns + offset``."""
        self.offset_ns = offset
        self.last_stamp_ns = t_ns

    def stamp(self, sim_time_ns) -> int:
        """The stream stamp of the simulator time ``sim_time_ns`` (0 before the first)."""
        return max(0, (sim_time_ns or 0) - self.offset_ns)


def head_pose(p, q) -> HeadPose:
    """A HeadPose of position ``p`` and unit quaternion ``q`` (tuples of floats)."""
    return HeadPose(np.array(p), np.array(q), matrix_of_quat(*q))


def _bisect(ts, t):
    lo, hi = 0, len(ts) - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ts[mid] <= t:
            lo = mid
        else:
            hi = mid
    return hi


def _parse_pose(t_ns, position, quaternion):
    """``(position, unit quaternion)`` as tuples of floats, or why the pose is rejected (a
    string)."""
    try:
        p = np.asarray(position, dtype=np.float64)
        q = np.asarray(quaternion, dtype=np.float64)
    except (TypeError, ValueError):
        return 'position/quaternion are not numbers'
    if p.size != 3 or q.size != 4:
        return f'expected 3 position and 4 quaternion values, got {p.size} and {q.size}'
    if isinstance(t_ns, float) and not math.isfinite(t_ns):
        return f'timestamp is {t_ns}'
    p, q = p.reshape(3).tolist(), q.reshape(4).tolist()
    if not all(map(math.isfinite, p)):
        return f'position has non-finite values {p}'
    if not all(map(math.isfinite, q)):
        return f'quaternion has non-finite values {q}'
    n = math.hypot(*q)
    if n < 1e-6:
        return f'quaternion has (near) zero norm {n:.3g}'
    return tuple(p), tuple(c / n for c in q)


def pose_problem(t_ns, position, quaternion) -> Optional[str]:
    """Why :meth:`HeadTrack.push` would reject this pose (None when it is usable): checked
    before anything is built for it."""
    pose = _parse_pose(t_ns, position, quaternion)
    return pose if isinstance(pose, str) else None
