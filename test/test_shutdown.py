"""The stop request every executable installs (hair_tracking.shutdown), in this process, with
raised signals.  Every wait here has a backstop that asks for a stop with another signal number
(SIGUSR1), so a broken wake-up still ends the test, and fails it: the assertions name the signal
that ended the wait."""
import os
import signal
import threading

import pytest

from hair_tracking import shutdown

DOMAIN = 79
BACKSTOP_S = 30.0


def _later(seconds, fn, *args):
    t = threading.Timer(seconds, fn, args)
    t.daemon = True
    t.start()
    return t


def test_a_signal_is_recorded_not_raised_and_the_handlers_come_back():
    before = {s: signal.getsignal(s) for s in shutdown.STOP_SIGNALS}
    with shutdown.installed() as stop:
        assert not stop.requested and stop.signal_name == ''
        signal.raise_signal(signal.SIGTERM)           # nothing raised here
        assert stop.wait(BACKSTOP_S)
        assert stop.requested and stop.signal_name == 'SIGTERM'
        signal.raise_signal(signal.SIGINT)            # the first signal is kept
        assert stop.signal_name == 'SIGTERM'
        with shutdown.installed() as inner:           # nested: the same request
            assert inner is stop
    assert {s: signal.getsignal(s) for s in shutdown.STOP_SIGNALS} == before


def test_callbacks_run_on_the_waker_thread_once_and_at_once_when_late():
    calls = []
    done = threading.Event()

    def record(name):
        calls.append((name, threading.current_thread() is threading.main_thread()))
        done.set()
    with shutdown.installed() as stop:
        forget = stop.on_request(lambda: record('forgotten'))
        forget()
        stop.on_request(lambda: record('early'))
        backstop = _later(BACKSTOP_S, stop.request, signal.SIGUSR1)
        _later(0.05, signal.raise_signal, signal.SIGINT)
        assert done.wait(BACKSTOP_S + 5)
        backstop.cancel()
        assert stop.signal_name == 'SIGINT'
        stop.on_request(lambda: record('late'))       # after the request: called at once
    assert calls == [('early', False), ('late', True)]


def test_interruptible_sections_raise_and_others_do_not():
    with shutdown.installed() as stop:
        with pytest.raises(KeyboardInterrupt):
            with stop.interruptible():
                signal.raise_signal(signal.SIGINT)
                stop.wait(BACKSTOP_S)                 # interrupted by the handler
        assert stop.requested
        with pytest.raises(KeyboardInterrupt):       # a request that came before
            with stop.interruptible():
                pass


def test_sigint_ignored_at_start_is_handled_all_the_same():
    """A background job of a shell script starts with SIGINT ignored; the stop request installs
    its handler anyway (Ctrl-C and ros2 launch stop a process with SIGINT)."""
    saved = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with shutdown.installed() as stop:
            signal.raise_signal(signal.SIGINT)
            assert stop.wait(BACKSTOP_S) and stop.signal_name == 'SIGINT'
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, saved)


@pytest.fixture
def ros():
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    made = []

    def make(**overrides):
        from rclpy.parameter import Parameter
        node = rclpy.create_node(f'shutdown_test_{len(made)}', context=ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        made.append((node, ex))
        return node, ex
    yield make
    for node, ex in made:
        ex.shutdown(timeout_sec=1.0)
        node.destroy_node()
    rclpy.try_shutdown(context=ctx)


def test_a_signal_ends_an_executor_wait_that_nothing_else_would_end(ros):
    """use_sim_time and no /clock: the node's timers never fire and the executor waits with no
    timeout; the signal ends the wait (before the executor would return for any other reason,
    the backstop's SIGUSR1 request)."""
    node, ex = ros(use_sim_time=True)
    ticks = []
    node.create_timer(0.01, lambda: ticks.append(1))
    with shutdown.installed() as stop:
        backstop = _later(BACKSTOP_S, stop.request, signal.SIGUSR1)
        _later(0.2, os.kill, os.getpid(), signal.SIGINT)
        shutdown.spin_until_stopped(ex, stop)
        backstop.cancel()
        assert stop.signal_name == 'SIGINT'
    assert ticks == []                                # /clock never came


def test_spin_until_stopped_ends_with_its_future_or_timeout_and_not_after_a_stop(ros):
    from rclpy.task import Future
    node, ex = ros()
    with shutdown.installed() as stop:
        future = Future()
        node.create_timer(0.01, lambda: future.set_result(7))
        shutdown.spin_until_stopped(ex, stop, future, timeout_sec=BACKSTOP_S)
        assert future.done() and not stop.requested
        shutdown.spin_until_stopped(ex, stop, Future(), timeout_sec=0.05)   # times out
        assert not stop.requested
        stop.request()
        never = []
        node.create_timer(0.0, lambda: never.append(1))
        shutdown.spin_until_stopped(ex, stop)        # a stop came before: no spinning
        assert never == []
