"""A bust for the hair, sized from one height as ROS4HRI's ``human_description`` sizes its
skeleton, and the frame it rides on when no body is tracked.

``human_description`` (the URDF of REP-155 humans, https://github.com/ros4hri/human_description,
``urdf/human-tpl.xacro``) derives every length from ``unit = height / 7.5`` (figure-drawing
proportions): head radius ``unit / 2``, neck ``unit / 4`` from the torso frame ``torso_<id>``
(on the spine at the shoulder line, x forward, y left, z up) to the head's pivot, each
shoulder joint ``0.8 unit`` from the neck along y, the torso ``2.75 unit`` high above the
mid-hip ``body_<id>`` (its spine drawn down to ``3/4`` of that below ``torso_<id>``), upper arm
``1.6 unit`` along ``-z`` of ``l_shoulder_<id>`` / ``r_shoulder_<id>``, limbs 3 cm thick.  Those
numbers place the bust's capsules (:data:`BUST`); their radii, which a stick figure does not
give, are round anthropometric figures in the same unit (neck ``unit / 4``: 5.7 cm at 1.70 m;
chest and trunk half as deep as a unit: 22.7 cm deep at 1.70 m).

:func:`bust` gives the five capsules in the torso frame; :func:`upper_arms` the arms' capsules
on the shoulder frames; :func:`neck_frame` the torso frame's pose from the head pose alone (the
head's pivot under its centre, the torso upright and turned with the head's heading), for a
scene without body tracking.
"""
from collections import namedtuple
import math
from typing import List, Tuple

import numpy as np

from hair_tracking.colliders.shapes import capsule_between, Shape

#: human_description's unit: height / UNITS_PER_HEIGHT.
UNITS_PER_HEIGHT = 7.5
#: [m] human_description's limb radius (its links are drawn as 3 cm cylinders).
LIMB_RADIUS = 0.03

#: The proportions of human_description in metres for one height: ``unit``, ``head_radius``,
#: ``neck_length`` (torso frame to the head's pivot), ``shoulder`` (neck to each shoulder joint
#: along y), ``torso_height`` (mid-hip to the torso frame), ``upper_arm``, ``forearm``,
#: ``limb_radius``.
Body = namedtuple('Body', ['height', 'unit', 'head_radius', 'neck_length', 'shoulder',
                           'torso_height', 'upper_arm', 'forearm', 'limb_radius'])

#: The bust in the torso frame: name, the capsule's segment ends and its radius, in units of
#: ``height / 7.5``.  The neck ends at the head's pivot (0.25 unit up), the shoulders at the
#: shoulder joints (0.8 unit along y, rising toward the neck), the chest spans the shoulders
#: below them, the trunk follows the spine down to 3/4 of the torso height.
BUST: Tuple[Tuple[str, Tuple[float, float, float], Tuple[float, float, float], float], ...] = (
    ('neck', (0.0, 0.0, -0.25), (0.0, 0.0, 0.25), 0.25),
    ('l_shoulder', (0.0, 0.25, 0.1), (0.0, 0.8, 0.0), 0.2),
    ('r_shoulder', (0.0, -0.25, 0.1), (0.0, -0.8, 0.0), 0.2),
    ('chest', (0.0, -0.3, -0.6), (0.0, 0.3, -0.6), 0.5),
    ('trunk', (0.0, 0.0, -0.6), (0.0, 0.0, -2.0625), 0.45),
)


def body(height: float) -> Body:
    """human_description's proportions for a person ``height`` metres tall."""
    if not (isinstance(height, (int, float)) and math.isfinite(height) and 0.3 <= height <= 3.0):
        raise ValueError(f'body.height: must be a person\'s height in metres (0.3 .. 3), got '
                         f'{height!r}')
    unit = float(height) / UNITS_PER_HEIGHT
    return Body(float(height), unit, unit / 2.0, unit * 0.25, unit * 0.8, unit * 2.75,
                unit * 1.6, unit, LIMB_RADIUS)


def bust(height: float, frame: str = 'torso', margin: float = 0.0,
         friction: float = 0.0) -> List[Shape]:
    """The five capsules of :data:`BUST` for ``height`` [m], on ``frame`` (the torso frame:
    ``torso_<id>`` of a tracked person, or the frame of :func:`neck_frame`)."""
    unit = body(height).unit
    return [capsule_between(np.multiply(a, unit), np.multiply(b, unit), r * unit, frame=frame,
                            margin=margin, friction=friction, name=name)
            for name, a, b, r in BUST]


def upper_arms(height: float, person: str, margin: float = 0.0,
               friction: float = 0.0) -> List[Shape]:
    """The upper arms of person ``person`` (REP-155 id) as human_description draws them:
    capsules of the limb radius from each shoulder joint down ``-z`` of ``l_shoulder_<id>`` /
    ``r_shoulder_<id>`` for the upper-arm length."""
    b = body(height)
    return [capsule_between((0.0, 0.0, 0.0), (0.0, 0.0, -b.upper_arm), b.limb_radius,
                            frame=f'{side}_shoulder_{person}', margin=margin, friction=friction,
                            name=f'{side}_upper_arm')
            for side in ('l', 'r')]


def neck_frame(head_rot, head_pos, height: float) -> Tuple[np.ndarray, np.ndarray]:
    """The torso frame ``(rotation (3, 3), origin (3,))`` in the world from the head pose alone
    (head frame origin at the head's centre): the head's pivot is ``head_radius`` below the
    centre in the head frame (human_description puts the head sphere's centre that far above
    the pivot), the torso frame ``neck_length`` below the pivot, upright (z up) and turned
    about z by the head's heading (the twist of the head's rotation about z, ``2 atan2(q_z,
    q_w)``), so nodding and tilting bend the neck and leave the shoulders level."""
    b = body(height)
    r = np.asarray(head_rot, dtype=np.float64)
    p = np.asarray(head_pos, dtype=np.float64)
    pivot = p - r[:, 2] * b.head_radius
    yaw = math.atan2(r[1, 0] - r[0, 1], r[0, 0] + r[1, 1])
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rot, pivot - np.array([0.0, 0.0, b.neck_length])
