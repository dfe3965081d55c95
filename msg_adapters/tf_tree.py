"""A small transform tree over TF's parent -> child transforms (no tf2 needed).

TF (REP-105, the ``/tf`` and ``/tf_static`` topics) sends rigid transforms ``parent -> child``:
``p_parent = t + R(q) @ p_child``.  :class:`TfTree` keeps the latest transform of every child
frame (static ones from ``/tf_static`` never expire) and composes chains: the pose of a frame in
the root of its tree (:meth:`TfTree.to_root`) and the transform between two frames of one tree
(:meth:`TfTree.lookup`).  Latest values only, no interpolation in time (tf2's
``lookup_transform`` at time 0); enough for static mounts (a camera on a stand, a camera's
optical frame) and the head chain of one tracker.  Frame names are compared without a leading
``/``.  The node keeps one of ``/tf_static`` and ``/tf``; a bag reader composes the head's
parent with ``/tf_static`` through one (:meth:`TfTree.add_message` takes TFMessages from rclpy
or rosbags alike).  The quaternion maths are :mod:`hair_tracking.core.transforms`.
"""
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from hair_tracking.core.transforms import (quat_conjugate, quat_multiply, quat_normalize,
                                           quat_to_matrix)
from msg_adapters.tf import transforms

MAX_DEPTH = 64


@dataclass(frozen=True)
class Edge:
    parent: str
    translation: np.ndarray     # (3,)
    rotation: np.ndarray        # (4,) unit quaternion x y z w
    stamp_ns: int
    static: bool


def frame_name(name: str) -> str:
    return str(name).strip().lstrip('/')


def compose(a: Tuple[np.ndarray, np.ndarray], b: Tuple[np.ndarray, np.ndarray]):
    """``a * b``: apply ``b`` first (``p -> t_a + R_a (t_b + R_b p)``)."""
    ta, qa = a
    tb, qb = b
    return ta + quat_to_matrix(qa) @ tb, quat_normalize(quat_multiply(qa, qb))


def invert(a: Tuple[np.ndarray, np.ndarray]):
    t, q = a
    qi = quat_conjugate(q)
    return -(quat_to_matrix(qi) @ t), qi


IDENTITY = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))


class TfTree:
    """The latest transform of each child frame; chains composed on request."""

    def __init__(self):
        self._edges: Dict[str, Edge] = {}

    def __len__(self) -> int:
        return len(self._edges)

    def set(self, parent: str, child: str, translation, rotation, stamp_ns: int = 0,
            static: bool = False) -> bool:
        """Store ``parent -> child``; False (ignored) for a malformed or self-referencing one,
        or a dynamic transform older than the one held (a static one always replaces)."""
        parent, child = frame_name(parent), frame_name(child)
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        q = np.asarray(rotation, dtype=np.float64).reshape(4)
        n = float(np.linalg.norm(q))
        if not parent or not child or parent == child or not np.all(np.isfinite(t)) \
                or not np.isfinite(n) or n < 1e-9:
            return False
        old = self._edges.get(child)
        if old is not None and not static and not old.static and stamp_ns < old.stamp_ns:
            return False
        self._edges[child] = Edge(parent, t.copy(), q / n, int(stamp_ns), bool(static))
        return True

    def add_message(self, msg, static: bool = False) -> None:
        """:meth:`set` every transform of a TFMessage (``static`` for ``/tf_static``)."""
        for parent, child, t, q, stamp in transforms(msg):
            self.set(parent, child, t, q, stamp, static=static)

    def frames(self) -> List[str]:
        """The child frames held, sorted."""
        return sorted(self._edges)

    def parent(self, child: str) -> Optional[str]:
        e = self._edges.get(frame_name(child))
        return e.parent if e is not None else None

    def to_root(self, frame: str, stop: Optional[str] = None):
        """``(root, translation, rotation)``: ``frame`` in the root of its tree (or in ``stop``
        when the chain passes it).  A frame nobody publishes is its own root."""
        frame = frame_name(frame)
        stop = frame_name(stop) if stop else None
        pose = IDENTITY
        seen = {frame}
        while frame != stop:
            e = self._edges.get(frame)
            if e is None:
                break
            pose = compose((e.translation, e.rotation), pose)
            frame = e.parent
            if frame in seen or len(seen) > MAX_DEPTH:
                raise ValueError(f'TF loop through frame {frame!r}')
            seen.add(frame)
        return frame, pose[0], pose[1]

    def lookup(self, target: str, source: str):
        """``(translation, rotation)`` taking points of ``source`` into ``target`` (tf2's
        ``lookup_transform(target, source)``), or None when they are not in one tree."""
        root_t, tt, qt = self.to_root(target)
        root_s, ts, qs = self.to_root(source)
        if root_t != root_s:
            return None
        return compose(invert((tt, qt)), (ts, qs))
