"""One node process's life: rclpy started without its signal handlers, the node made, spun
until a stop is asked for (:mod:`hair_tracking.shutdown`), then taken down in order.  Shared by
``hair_sim_node`` and ``hair_sim_ghosts``."""
import sys
from typing import Callable, Iterable, List, Optional

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from hair_tracking import executable, shutdown


def spin_node(name: str, make_node: Callable[[], Node], ros_argv: List[str], stop,
              started: Iterable[str], gc_freeze: bool,
              user_error: Callable[[Exception], Optional[str]]) -> int:
    """Run the node ``make_node()`` builds in this process until ``stop`` (the executable's
    stop request) is asked for.

    ``ros_argv`` is the program name and the ROS arguments for rclpy; ``started`` the lines
    of the process settings applied, logged under the logger ``name``; ``gc_freeze`` freezes
    the heap once the node is built.  ``user_error(e)`` turns an exception raised while the node
    is made or spun into the one-line message printed for it (exit 2), or ``None`` for an
    exception that is not the user's (raised on).  Returns 0 once stopped."""
    node = executor = None
    code = 0
    try:
        # no rclpy signal handler: it would shut the context down from another thread, under
        # whatever the executor runs; the stop request wakes the executor instead
        rclpy.init(args=ros_argv, signal_handler_options=SignalHandlerOptions.NO)
        log = rclpy.logging.get_logger(name)
        for line in started:
            log.info(line)
        executor = SingleThreadedExecutor()
        if not stop.requested:
            node = make_node()
            if gc_freeze:
                executable.freeze_heap()
            executor.add_node(node)
            shutdown.spin_until_stopped(executor, stop)
        if stop.requested:
            log.info(f'{stop.signal_name}: stopping')
    except ExternalShutdownException:
        pass
    except Exception as e:        # noqa: B902 - the caller says which are the user's
        message = user_error(e)
        if message is None:
            raise
        print(message, file=sys.stderr)
        code = 2
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code
