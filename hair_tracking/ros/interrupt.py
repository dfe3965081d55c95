"""Ctrl-C for the executables that spin a node: stop between callbacks, never inside one."""
import signal


def interrupt_between_callbacks(node) -> None:
    """Make Ctrl-C stop ``node``'s executor between callbacks (main thread only).

    Python's own SIGINT handler raises KeyboardInterrupt at whatever the main thread is running;
    inside rclpy's take or publish of a message (pybind11 converting the message object) it comes
    out as "RuntimeError: Unable to convert call argument" instead, and the process dies with a
    traceback.  Here SIGINT only triggers a guard condition of the node (a call into rcl that
    takes no Python lock); the executor runs its callback like any other, and that raises
    KeyboardInterrupt out of ``spin_once`` / ``spin``."""
    def stop():
        raise KeyboardInterrupt

    guard = node.create_guard_condition(stop)
    signal.signal(signal.SIGINT, lambda signum, frame: guard.trigger())
