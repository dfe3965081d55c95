"""Roster: who is in view, as REP-155 (ROS4HRI) perception says, and their hair.

REP-155 lists the faces tracked now on ``/humans/faces/tracked`` (random ids) and puts each on TF
as ``face_<id>``: origin at the sellion, x out of the face, z toward the scalp.  The hair's head
frame (REP-103: x forward, z up, origin at the head centre) has the face frame's axes; its origin
lies at ``people.sellion_offset`` in the face frame, behind and above the sellion.

A person is *seen* when their id is on a list or their face frame arrives; one who is not seen
for ``people.lost_timeout_s`` is removed with their hair.  Hair is made at a person's first face
pose (an id listed without a pose waits for one), while the crowd has a place
(``people.max``; the others wait); one who comes back after being removed gets fresh hair.  Time
is what the caller says it is (the node's clock; a test's own), so the roster runs without ROS.
"""
import re
from typing import Dict, Iterable, List, Optional

import numpy as np

from hair_tracking.core.head_track import pose_problem, PoseResult
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.people.crowd import Crowd

#: REP-155's face frames: ``face_<id>``.
FACE_PREFIX = 'face_'
#: Ids that can name a topic (``/humans/faces/<id>/hair/points``): a ROS name token.
_ID = re.compile(r'[A-Za-z][A-Za-z0-9_]*\Z')


def face_id(frame: str) -> Optional[str]:
    """The id of a REP-155 face frame ``face_<id>``; None for any other frame."""
    frame = str(frame).lstrip('/')
    return frame[len(FACE_PREFIX):] if frame.startswith(FACE_PREFIX) and \
        len(frame) > len(FACE_PREFIX) else None


def id_problem(pid: str) -> Optional[str]:
    """Why ``pid`` cannot name a person's topics (None when it can)."""
    if _ID.match(pid) and '__' not in pid:
        return None
    return (f'face id {pid!r} cannot name a topic (/humans/faces/<id>/...: a letter, then '
            'letters, digits and single underscores): ignored')


class Roster:
    """The people in view and their hair (:class:`~hair_tracking.people.crowd.Crowd`).

    ``appeared`` and ``removed`` collect the ids whose hair was made or dropped since the
    caller last emptied them (the ROS layer creates and destroys their publishers).
    """

    def __init__(self, scene: Scene, crowd: Optional[Crowd] = None):
        people = scene.people
        self.crowd = crowd if crowd is not None else Crowd(scene, people.max)
        self.offset = np.array(people.sellion_offset, dtype=np.float64)
        self.lost_timeout_ns = int(round(people.lost_timeout_s * 1e9))
        self._seen: Dict[str, int] = {}
        self.appeared: List[str] = []
        self.removed: List[str] = []
        self.waiting = 0            # face poses of people without a place
        self.rejected = 0           # face poses refused (non-finite, zero quaternion ...)
        self.last_rejection = ''

    def listed(self, ids: Iterable[str], now_ns: int) -> None:
        """An id list (``/humans/faces/tracked``) arrived at ``now_ns``."""
        for pid in ids:
            self._seen[str(pid)] = int(now_ns)

    def face(self, pid: str, t_ns: int, position, quaternion, now_ns: int
             ) -> Optional[PoseResult]:
        """Person ``pid``'s face (the sellion frame, in the fixed frame) at stamp ``t_ns``,
        arrived at ``now_ns``; hair made when new and a place is free.  Returns what happened to
        the pose (None: no place).  A pose the head track would refuse is refused first,
        before any hair is made for it (:attr:`rejected`, :attr:`last_rejection`); the person
        still counts as seen."""
        self._seen[pid] = int(now_ns)
        problem = pose_problem(t_ns, position, quaternion)
        if problem is not None:
            self.rejected += 1
            self.last_rejection = f'face {pid}: {problem}'
            return PoseResult.REJECTED
        q = np.asarray(quaternion, dtype=np.float64).reshape(4)
        p = np.asarray(position, dtype=np.float64).reshape(3) + \
            quat_to_matrix(q / np.linalg.norm(q)) @ self.offset
        crowd = self.crowd
        if pid in crowd.people:
            return crowd.push_pose(pid, t_ns, p, q)
        if len(crowd.people) >= crowd.places:
            self.waiting += 1
            return None
        result = crowd.add(pid, t_ns, p, q)
        if result is not PoseResult.REJECTED:
            self.appeared.append(pid)
        return result

    def without_pose(self) -> List[str]:
        """Ids seen (listed) that have no hair: no usable face pose has come for them yet,
        or no place was free."""
        return sorted(pid for pid in self._seen if pid not in self.crowd.people)

    def expire(self, now_ns: int) -> List[str]:
        """Remove everyone not seen for the lost timeout by ``now_ns``; their ids."""
        gone = [pid for pid, seen in self._seen.items()
                if now_ns - seen > self.lost_timeout_ns]
        for pid in gone:
            del self._seen[pid]
            if pid in self.crowd.people:
                self.crowd.remove(pid)
                self.removed.append(pid)
        return gone

    def advance_to(self, t_ns: int) -> int:
        """Every person's hair up to stamp ``t_ns`` (:meth:`Crowd.advance_to`)."""
        return self.crowd.advance_to(t_ns)
