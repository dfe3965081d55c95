"""Static strand data (built once from the scene) apart from changing state.

All arrays are C-contiguous float64.  ``S`` strands, ``N`` nodes per strand (uniform within a
strand set; guides and ghosts may differ).  Rest data live in the head frame; state lives in the
world frame (the fixed frame of the head-pose stream).
"""
from dataclasses import dataclass

import numpy as np


@dataclass
class HeadPose:
    """Head transform at one instant: ``p_world = position + rotation @ p_head``."""

    position: np.ndarray      # (3,) metres
    quaternion: np.ndarray    # (4,) x, y, z, w, unit, sign-continuous
    rotation: np.ndarray      # (3, 3)

    def to_world(self, points_head):
        return points_head @ self.rotation.T + self.position

    def to_head(self, points_world):
        return (points_world - self.position) @ self.rotation


def carry_rigidly(points: np.ndarray, old: HeadPose, new: HeadPose) -> np.ndarray:
    """``points`` (..., 3), world frame, moved rigidly with the head from pose ``old`` to pose
    ``new``: ``R_new R_old^T (p - p_old) + p_new``."""
    rot = new.rotation @ old.rotation.T
    return (points - old.position) @ rot.T + new.position


def part_rows(count: int, part: int, parts: int) -> slice:
    """Rows ``count * part // parts .. count * (part + 1) // parts - 1`` of ``count``: part
    ``part`` of ``parts`` (the parts together are every row once)."""
    part, parts = int(part), int(parts)
    if not 0 <= part < parts:
        raise ValueError(f'strand part {part} of {parts} does not exist')
    return slice(count * part // parts, count * (part + 1) // parts)


def strand_part(count: int, part: int, parts: int) -> np.ndarray:
    """Indices of the strands of part ``part`` of ``parts`` of ``count`` strands
    (:func:`part_rows`)."""
    rows = part_rows(count, part, parts)
    return np.arange(rows.start, rows.stop)


class StrandSet:
    """Topology and rest shape of a set of strands, plus a state: plain data.

    ``rest`` (S, N, 3) rest node positions, head frame [m]; ``rest_length`` (S, N-1) rest
    segment lengths [m]; ``inv_mass`` (S, N) inverse masses, 0 for the two attached root nodes;
    ``x`` (S, N, 3) positions, world frame [m]; ``v`` (S, N, 3) velocities [m/s].

    The guide solver advances ``x`` and ``v`` of the guides in place.  A ghost tracker takes
    the ghosts' ``x`` and ``v`` as its start state when it is built and keeps the state in a
    layout of its own from then on: read the ghosts from the tracker
    (:class:`~hair_tracking.ghosts.interface.GhostTracking`), not from these arrays.
    """

    def __init__(self, rest: np.ndarray, rest_length: np.ndarray, inv_mass: np.ndarray,
                 x: np.ndarray, v: np.ndarray):
        self.rest = rest
        self.rest_length = rest_length
        self.inv_mass = inv_mass
        self.x = x
        self.v = v

    @staticmethod
    def from_rest(rest: np.ndarray) -> 'StrandSet':
        rest = np.ascontiguousarray(rest, dtype=np.float64)
        seg = np.linalg.norm(np.diff(rest, axis=1), axis=2)
        inv_mass = np.ones(rest.shape[:2])
        inv_mass[:, :2] = 0.0
        return StrandSet(rest=rest, rest_length=np.ascontiguousarray(seg),
                         inv_mass=inv_mass, x=rest.copy(), v=np.zeros_like(rest))

    @property
    def count(self) -> int:
        return self.rest.shape[0]

    @property
    def nodes(self) -> int:
        return self.rest.shape[1]

    @property
    def strand_length(self) -> np.ndarray:
        return self.rest_length.sum(axis=1)

    def place_at(self, head: HeadPose) -> None:
        """Put every strand in its rest shape carried by ``head``, at rest."""
        self.x[...] = head.to_world(self.rest)
        self.v[...] = 0.0
