"""Load shedding for a live pose stream: track the ghosts once per pose while the node cannot
keep up, and every substep again once it can.

A live node has one pose period (16.7 ms at 60 Hz) for each pose. When the step takes longer, poses
queue up, each later call has more substeps due, and the step grows until it hits
``solver.max_substeps``: the latency grows to many pose periods. Real-time renderers lower their
level of detail under load instead; here the lever is the tracking schedule
(``tracking.every_substep``): tracking the ghosts once per pose over all its substeps costs one
tracking step instead of 4 (60 Hz poses, 240 Hz substeps), and is the paper's own setting (the
ghosts follow the targets once per frame).

The decision uses the work of the last :data:`WINDOW` poses (the node passes the step plus the
publishing done since the previous pose: the time its one thread spends per pose; medians, so
one slow pose does not flip it) against the pose period (median interval of their stamps):

* shed when the work, tracking every substep, takes more than ``budget`` of the period;
* restore when the work it *would* take tracking every substep, estimated as the shed work
  plus ``substeps - 1`` more tracking steps, is below ``RESTORE_FRACTION * budget`` of the
  period (the gap keeps it from switching back and forth);
* shed at once, without waiting for half a window, when :data:`URGENT_POSES` poses in a row
  took longer than :data:`URGENT` pose periods each: the node then falls further behind with
  every pose (each next call has more substeps due), so waiting for the medians would let the
  first poses grow longer and longer.  One slow pose alone still does not decide.

This module imports no ROS package; the node feeds it (:mod:`hair_tracking.ros.node`).  Offline
runs (``hair_sim_bag run``) never shed: their output must be a function of the input alone.
"""
from collections import deque
from statistics import median
from typing import Optional

#: Poses whose timings decide (medians).
WINDOW = 8
#: Restore only when the full schedule is estimated below this fraction of the budget.
RESTORE_FRACTION = 2.0 / 3.0
#: Work above this many pose periods on URGENT_POSES poses in a row sheds at once.
URGENT = 1.0
URGENT_POSES = 2


class LoadShedder:
    """Decides, pose by pose, whether the ghosts are tracked once per pose (see module doc).

    ``budget``: the share of the pose period a step may take (0 < budget); ``shedding`` is the
    current decision, ``switches`` counts the changes.
    """

    def __init__(self, budget: float = 0.7):
        if not budget > 0.0:
            raise ValueError(f'budget: must be > 0 (a share of the pose period), got {budget!r}')
        self.budget = float(budget)
        self.shedding = False
        self.switches = 0
        self._last_stamp: Optional[int] = None
        self._periods = deque(maxlen=WINDOW)
        self._full = deque(maxlen=WINDOW)        # step ms, tracking every substep
        self._estimate = deque(maxlen=WINDOW)    # step ms it would take, while shedding

    def reset(self) -> None:
        """Forget the timings (time went backwards, the hair was rebuilt); keep the decision."""
        self._last_stamp = None
        self._periods.clear()
        self._full.clear()
        self._estimate.clear()

    def update(self, stamp_ns: int, step_ms: float, track_ms: float, substeps: int) -> bool:
        """Record one pose: its stamp, the work it took (``step_ms``: the step and, in the
        node, the publishing since the previous pose), the time of its ghost tracking and its
        substeps.  Returns whether the next pose should be tracked once per pose."""
        if self._last_stamp is not None and stamp_ns > self._last_stamp:
            self._periods.append((stamp_ns - self._last_stamp) * 1e-6)
        self._last_stamp = stamp_ns
        if substeps <= 0:
            return self.shedding
        if self.shedding:
            self._estimate.append(step_ms + (substeps - 1) * track_ms)
        else:
            self._full.append(step_ms)
        if not self.shedding and self._periods and len(self._full) >= URGENT_POSES and \
                min(list(self._full)[-URGENT_POSES:]) > URGENT * median(self._periods):
            self._switch(True)
            return True
        if len(self._periods) < WINDOW // 2:
            return self.shedding
        allowed = self.budget * median(self._periods)
        if not self.shedding and len(self._full) >= WINDOW // 2 and \
                median(self._full) > allowed:
            self._switch(True)
        elif self.shedding and len(self._estimate) >= WINDOW and \
                median(self._estimate) < RESTORE_FRACTION * allowed:
            self._switch(False)
        return self.shedding

    def _switch(self, shed: bool) -> None:
        self.shedding = shed
        self.switches += 1
        self._full.clear()
        self._estimate.clear()
