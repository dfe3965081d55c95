"""How much CPU time the hypervisor took from this virtual machine (Linux ``/proc/stat``).

On a shared VM the same work can take 1.5-3x longer from one hour to the next, and the main
cause on the project's machine is *steal*: time the hypervisor ran other guests while this VM
had work (the 8th value of the ``cpu`` line of ``/proc/stat``).  Timings taken while it is high
say more about the neighbours than about the code, so the benchmarks in ``scripts/`` report the
stolen share next to their timings.
Standard library only; where ``/proc/stat`` cannot be read (not Linux) every figure is None.
"""
from typing import Optional, Tuple

STAT_PATH = '/proc/stat'


def cpu_times(path: str = STAT_PATH) -> Optional[Tuple[int, int]]:
    """(steal, total) jiffies over all CPUs since boot, or None if ``path`` is unreadable."""
    try:
        with open(path) as f:
            fields = f.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != 'cpu':
        return None
    try:
        values = [int(v) for v in fields[1:]]
    except ValueError:
        return None
    # user nice system idle iowait irq softirq steal [guest guest_nice]: the guest times are
    # already counted in user and nice
    counted = values[:8]
    steal = counted[7] if len(counted) > 7 else 0
    return steal, sum(counted)


def steal_share(before: Optional[Tuple[int, int]],
                after: Optional[Tuple[int, int]]) -> Optional[float]:
    """The share (0..1) of CPU time stolen between two :func:`cpu_times` readings, or None
    when either is missing or no time passed."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return max(0.0, (after[0] - before[0]) / (after[1] - before[1]))


class StealMeter:
    """The stolen share since the previous :meth:`share` call (or since construction)."""

    def __init__(self, path: str = STAT_PATH):
        self.path = path
        self._mark = cpu_times(path)

    def share(self) -> Optional[float]:
        now = cpu_times(self.path)
        out = steal_share(self._mark, now)
        if now is not None and (self._mark is None or now[1] > self._mark[1]):
            self._mark = now
        return out


def format_share(share: Optional[float]) -> str:
    """``'12.3 %'``, or ``'n/a'`` when unknown."""
    return 'n/a' if share is None else f'{share * 100:.1f} %'
