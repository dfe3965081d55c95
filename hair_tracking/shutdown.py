"""How every executable stops: SIGINT (Ctrl-C) and SIGTERM ask it to stop, and it stops promptly
with exit code 0 and its outputs closed, whatever it is waiting for.

One :class:`StopRequest` per process, made by :func:`hair_tracking.executable.started` before
anything else in an executable's ``main()`` (docs/architecture.md, "How the executables stop",
says why it works so):

* Its handler for SIGINT and SIGTERM only records the request; it raises nothing, so no
  exception ever lands inside rclpy's conversion of a message or a half-written bag.  The
  handler is installed even where SIGINT starts ignored (a background job of a shell script):
  SIGINT is how Ctrl-C and ``ros2 launch`` ask a process to stop.
* A signal handled by Python runs its handler only when the main thread is back in the
  interpreter, and an rclpy executor can sit in its wait for ever: every timer of a node with
  ``use_sim_time`` runs on ``/clock``, which may never come.  So the interpreter is also told to
  write each signal's number to a pipe (:func:`signal.set_wakeup_fd`, done by its C-level
  handler the moment the signal arrives), and a thread reading that pipe runs the callbacks
  registered with :meth:`StopRequest.on_request`: they wake what the main thread waits on (an
  executor's wait through a future, :func:`spin_until_stopped`; an :class:`threading.Event`).
* Inside :meth:`StopRequest.interruptible` the handler raises :class:`KeyboardInterrupt` in the
  main thread instead: for work that is plain Python and numba (compiling kernels), where an
  exception at any point is harmless and a flag would be seen only when the work is done.
"""
import contextlib
import os
import signal
import sys
import threading
from typing import Callable, List, Optional

#: The signals that ask an executable to stop.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Whether a stop was asked for, and the means to wake whatever waits for one.

    Made and installed by :func:`install`; :meth:`request` asks for a stop from code (as a
    signal would).
    """

    def __init__(self):
        self._signum: Optional[int] = None       # set by the handler: a plain assignment
        self._interruptible = 0                 # depth of interruptible() sections
        self._lock = threading.Lock()           # never taken by the signal handler
        self._callbacks: List[Callable[[], None]] = []
        self._event = threading.Event()         # set by the waker thread, not the handler
        self._saved = {}
        self._wakeup_fd = None
        self._pipe = None
        self._waker = None

    # ------------------------------------------------------------------ the request
    @property
    def requested(self) -> bool:
        """True once SIGINT or SIGTERM arrived (or :meth:`request` was called)."""
        return self._signum is not None

    @property
    def signal_name(self) -> str:
        """The name of the signal that asked for the stop ('' before one)."""
        if self._signum is None:
            return ''
        try:
            return signal.Signals(self._signum).name
        except ValueError:
            return str(self._signum)

    def request(self, signum: int = signal.SIGINT) -> None:
        """Ask for a stop from code, as a signal does (from any thread)."""
        self._note(signum)

    def on_request(self, callback: Callable[[], None]) -> Callable[[], None]:
        """Call ``callback()`` once a stop is asked for: from the waker thread soon after the
        signal, or at once if it was asked for already.  Returns a function that unregisters
        it.  The callback runs outside the main thread: it may take locks and call rcl (wake
        an executor, set a future or an event), and must not take long."""
        with self._lock:
            already = self.requested and self._event.is_set()
            if not already:
                self._callbacks.append(callback)
        if already:
            _call(callback)

        def forget():
            with self._lock:
                if callback in self._callbacks:
                    self._callbacks.remove(callback)
        return forget

    def wait(self, seconds: Optional[float] = None) -> bool:
        """Sleep up to ``seconds`` (None: until a stop), returning early on a stop request;
        returns whether a stop was asked for."""
        if not self.requested:
            self._event.wait(seconds)    # set by the waker thread (or request())
        return self.requested

    @contextlib.contextmanager
    def interruptible(self):
        """Inside, a stop request raises :class:`KeyboardInterrupt` in the main thread, at once
        if one came before (for plain Python and numba work only: no rclpy call, no file being
        written that the exception would leave half done)."""
        if self.requested:
            raise KeyboardInterrupt
        self._interruptible += 1
        try:
            yield self
        finally:
            self._interruptible -= 1

    # ------------------------------------------------------------------ internals
    def _handle(self, signum, frame) -> None:
        """The Python-level handler (main thread): record, and raise only where allowed."""
        if self._signum is None:
            self._signum = signum
        if self._interruptible > 0:
            raise KeyboardInterrupt

    def _note(self, signum: int) -> None:
        """The first request runs the callbacks (waker thread, or request()'s caller)."""
        if self._signum is None:
            self._signum = signum
        with self._lock:
            if self._event.is_set():
                return
            self._event.set()
            callbacks, self._callbacks = self._callbacks, []
        for callback in callbacks:
            _call(callback)

    def _wake_loop(self, read_fd: int) -> None:
        """The waker thread: each byte the interpreter writes to the pipe is a signal number
        (0 ends the thread)."""
        while True:
            try:
                data = os.read(read_fd, 64)
            except InterruptedError:
                continue
            except OSError:
                return
            for signum in data:
                if signum == 0:
                    return
                if signum in STOP_SIGNALS:
                    self._note(signum)

    def _install(self) -> None:
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        self._pipe = (read_fd, write_fd)
        self._waker = threading.Thread(target=self._wake_loop, args=(read_fd,),
                                       name='stop-request-waker', daemon=True)
        self._waker.start()
        self._wakeup_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        for signum in STOP_SIGNALS:
            self._saved[signum] = signal.signal(signum, self._handle)

    def _uninstall(self) -> None:
        for signum, handler in self._saved.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
        self._saved = {}
        signal.set_wakeup_fd(self._wakeup_fd if self._wakeup_fd is not None else -1)
        read_fd, write_fd = self._pipe
        try:
            os.write(write_fd, b'\0')            # ends the waker thread
        except OSError:
            pass
        self._waker.join(5.0)
        if not self._waker.is_alive():
            os.close(read_fd)
        os.close(write_fd)


def _call(callback: Callable[[], None]) -> None:
    try:
        callback()
    except Exception as e:       # noqa: B902 - a waker that fails must not stop the others
        print(f'stop request: {callback!r} failed: {type(e).__name__}: {e}', file=sys.stderr)


_current: Optional[StopRequest] = None
_depth = 0


@contextlib.contextmanager
def installed():
    """The process's :class:`StopRequest`, its handlers installed for the duration (main thread
    only; nested uses share the outermost one; the previous handlers come back at the end)."""
    global _current, _depth
    if _current is None:
        stop = StopRequest()
        stop._install()
        _current = stop
    _depth += 1
    try:
        yield _current
    finally:
        _depth -= 1
        if _depth == 0:
            stop, _current = _current, None
            stop._uninstall()


def spin_until_stopped(executor, stop: StopRequest, future=None,
                       timeout_sec: Optional[float] = None) -> None:
    """Run ``executor``'s callbacks until a stop is asked for, ``future`` (an rclpy future) is
    done or ``timeout_sec`` [s] passed: rclpy's ``spin_until_future_complete`` on a future that
    the stop request completes from the waker thread, so the executor's wait ends at once,
    whatever clock its timers follow."""
    from rclpy.task import Future
    done = Future()
    forget = stop.on_request(lambda: done.set_result(True))
    if future is not None:
        future.add_done_callback(lambda f: done.set_result(False))
    try:
        if not stop.requested and (future is None or not future.done()):
            executor.spin_until_future_complete(done, timeout_sec)
    finally:
        forget()
