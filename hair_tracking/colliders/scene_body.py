"""The scene's body (``body.*``): the bust of :func:`~hair_tracking.colliders.body.bust` on the
torso frame, posed for a substep from the head poses at its start and end.

The torso frame is the TF frame ``body.frame`` when one is named and its pose is known (the node
looks it up at each head pose and hands it over with :meth:`SceneBody.set_frame`; the last pose
received is kept while none arrives), else the neck frame of the head pose
(:func:`~hair_tracking.colliders.body.neck_frame`: the head's pivot ``height / 15`` below the
head centre, the torso frame ``height / 30`` below the pivot, upright, turned about the vertical
by the head's heading, so nodding and tilting bend the neck and leave the shoulders level, and
turning the head turns the shoulders with it).

The margin is the scene's ``body.margin`` capped at half the hair's shortest segment
(:func:`~hair_tracking.colliders.margin.fit_margin` without a rest clearance: the rest shape of
a groom is given in the head frame and may hang through the body; the bust is what keeps it
out).
"""
import math
from typing import Optional, Tuple

import numpy as np

from hair_tracking.colliders.body import bust, neck_frame
from hair_tracking.colliders.kernels import deepest
from hair_tracking.colliders.margin import fit_margin
from hair_tracking.colliders.pose import frames_at, posed
from hair_tracking.colliders.shapes import FIXED_FRAME, HEAD_FRAME, Shape, shape_table

#: The frame name the bust's shapes ride on in its table (the third frame of the table).
TORSO = 'torso'
#: [m / s] A torso frame that moves faster than this over a substep jumped (a re-detected
#: person, a TF glitch): that substep it is taken as not moving (colliders.pose).
JUMP_SPEED = 10.0


class SceneBody:
    """The bust of a scene's ``body`` section for a strand set whose shortest positive segment
    is ``shortest_segment`` [m]; :meth:`posed` gives a substep's posed table.  ``head``: the
    head collider the strand set is kept out of, ``(center, axes)`` (head frame, the margin
    included), put first in the table, so that a node pushed out of the neck is not left in
    the head (none: the bust alone)."""

    def __init__(self, spec, shortest_segment: float, head=None):
        self.spec = spec
        shapes = bust(spec.height, frame=TORSO, margin=spec.margin, friction=spec.friction)
        margin = fit_margin(shapes[0], None, [shortest_segment]) if shortest_segment > 0 \
            else float(spec.margin)
        self.margin = margin
        shapes = bust(spec.height, frame=TORSO, margin=margin, friction=spec.friction)
        self.shapes = shapes
        #: the shapes before the bust in the table (the head collider, when given)
        self.lead = 0 if head is None else 1
        if head is not None:
            shapes = [Shape('ellipsoid', frame=HEAD_FRAME, center=tuple(head[0]),
                            radii=tuple(head[1]), name='head')] + shapes
        self.local = shape_table(shapes, frames=(FIXED_FRAME, HEAD_FRAME, TORSO))
        self.bare = shape_table(bust(spec.height, frame=TORSO),
                                frames=(FIXED_FRAME, HEAD_FRAME, TORSO))
        self._frame: Optional[Tuple[np.ndarray, np.ndarray]] = None

    def set_frame(self, rotation, position) -> None:
        """The pose of the TF frame ``body.frame`` in the fixed frame of the head pose (kept
        until the next one)."""
        self._frame = (np.array(rotation, dtype=np.float64).reshape(3, 3),
                       np.array(position, dtype=np.float64).reshape(3))

    def torso(self, head) -> Tuple[np.ndarray, np.ndarray]:
        """The torso frame ``(rotation, origin)`` for the head pose ``head``."""
        if self.spec.frame and self._frame is not None:
            return self._frame
        return neck_frame(head.rotation, head.position, self.spec.height)

    def posed(self, head_prev, head, dt: float) -> np.ndarray:
        """The posed table of a substep ``dt`` [s] over which the head moves from ``head_prev``
        to ``head`` (the torso frame with it)."""
        now = frames_at(head.rotation, head.position, [self.torso(head)])
        before = frames_at(head_prev.rotation, head_prev.position, [self.torso(head_prev)])
        return posed(self.local, now[0], now[1], before[0], before[1], JUMP_SPEED * dt)

    def posed_bare(self, head) -> np.ndarray:
        """The bare bust (no margin) at the head pose ``head``, for measuring depth."""
        now = frames_at(head.rotation, head.position, [self.torso(head)])
        return posed(self.bare, now[0], now[1])

    def depth(self, x, head, inv_mass=None) -> float:
        """Deepest node [m] of ``x`` (S, N, 3, float64 or float32) inside the bare bust at the
        head pose ``head``; with ``inv_mass`` (S, N) only the free nodes count."""
        out = np.zeros(x.shape[0])
        mass = np.zeros((0, 0)) if inv_mass is None else inv_mass
        deepest(x, mass, inv_mass is not None, self.posed_bare(head), out)
        return float(out.max()) if out.size else 0.0

    def push_cap(self, dt: float) -> float:
        """The push-out bound of a substep ``dt`` [s]: ``body.max_push_speed * dt`` [m]."""
        return float(self.spec.max_push_speed) * dt if math.isfinite(dt) else -1.0


def make_body(spec, shortest_segment: float, head=None) -> Optional[SceneBody]:
    """The scene's :class:`SceneBody` (``head`` as there), ``None`` without ``body.bust``."""
    return SceneBody(spec, shortest_segment, head) if spec.bust else None
