"""The scene's body: the bust (``body.*``) of :func:`~hair_tracking.colliders.body.bust` on the
torso frame and the further colliders of the scene's slots (``colliders.<slot>.*``), each on its
frame, posed for a substep from the head poses at its start and end.

The torso frame is the TF frame ``body.frame`` when one is named and its pose is known (the node
looks it up at each head pose and hands it over with :meth:`SceneBody.set_frame`; the last pose
received is kept while none arrives), else the neck frame of the head pose
(:func:`~hair_tracking.colliders.body.neck_frame`: the head's pivot ``height / 15`` below the
head centre, the torso frame ``height / 30`` below the pivot, upright, turned about the vertical
by the head's heading, so nodding and tilting bend the neck and leave the shoulders level, and
turning the head turns the shoulders with it).

A slot's collider rides on ``head`` (the head pose), ``fixed`` (the fixed frame of the head
pose) or a TF frame by name: the node hands each TF frame's pose over with
:meth:`SceneBody.set_tf_frame` and the last pose received is kept while none arrives; until a
first pose has arrived the collider is left out of the table (:meth:`SceneBody.waiting` names
it).

The margin is the scene's ``body.margin`` (a slot's ``margin``) capped at half the hair's
shortest segment (:func:`~hair_tracking.colliders.margin.fit_margin` without a rest clearance:
the rest shape of a groom is given in the head frame and may hang through the body; the bust is
what keeps it out).
"""
from dataclasses import replace
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from hair_tracking.colliders.body import bust, neck_frame
from hair_tracking.colliders.kernels import deepest
from hair_tracking.colliders.margin import fit_margin
from hair_tracking.colliders.pose import frames_at, posed
from hair_tracking.colliders.shapes import (FIXED_FRAME, HEAD_FRAME, L_FRAME, Shape,
                                            shape_table)

#: The frame name the bust's shapes ride on in its table (the third frame of the table).
TORSO = 'torso'
#: [m / s] A torso frame that moves faster than this over a substep jumped (a re-detected
#: person, a TF glitch): that substep it is taken as not moving (colliders.pose).
JUMP_SPEED = 10.0


def slot_shapes(colliders) -> List[Shape]:
    """The shapes of the scene's used collider slots (``scene.colliders``), each named after
    its slot and validated (a ValueError of one line naming the slot)."""
    shapes = []
    for slot, c in colliders.used():
        frame = c.frame.lstrip('/')
        if frame == TORSO:
            raise ValueError(f'colliders.{slot}.frame: {TORSO!r} is the name the bust\'s frame '
                             'has inside the simulator; name the TF frame itself')
        shapes.append(Shape(c.shape, frame=frame, center=tuple(c.center),
                            rotation=tuple(c.rotation), radius=c.radius,
                            half_length=c.half_length, radii=tuple(c.radii), margin=c.margin,
                            friction=c.friction, name=slot).validate())
    return shapes


class SceneBody:
    """The bust of a scene's ``body`` section (``spec``; none when ``spec.bust`` is false) and
    the shapes ``extra`` (:func:`slot_shapes`) for a strand set whose shortest positive segment
    is ``shortest_segment`` [m]; :meth:`posed` gives a substep's posed table.  ``head``: the
    head collider the strand set is kept out of, ``(center, axes)`` (head frame, the margin
    included), put first in the table, so that a node pushed out of the neck is not left in
    the head (none: the bust alone)."""

    def __init__(self, spec, shortest_segment: float, head=None, extra: Sequence[Shape] = ()):
        self.spec = spec
        shapes = bust(spec.height, frame=TORSO, margin=spec.margin, friction=spec.friction) \
            if spec.bust else []
        margin = fit_margin(bust(spec.height, margin=spec.margin)[0], None,
                            [shortest_segment]) if shortest_segment > 0 else float(spec.margin)
        self.margin = margin
        if spec.bust:
            shapes = bust(spec.height, frame=TORSO, margin=margin, friction=spec.friction)
        extra = [replace(s, margin=fit_margin(s, None, [shortest_segment]))
                 if shortest_segment > 0 else s for s in extra]
        self.shapes = shapes + extra
        #: the shapes before the bust in the table (the head collider, when given)
        self.lead = 0 if head is None else 1
        table = list(self.shapes)
        if head is not None:
            table = [Shape('ellipsoid', frame=HEAD_FRAME, center=tuple(head[0]),
                           radii=tuple(head[1]), name='head')] + table
        self.frames = (FIXED_FRAME, HEAD_FRAME, TORSO) + tuple(
            f for f in dict.fromkeys(s.frame for s in extra)
            if f not in (FIXED_FRAME, HEAD_FRAME))
        self.local = shape_table(table, frames=self.frames)
        self.bare = shape_table([replace(s, margin=0.0) for s in self.shapes],
                                frames=self.frames)
        self._frame: Optional[Tuple[np.ndarray, np.ndarray]] = None
        self._tf: Dict[str, Tuple[np.ndarray, np.ndarray]] = {}

    def tf_frames(self) -> Tuple[str, ...]:
        """The TF frames the slot colliders ride on (the bust's ``body.frame`` not included)."""
        return self.frames[3:]

    def set_frame(self, rotation, position) -> None:
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

    def waiting(self) -> List[str]:
        """The slot colliders left out of the table because their TF frame has not arrived
        yet, as ``'<slot> (<frame>)'``."""
        return [f'{s.name} ({s.frame})' for s in self.shapes
                if s.frame in self.tf_frames() and s.frame not in self._tf]

    def torso(self, head) -> Tuple[np.ndarray, np.ndarray]:
        """The torso frame ``(rotation, origin)`` for the head pose ``head``."""
        if self.spec.frame and self._frame is not None:
            return self._frame
        return neck_frame(head.rotation, head.position, self.spec.height)

    def _frames(self, head):
        """The poses of the table's frames at ``head``, a TF frame not yet received at the
        identity (its shapes are left out)."""
        others = [self.torso(head)] + [self._tf.get(f, (np.eye(3), np.zeros(3)))
                                       for f in self.tf_frames()]
        return frames_at(head.rotation, head.position, others)

    def _known(self, local: np.ndarray) -> np.ndarray:
        """The rows of ``local`` whose frame has a pose."""
        missing = [self.frames.index(f) for f in self.tf_frames() if f not in self._tf]
        if not missing:
            return local
        return local[~np.isin(local[:, L_FRAME], missing)]

    def posed(self, head_prev, head, dt: float) -> np.ndarray:
        """The posed table of a substep ``dt`` [s] over which the head moves from ``head_prev``
        to ``head`` (the torso frame with it)."""
        now = self._frames(head)
        before = self._frames(head_prev)
        return posed(self._known(self.local), now[0], now[1], before[0], before[1],
                     JUMP_SPEED * dt)

    def posed_bare(self, head) -> np.ndarray:
        """The bare shapes (no margin) at the head pose ``head``, for measuring depth."""
        now = self._frames(head)
        return posed(self._known(self.bare), now[0], now[1])

    def depth(self, x, head, inv_mass=None) -> float:
        """Deepest node [m] of ``x`` (S, N, 3, float64 or float32) inside the bare shapes at
        the head pose ``head``; with ``inv_mass`` (S, N) only the free nodes count."""
        out = np.zeros(x.shape[0])
        mass = np.zeros((0, 0)) if inv_mass is None else inv_mass
        deepest(x, mass, inv_mass is not None, self.posed_bare(head), out)
        return float(out.max()) if out.size else 0.0

    def push_cap(self, dt: float) -> float:
        """The push-out bound of a substep ``dt`` [s]: ``body.max_push_speed * dt`` [m]."""
        return float(self.spec.max_push_speed) * dt if math.isfinite(dt) else -1.0


def make_body(spec, shortest_segment: float, head=None,
              colliders=None) -> Optional[SceneBody]:
    """The scene's :class:`SceneBody` for its ``body`` section ``spec`` and its collider slots
    ``colliders`` (``scene.colliders``; ``head`` as there), ``None`` without ``body.bust`` and
    without a used slot."""
    extra = slot_shapes(colliders) if colliders is not None else []
    return SceneBody(spec, shortest_segment, head, extra) if spec.bust or extra else None
