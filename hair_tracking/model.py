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


@dataclass
class StrandSet:
    """Topology and rest shape of a set of strands, plus their dynamic state."""

    rest: np.ndarray          # (S, N, 3) rest node positions, head frame [m]
    rest_length: np.ndarray   # (S, N-1) rest segment lengths [m]
    inv_mass: np.ndarray      # (S, N) inverse masses; 0 for the two attached root nodes
    x: np.ndarray             # (S, N, 3) positions, world frame [m]
    v: np.ndarray             # (S, N, 3) velocities, world frame [m/s]

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
