"""What every ghost tracker is to the simulator: the one interface the paper's tracker
(:class:`~hair_tracking.ghosts.tracker.GhostTracker`, ``tracking.mode: paper``), the blend tracker
(:class:`~hair_tracking.ghosts.blend.BlendTracker`) and the turn tracker
(:class:`~hair_tracking.ghosts.turn.TurnTracker`) implement.

A tracker owns the ghosts' state, in whatever layout its kernel needs: it takes the ghost
strands' ``x`` and ``v`` as its start state when it is built and from then on is the only
place that state lives.  The caller moves it with :meth:`GhostTracking.step`,
:meth:`~GhostTracking.reset`, :meth:`~GhostTracking.carry` and
:meth:`~GhostTracking.zero_velocities`, and reads it with :meth:`~GhostTracking.positions`,
:meth:`~GhostTracking.part_positions`, :meth:`~GhostTracking.write_records` and
:meth:`~GhostTracking.velocities`.  A tracker may defer work to those reads (the blend and turn
trackers place the ghosts only when the hair is read, once per output frame however many steps
came in between); nothing else runs its kernels.
"""
from typing import Dict, NamedTuple, Optional, Protocol, runtime_checkable, Tuple

import numpy as np

from hair_tracking.core.model import HeadPose


class TrackStep(NamedTuple):
    """What one tracking step follows: the guides moved from ``guide_x_old`` to ``guide_x``
    ((G, M, 3), world [m]) over ``substeps`` guide substeps lasting ``dt`` [s] in all, and the
    head is at ``head`` at the end.  The paper's tracker integrates over the step (it reads
    every field); the blend and turn trackers place the ghosts from ``guide_x`` and ``head``
    (a caller that runs only those may leave ``guide_x_old`` None instead of keeping a copy of
    the guides)."""

    dt: float
    substeps: int
    guide_x_old: Optional[np.ndarray]
    guide_x: np.ndarray
    head: HeadPose


@runtime_checkable
class GhostTracking(Protocol):
    """The interface of a ghost tracker (see the module docstring).  Positions and velocities
    are (S, N, 3) in the ghosts' row order, world frame, [m] and [m/s]."""

    #: counters of the tracker (at least ``steps`` and ``parallel``: 1 when its kernel runs
    #: the parallel variant)
    stats: Dict[str, int]
    #: (S,) the ghosts' row order: row ``i`` is the groom's strand ``permutation[i]`` (the
    #: paper tracker groups them by guide; the others keep the groom's order)
    permutation: np.ndarray

    def step(self, motion: TrackStep) -> None:
        """Move the ghosts after the guides (see :class:`TrackStep`)."""

    def reset(self, head: HeadPose) -> None:
        """Every ghost in its rest shape carried by ``head``, at rest."""

    def carry(self, old: HeadPose, new: HeadPose) -> None:
        """Every ghost moved rigidly with the head from ``old`` to ``new``, at rest (a
        teleport or time going backwards: no whip)."""

    def zero_velocities(self) -> None:
        """The ghosts at rest where they are."""

    def positions(self) -> np.ndarray:
        """The ghost positions now (read only)."""

    def velocities(self) -> np.ndarray:
        """The ghost velocities now (read only)."""

    def part_positions(self, part: int, parts: int) -> Tuple[np.ndarray, np.ndarray]:
        """``(strand indices, their positions)`` of part ``part`` of ``parts`` of the ghosts
        (the parts together are every strand once)."""

    def write_records(self, words: np.ndarray, stride: int, rot: Optional[np.ndarray] = None,
                      origin: Optional[np.ndarray] = None) -> bool:
        """The positions as float32 x y z at the start of ``words``' point records
        (:func:`~hair_tracking.core.point_records.points_to_records`); True when all are
        finite."""
