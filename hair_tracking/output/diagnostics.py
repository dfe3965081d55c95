"""The hair's diagnostic status, for every publisher of hair: its level, message and key-value
pairs (diagnostic_msgs/DiagnosticStatus), the part that needs no wall clock.

The ``hair_sim`` node adds its timings, its input's health and its settings around these
(:meth:`hair_tracking.ros.node.HairSimNode.diagnostics`); ``hair_sim_bag run`` writes them as
they are (repeatable runs, no wall-clock values); a ghost shard (``hair_sim_ghosts``) reports
its own counters the same way.
"""
from typing import Dict, List, NamedTuple, Optional

import numpy as np

#: diagnostic_msgs/DiagnosticStatus levels.
OK, WARN, ERROR = 0, 1, 2
HARDWARE_ID = 'hair_tracking'


def status_name(node_name: str) -> str:
    """The status's name: ``<node>: hair simulation``."""
    return f'{node_name}: hair simulation'


class Status(NamedTuple):
    """One diagnostic status without its name: ``level`` (:data:`OK`, :data:`WARN`,
    :data:`ERROR`), ``message`` ('ok' or the problems joined by '; '), ``values`` (key ->
    text, in the order they are published)."""

    level: int
    message: str
    values: Dict[str, str]


def make_status(level: int, problems: List[str], values: Dict[str, str]) -> Status:
    """A :class:`Status` of ``problems`` ('ok' when there are none)."""
    return Status(level, '; '.join(problems) if problems else 'ok', values)


class Counted:
    """Counts that warn when they grew since the previous report: ``check(name: count, ...)``
    returns the problems (``'3 head poses rejected'``) of the counts that grew."""

    def __init__(self):
        self._marks: Dict[str, int] = {}

    def check(self, counts: Dict[str, int]) -> List[str]:
        problems = []
        for what, n in counts.items():
            before = self._marks.get(what, 0)
            if n > before:
                problems.append(f'{n - before} {what}')
            self._marks[what] = n
        return problems


class HairHealth:
    """The simulator's part of the status: substeps dropped and head poses rejected since the
    previous report (WARN), and its counters and figures as values."""

    def __init__(self):
        self._counted = Counted()

    def problems(self, sim, rejected: int) -> List[str]:
        """Substeps dropped and poses rejected since the previous call."""
        return self._counted.check({'substeps dropped': sim.counters.substeps_dropped,
                                    'head poses rejected': rejected})

    @staticmethod
    def values(sim, stretch: float, depth: float, rejected: int, rebuilds: int,
               checked: Optional[np.ndarray] = None) -> Dict[str, str]:
        """``substeps`` ... ``sim_time_ns`` of ``sim`` (a
        :class:`~hair_tracking.simulator.HairSimulator`): its counters, ``stretch`` and
        ``depth`` [m] as measured by the caller (with ``checked``, the ghost strands they were
        measured over), ``rejected`` poses and hair ``rebuilds``."""
        c = sim.counters
        out = {
            'substeps': str(c.substeps),
            'substeps_last': str(c.last_substeps),
            'substeps_dropped': str(c.substeps_dropped),
            'max_stretch': f'{stretch:.6f}',
            'penetration_m': f'{depth:.6f}',
        }
        if checked is not None:
            out['checked_ghosts'] = f'{checked[0]}-{checked[-1]}' if checked.size else 'none'
        out.update({
            'poses_rejected': str(rejected),
            'hair_resets': str(c.resets),
            'hair_rebuilds': str(rebuilds),
            'guides': str(sim.guides.count),
            'ghosts': str(sim.ghosts.count if sim.ghosts is not None else 0),
            'sim_time_ns': str(sim.time_ns if sim.time_ns is not None else 'n/a'),
        })
        return out
