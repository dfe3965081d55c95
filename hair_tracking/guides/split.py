"""The substep split rule: how many equal parts a substep is split into when the hair moves fast.

A substep in which a hair node would move farther than half the per-substep displacement clamp
(``solver.max_displacement``; :data:`SPLIT_DISTANCE` when the clamp is off) is *split* into
equal shorter substeps, at most :data:`MAX_SPLIT` and none shorter than :data:`MIN_SPLIT_DT`,
with the head interpolated between its two poses (lerp, slerp: :func:`split_heads`).  The
estimate is the larger of the head's rigid motion at the farthest hair node
(:meth:`SplitRule.rigid`) and the largest node speed of the previous substep times ``dt``,
plus ``|g| dt^2`` (:func:`split_motion`).  Without this the clamp, a safety net, would become
the dynamics in fast motion (a 20 m/s head moves a root 8 cm per 1/240 s substep; a 1/10 s
substep lets hair fall 5 cm) and tear the strands apart: measured in the stability matrix
(docs/stability.md), up to 1500 % stretch.  The split count depends only on the state, so runs
stay deterministic.

The rule is applied in two places with the same arithmetic: in Python between runs of substeps
(:meth:`SplitRule.parts`, by :func:`run_split`, the loop of the simulator and of the crowd) and
inside the compiled guide runs (:func:`split_due`, the stop rule of
:func:`~hair_tracking.guides.ftl.ftl_advance`), which end a run before the first substep after
one the rule would split: so a run is the hair of the substeps taken one by one.  Both read
:func:`split_motion` (compiled without fast-math flags: the Python and the compiled decision
agree to the last bit).
"""
import math
from typing import Callable, Sequence, Tuple

from numba import njit

from hair_tracking.core.model import HeadPose
from hair_tracking.core.transforms import quat_angle, quat_to_matrix, slerp

#: Most parts one substep is split into when the hair moves fast.
MAX_SPLIT = 16
#: Parts are never shorter than this [s]: FTL's velocity correction injects energy into long
#: strands at very short substeps (docs/stability.md), so splitting must not drive dt there.
MIN_SPLIT_DT = 1.0 / 960.0
#: Split when the estimated node motion of a substep exceeds this fraction of the clamp ...
SPLIT_FRACTION = 0.5
#: ... or this distance [m] when the clamp is off (``solver.max_displacement = 0``).
SPLIT_DISTANCE = 0.025


@njit(cache=True)
def split_motion(step, rigid, gdt2):
    """The estimated node motion [m] of a substep: the larger of ``step`` [m] (the largest
    node displacement of the previous substep, as a speed times ``dt``) and ``rigid`` [m] (how
    far the head's motion carries the farthest node; kept when ``step`` is NaN), plus
    ``gdt2`` = ``|g| dt^2``."""
    return (step if step > rigid else rigid) + gdt2


@njit(cache=True)
def split_due(far, dt, rigid, gdt2, limit):
    """Whether a substep ``dt`` whose head moves hair nodes by ``rigid`` [m], after one whose
    largest squared node displacement was ``far`` [m^2], is split (its :func:`split_motion`
    above ``limit``): the compiled guide runs' stop rule."""
    return split_motion(math.sqrt(far) / dt * dt, rigid, gdt2) > limit


class SplitRule:
    """The split rule of one hair: ``max_displacement`` the scene's per-substep clamp [m] (0:
    off), ``gravity_norm`` ``|g|`` [m/s^2], ``reach`` the farthest any hair node can be from
    the head origin [m] (root distance + strand length)."""

    def __init__(self, max_displacement: float, gravity_norm: float, reach: float):
        self.max_displacement = float(max_displacement)
        self.gravity_norm = float(gravity_norm)
        self.reach = float(reach)

    def limit(self, dt: float) -> Tuple[float, int]:
        """``(limit, floor)``: the node motion [m] above which a substep ``dt`` is split, and
        the most parts it may be split into without going below :data:`MIN_SPLIT_DT`."""
        md = self.max_displacement
        limit = SPLIT_FRACTION * md if md > 0 else SPLIT_DISTANCE
        return limit, max(1, int(dt / MIN_SPLIT_DT + 1e-9))

    def gdt2(self, dt: float) -> float:
        """``|g| dt^2`` [m]: how far gravity moves a node in a substep ``dt``."""
        return self.gravity_norm * dt * dt

    def parts(self, dt: float, rigid: float, speed: float) -> int:
        """Parts to split a substep ``dt`` into so that no node moves farther than the split
        limit, with ``rigid`` [m] how far the head's motion carries the farthest node
        (:meth:`rigid`) and ``speed`` [m/s] the nodes' largest speed."""
        limit, floor = self.limit(dt)
        motion = split_motion.py_func(speed * dt, rigid, self.gdt2(dt))
        if not motion > limit:          # also False for NaN: never split on bad numbers
            return 1
        return int(min(MAX_SPLIT, floor, math.ceil(motion / limit)))

    def stop(self, dt: float, rigid: Sequence[float]) -> tuple:
        """The compiled runs' stop rule for substeps ``dt`` with the head motions ``rigid``
        (one a substep): ``(rigid, limit, gdt2)``, the limit 0 (not applied) where no substep
        may be split (:data:`MIN_SPLIT_DT`)."""
        limit, floor = self.limit(dt)
        return rigid, limit if floor > 1 else 0.0, self.gdt2(dt)

    def rigid(self, head_prev: HeadPose, head: HeadPose) -> float:
        """How far [m] the head's motion from ``head_prev`` to ``head`` carries the farthest
        hair node."""
        angle = quat_angle(head_prev.quaternion, head.quaternion)
        dx, dy, dz = (head.position - head_prev.position).tolist()
        return math.sqrt(dx * dx + dy * dy + dz * dz) + 2.0 * math.sin(0.5 * angle) * self.reach

    def rigid_run(self, head_prev: HeadPose, heads: Sequence[HeadPose]):
        """:meth:`rigid` of every substep from ``head_prev`` through ``heads``."""
        return [self.rigid(a, b) for a, b in zip([head_prev] + list(heads[:-1]), heads)]


def run_split(n: int, parts: Callable[[int], int], split: Callable[[int, int], None],
              run: Callable[[int], int]) -> None:
    """Substeps ``0 .. n - 1`` under the split rule: substep ``k`` is split into
    ``parts(k)`` parts by ``split(k, parts)`` when that is more than one, else a run of
    substeps from ``k`` is taken by ``run(k)``, which returns how many it took (at least one;
    it stops before the first substep after one the rule would split, :func:`split_due`)."""
    k = 0
    while k < n:
        p = parts(k)
        if p > 1:
            split(k, p)
            k += 1
        else:
            k += run(k)


def split_heads(head_prev: HeadPose, head: HeadPose, parts: int):
    """The ends of ``parts`` equal parts of a substep from ``head_prev`` to ``head``: the
    positions interpolated linearly, the rotations by slerp, ``head`` last."""
    heads = []
    for k in range(1, parts):
        u = k / parts
        q = slerp(head_prev.quaternion, head.quaternion, u)
        heads.append(HeadPose((1.0 - u) * head_prev.position + u * head.position, q,
                              quat_to_matrix(q)))
    return heads + [head]
