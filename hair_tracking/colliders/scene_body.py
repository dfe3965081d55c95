"""The scene's body as one strand set meets it: the bust (``body.*``) of
:func:`~hair_tracking.colliders.body.bust` on the torso frame and the further colliders of the
scene's slots (``colliders.<slot>.*``), each on its frame, posed for a substep from the head
poses at its start and end (the frames' poses are the table's,
:class:`~hair_tracking.colliders.table.ColliderTable`).

The margin is the scene's ``body.margin`` (a slot's ``margin``) capped at half the hair's
shortest segment (:func:`~hair_tracking.colliders.margin.fit_margin` without a rest clearance:
the rest shape of a groom is given in the head frame and may hang through the body; the bust is
what keeps it out).
"""
from dataclasses import replace
import math
from typing import List, Optional

import numpy as np

from hair_tracking.colliders.body import bust
from hair_tracking.colliders.kernels import deepest
from hair_tracking.colliders.margin import fit_margin
from hair_tracking.colliders.pose import posed
from hair_tracking.colliders.shapes import Shape, shape_table

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
    """The bust of the table's ``body`` section (none without ``body.bust``) and the table's
    slot shapes, as a strand set whose shortest positive segment is ``shortest_segment`` [m]
    meets them (their margins fitted to it); :meth:`posed` gives a substep's posed table, its
    frames posed by ``table`` (a :class:`~hair_tracking.colliders.table.ColliderTable`, which
    holds the frames' poses for every strand set).  ``head``: the head's row (margin fitted)
    the strand set is kept out of in the same pass, put first, so that a node pushed out of
    the neck is not left in the head (none: the bust and slots alone)."""

    def __init__(self, table, shortest_segment: float, head: Optional[Shape] = None):
        self.table = table
        spec = self.spec = table.body_spec
        margin = fit_margin(bust(spec.height, margin=spec.margin)[0], None,
                            [shortest_segment]) if shortest_segment > 0 else float(spec.margin)
        self.margin = margin
        shapes = bust(spec.height, frame=TORSO, margin=margin, friction=spec.friction) \
            if spec.bust else []
        extra = [replace(s, margin=fit_margin(s, None, [shortest_segment]))
                 if shortest_segment > 0 else s for s in table.extra]
        self.shapes = shapes + extra
        #: the shapes before the bust in the table (the head's row, when given)
        self.lead = 0 if head is None else 1
        rows = ([head] if head is not None else []) + self.shapes
        self.local = shape_table(rows, frames=table.frames)
        self.bare = shape_table([replace(s, margin=0.0) for s in self.shapes],
                                frames=table.frames)

    def posed(self, head_prev, head, dt: float) -> np.ndarray:
        """The posed table of a substep ``dt`` [s] over which the head moves from ``head_prev``
        to ``head`` (the torso frame with it)."""
        now = self.table.frame_poses(head)
        before = self.table.frame_poses(head_prev)
        return posed(self.table.known(self.local), now[0], now[1], before[0], before[1],
                     JUMP_SPEED * dt)

    def posed_bare(self, head) -> np.ndarray:
        """The bare shapes (no margin) at the head pose ``head``, for measuring depth."""
        now = self.table.frame_poses(head)
        return posed(self.table.known(self.bare), now[0], now[1])

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


def make_body(table, shortest_segment: float,
              head: Optional[Shape] = None) -> Optional[SceneBody]:
    """The :class:`SceneBody` of ``table`` for a strand set (arguments as there), ``None``
    when the table has no bust and no slot shape."""
    return SceneBody(table, shortest_segment, head) \
        if table.body_spec.bust or table.extra else None
