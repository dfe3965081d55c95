"""A publisher and a subscriber in one process, over DDS: what the tests of the message writers
use to show that bytes they publish arrive as the message they stand for; and the bounded spin
the tests that talk over DDS wait with."""
import time


def spin_until(executor, predicate, timeout_s: float):
    """Spin ``executor`` until ``predicate()`` holds or ``timeout_s`` passes; its last value."""
    deadline = time.monotonic() + timeout_s
    while not predicate() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return predicate()


def publish_and_receive(msg_type, payloads, domain_id: int, topic: str = 'loopback',
                        timeout_s: float = 10.0):
    """Publish each of ``payloads`` (messages or their CDR bytes) on ``topic`` once a
    subscriber of ``msg_type`` in the same process has matched; the messages it received,
    in order (fails when the subscription never matches or fewer arrive in ``timeout_s``)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=domain_id)
    executor = SingleThreadedExecutor(context=ctx)
    try:
        node = rclpy.create_node('loopback', context=ctx)
        executor.add_node(node)
        received = []
        node.create_subscription(msg_type, topic, received.append, len(payloads) + 1)
        pub = node.create_publisher(msg_type, topic, len(payloads) + 1)
        assert spin_until(executor, lambda: pub.get_subscription_count() >= 1, timeout_s), \
            'the subscription never matched'
        for payload in payloads:
            pub.publish(payload)
        assert spin_until(executor, lambda: len(received) >= len(payloads), timeout_s), \
            f'{len(received)} of {len(payloads)} messages received'
        node.destroy_node()
        return received
    finally:
        executor.shutdown()
        rclpy.try_shutdown(context=ctx)
