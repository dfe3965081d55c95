"""Settling hair with the head still: a fixed time, then on until it comes to rest."""
from typing import Callable, Sequence

import numpy as np

#: A settle until still goes on this long [s] at a time ...
SETTLE_CHUNK_S = 0.1
#: ... and, with the fixed time before it, at most this long [s] in all.
MAX_SETTLE_S = 30.0


def settle(run: Callable[[int], None], nodes: Callable[[], Sequence[np.ndarray]], dt: float,
           settle_time: float, settle_speed: float) -> float:
    """Run ``settle_time`` [s] of substeps ``dt`` [s] (``run(steps)``), then, with
    ``settle_speed`` > 0 [m/s], :data:`SETTLE_CHUNK_S` at a time until no node of ``nodes()``
    (the arrays of positions that settle) moved faster than ``settle_speed`` over the last
    chunk, at most :data:`MAX_SETTLE_S` in all.  Returns the time simulated [s]."""
    steps = int(round(settle_time / dt))
    run(steps)
    settled = steps * dt
    if settle_speed > 0.0:
        chunk = max(1, int(round(SETTLE_CHUNK_S / dt)))
        while settled + chunk * dt <= MAX_SETTLE_S + 1e-9:
            before = [np.array(a, dtype=np.float64) for a in nodes()]
            run(chunk)
            settled += chunk * dt
            moved = max((float(np.max(np.abs(a - b))) if a.size else 0.0
                         for a, b in zip(nodes(), before)), default=0.0)
            if moved <= settle_speed * chunk * dt:
                break
    return settled
