"""Ctrl-C in the executables that spin a node (hair_tracking.ros.interrupt), in-process with a
real context and a raised SIGINT."""
import os
import signal

import pytest

from hair_tracking.ros.interrupt import interrupt_between_callbacks

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
DOMAIN = 79


def test_ctrl_c_stops_the_executor_between_callbacks_not_inside_one():
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    ctx = Context()
    rclpy.init(context=ctx, domain_id=DOMAIN)
    saved = signal.getsignal(signal.SIGINT)
    try:
        node = rclpy.create_node('interrupt_test', context=ctx)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        interrupt_between_callbacks(node)
        signal.raise_signal(signal.SIGINT)        # handled here without raising ...
        with pytest.raises(KeyboardInterrupt):
            for _ in range(20):                   # ... but by the executor's next turn
                ex.spin_once(timeout_sec=0.1)
        ex.spin_once(timeout_sec=0.0)             # one stop per Ctrl-C
        ex.shutdown(timeout_sec=1.0)
        node.destroy_node()
    finally:
        signal.signal(signal.SIGINT, saved)
        rclpy.try_shutdown(context=ctx)
