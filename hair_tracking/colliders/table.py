"""The scene's colliders as one table: the head's row, the bust and the slots' shapes, and the
poses of the frames they ride on.

The simulator owns one :class:`ColliderTable`, built from the scene: the head's row
(``collider.*``: an ellipsoid or sphere on the frame ``head``,
:func:`~hair_tracking.colliders.head.head_collider`; none for shape ``none``), the bust
(``body.*``) on the torso frame and the further shapes of the collider slots
(``colliders.<slot>.*``), each on its frame.  Every strand
set meets the same table through :meth:`ColliderTable.for_strands`, with the margins fitted to
its strands (:func:`~hair_tracking.colliders.margin.fit_margin`): the head's row as its fast
path runs it (:class:`~hair_tracking.colliders.head.HeadCollider`) and the bust and slots as
the contact kernels' posed tables (:class:`~hair_tracking.colliders.scene_body.SceneBody`),
whose frames the table poses.  A frame's pose is handed to the table once and every strand
set's colliders ride on it.

The torso frame is the TF frame ``body.frame`` when one is named and its pose is known (the node
looks it up at each head pose and hands it over with :meth:`ColliderTable.set_body_frame`; the
last pose received is kept while none arrives), else the neck frame of the head pose
(:func:`~hair_tracking.colliders.body.neck_frame`: the head's pivot ``height / 15`` below the
head centre, the torso frame ``height / 30`` below the pivot, upright, turned about the vertical
by the head's heading, so nodding and tilting bend the neck and leave the shoulders level, and
turning the head turns the shoulders with it).

A slot's collider rides on ``head`` (the head pose), ``fixed`` (the fixed frame of the head
pose) or a TF frame by name: the node hands each TF frame's pose over with
:meth:`ColliderTable.set_tf_frame` and the last pose received is kept while none arrives;
until a first pose has arrived the collider is left out of the posed tables
(:meth:`ColliderTable.waiting` names it).
"""
from typing import Dict, List, NamedTuple, Optional, Tuple

import numpy as np

from hair_tracking.colliders.body import neck_frame
from hair_tracking.colliders.head import head_collider, HeadCollider
from hair_tracking.colliders.pose import frames_at
from hair_tracking.colliders.scene_body import make_body, SceneBody, slot_shapes, TORSO
from hair_tracking.colliders.shapes import FIXED_FRAME, HEAD_FRAME, L_FRAME, Shape


class StrandColliders(NamedTuple):
    """The table as one strand set meets it (:meth:`ColliderTable.for_strands`): ``head`` the
    head's row with its margin fitted to the strands (``None`` without a head collider),
    ``body`` the bust and slot shapes (``None`` without either)."""

    head: Optional[HeadCollider]
    body: Optional[SceneBody]


class ColliderTable:
    """The scene's colliders and the poses of their frames (module docstring); ``scene`` a
    :class:`~hair_tracking.core.scene.Scene` (its ``collider``, ``body`` and ``colliders``).
    ValueError of one line for an unusable shape."""

    def __init__(self, scene):
        #: the head's row (an ellipsoid on the head frame) as its kernels take it, the scene's
        #: margin; ``None`` for ``collider.shape`` none
        self.head: Optional[HeadCollider] = head_collider(scene.collider)
        self.body_spec = scene.body
        #: the slots' shapes (:func:`~hair_tracking.colliders.scene_body.slot_shapes`)
        self.extra = slot_shapes(scene.colliders)
        #: the frames the tables index: fixed, head, the torso, then the slots' TF frames
        self.frames = (FIXED_FRAME, HEAD_FRAME, TORSO) + tuple(
            f for f in dict.fromkeys(s.frame for s in self.extra)
            if f not in (FIXED_FRAME, HEAD_FRAME))
        self._frame: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._tf: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}
        #: the bust and slots :meth:`body_depth` measures (bare: no margin is fitted)
        self._measured = make_body(self, 0.0)

    # ------------------------------------------------------------ strand sets
    def for_strands(self, strands) -> StrandColliders:
        """The table as the strand set ``strands`` (a
        :class:`~hair_tracking.core.model.StrandSet`) meets it, margins fitted to it."""
        head = None if self.head is None else \
            self.head.fitted(strands.rest, strands.inv_mass, strands.rest_length)
        return StrandColliders(head, self.body_for(strands))

    def body_for(self, strands, head: Optional[Shape] = None) -> Optional[SceneBody]:
        """The bust and slot shapes as the strand set ``strands`` meets them (margins capped
        at half its shortest positive segment; ``None`` without either); ``head``: a head row
        (margin fitted) put first in their posed tables (the trackers that run every shape in
        one pass)."""
        positive = strands.rest_length[strands.rest_length > 0]
        return make_body(self, float(positive.min()) if positive.size else 0.0, head)

    def body_depth(self, x, head, inv_mass=None) -> float:
        """Deepest node [m] of ``x`` (S, N, 3) inside the bare bust and slot shapes at the head
        pose ``head`` (0 without any); with ``inv_mass`` only the free nodes count."""
        return 0.0 if self._measured is None else self._measured.depth(x, head, inv_mass)

    # ------------------------------------------------------------ frames
    def set_body_frame(self, rotation, position) -> None:
        """The pose of the TF frame ``body.frame`` in the fixed frame of the head pose (kept
        until the next one)."""
        self._frame = (np.array(rotation, dtype=np.float64).reshape(3, 3),
                       np.array(position, dtype=np.float64).reshape(3))

    def set_tf_frame(self, name: str, rotation, position) -> None:
        """The pose of the TF frame ``name`` of a slot collider in the fixed frame of the head
        pose (kept until the next one; a frame no collider rides on is ignored)."""
        if name in self.tf_frames():
            self._tf[name] = (np.array(rotation, dtype=np.float64).reshape(3, 3),
                              np.array(position, dtype=np.float64).reshape(3))

    def keep_frames(self, other: 'ColliderTable') -> None:
        """The frames' poses ``other`` (the table this one replaces) has received, for the
        frames this table's shapes ride on."""
        self._frame = other._frame
        for name, pose in other._tf.items():
            self.set_tf_frame(name, *pose)

    def tf_frames(self) -> Tuple[str, ...]:
        """The TF frames the slot colliders ride on (the bust's ``body.frame`` not included)."""
        return self.frames[3:]

    def waiting(self) -> List[str]:
        """The slot colliders left out of the posed tables because their TF frame has not
        arrived yet, as ``'<slot> (<frame>)'``."""
        return [f'{s.name} ({s.frame})' for s in self.extra
                if s.frame in self.tf_frames() and s.frame not in self._tf]

    def torso(self, head) -> Tuple[np.ndarray, np.ndarray]:
        """The torso frame ``(rotation, origin)`` for the head pose ``head``."""
        if self.body_spec.frame and self._frame is not None:
            return self._frame
        return neck_frame(head.rotation, head.position, self.body_spec.height)

    def frame_poses(self, head):
        """The poses ``(rot (F, 3, 3), pos (F, 3))`` of the table's frames at the head pose
        ``head``, a TF frame not yet received at the identity (its shapes are left out,
        :meth:`known`)."""
        others = [self.torso(head)] + [self._tf.get(f, (np.eye(3), np.zeros(3)))
                                       for f in self.tf_frames()]
        return frames_at(head.rotation, head.position, others)

    def known(self, local: np.ndarray) -> np.ndarray:
        """The rows of the local table ``local`` whose frame has a pose."""
        missing = [self.frames.index(f) for f in self.tf_frames() if f not in self._tf]
        if not missing:
            return local
        return local[~np.isin(local[:, L_FRAME], missing)]
