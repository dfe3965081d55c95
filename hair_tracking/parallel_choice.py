"""Run a kernel on all threads or on one, whichever this machine makes faster right now.

The static rule (:func:`hair_tracking.guides.integrate.runs_parallel`: enough nodes and more than
one
numba thread) assumes that every thread gets a core.  On a shared virtual machine it does not
always: while the hypervisor runs other guests on one of this VM's two vCPUs (steal time,
``/proc/stat``), a parallel region waits at its end for the thread that was taken away, and the
parallel kernel becomes slower than its serial twin.  Measured here with 10 k ghosts, one
tracking substep, alternating the variants in one process: in a phase with 16-25 % of the CPU
time stolen, two threads 8.5 ms against 6.3 ms on one (the second vCPU cost more than it
brought); in a quiet phase 3.4 ms against 6 ms.

:class:`ParallelChooser` therefore times the call site and keeps whichever variant was faster:
the static rule's choice first, and after ``settle`` calls a short trial of the other one
(``window`` calls, fewer when it has lost already) compared with the median of the current
one's last ``window`` calls, again every ``reprobe`` calls.  The variants give bit-identical
results (the serial twins are the same code, see
:func:`hair_tracking.guides.integrate.serial_twin`),
so the choice changes speed only, never the output.  Standard library only.
"""
import statistics
import time


class ParallelChooser:
    """Chooses between the parallel and the serial variant of one call site from timings.

    Usage per call: ``parallel = chooser.choose(static)`` (``static``: what the static rule
    says; False means the problem is too small or there is one thread: serial, no trial), run
    that variant, then ``chooser.record(seconds)``.

    ``window`` calls make a trial and the reference it is compared with (medians); the other
    variant is taken when its median is below ``margin`` times the current one's; ``settle``
    calls run before the first trial, ``reprobe`` calls between trials.
    """

    def __init__(self, window: int = 8, settle: int = 64, reprobe: int = 512,
                 margin: float = 0.9):
        if window < 1 or settle < window or reprobe < window or not 0.0 < margin <= 1.0:
            raise ValueError(f'ParallelChooser: window >= 1, settle and reprobe >= window, '
                             f'0 < margin <= 1; got {window}, {settle}, {reprobe}, {margin}')
        self.window, self.settle, self.reprobe, self.margin = window, settle, reprobe, margin
        self.parallel = True         # the current choice while the static rule allows both
        self.switches = 0            # times the choice changed after a trial
        self.trials = 0
        self._recent = []            # the current choice's last ``window`` timings [s]
        self._trial = []             # the other variant's timings during a trial [s]
        self._until_trial = settle
        self._running = None         # the variant handed out by the last choose()
        self._allowed = False

    @property
    def in_use(self) -> bool:
        """Whether the parallel kernel is the current choice (False while the static rule
        forbids it)."""
        return self._allowed and self.parallel

    def choose(self, static: bool) -> bool:
        """The variant to run now: True for the parallel kernel."""
        if not static:               # too small or one thread: serial, forget the timings
            if self._allowed:
                self._reset()
            self._running = False
            return False
        self._allowed = True
        trying = self._until_trial <= 0 and len(self._recent) >= self.window
        self._running = (not self.parallel) if trying else self.parallel
        return self._running

    def record(self, seconds: float) -> None:
        """The duration of the call that :meth:`choose` chose for."""
        if not self._allowed or self._running is None:
            return
        if self._running == self.parallel:
            self._recent.append(seconds)
            del self._recent[:-self.window]
            self._until_trial -= 1
            return
        self._trial.append(seconds)
        bar = self.margin * statistics.median(self._recent)
        # A trial whose median can no longer beat the bar ends at once: with more than half of
        # its window at or above the bar, the median is too (the losing variant is often
        # twice as slow, and every call of a trial is a slow frame).
        lost = sum(1 for t in self._trial if t >= bar) > self.window // 2
        if len(self._trial) < self.window and not lost:
            return
        self.trials += 1
        if not lost and statistics.median(self._trial) < bar:
            self.parallel = not self.parallel
            self.switches += 1
            self._recent = self._trial[-self.window:]
        self._trial = []
        self._until_trial = self.reprobe

    def timed(self, static: bool, parallel_fn, serial_fn, *args):
        """``parallel_fn(*args)`` or ``serial_fn(*args)`` as :meth:`choose` says, timed."""
        fn = parallel_fn if self.choose(static) else serial_fn
        start = time.perf_counter()
        out = fn(*args)
        self.record(time.perf_counter() - start)
        return out

    def _reset(self) -> None:
        self.parallel = True
        self._recent, self._trial = [], []
        self._until_trial = self.settle
        self._allowed = False
