"""``make demo`` stops its node as a user would: SIGINT, then SIGTERM, SIGKILL only as the last
resort, and says so (live_demo.stop_node, on stand-in processes)."""
import subprocess
import sys

import pytest

from hair_tracking.ros.live_demo import stop_node

#: A bound on the wait for a process that obeys a signal (never reached: it stops).
WAIT_S = 120.0

#: A process that says it is ready, then waits; ``{ignore}`` lists the signals it ignores.
CHILD = '''
import signal, sys, time
ignore = {ignore}
for name in ignore:
    signal.signal(getattr(signal, name), signal.SIG_IGN)
if 'SIGINT' not in ignore:             # as rclpy does: its own SIGINT handler, so Ctrl-C
    signal.signal(signal.SIGINT, signal.default_int_handler)  # works in a background job too
if 'SIGTERM' not in ignore:            # as rclpy does: SIGTERM shuts down, exit status 0
    signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
print('ready', flush=True)
while True:
    time.sleep(0.05)
'''


def _child(ignore):
    proc = subprocess.Popen([sys.executable, '-c', CHILD.format(ignore=list(ignore))],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == 'ready'
    return proc


@pytest.mark.parametrize('ignore, code, said', [
    ((), -2, []),                                                # Ctrl-C is enough
    (('SIGINT',), 0, ['sending SIGTERM']),                       # a clean external shutdown
    (('SIGINT', 'SIGTERM'), -9, ['sending SIGTERM', 'killing it (SIGKILL)']),
])
def test_the_node_is_stopped_by_the_gentlest_signal_that_works(ignore, code, said):
    """The stand-in says which signals it ignores, so the wait knows without a clock: after
    one it ignores, the node "did not stop in time" at once; after one it obeys, the wait
    lasts until it has stopped (however loaded the machine is)."""
    proc = _child(ignore)
    lines = []

    def wait(child, sig, timeout):
        if sig.name not in ignore:
            child.wait(WAIT_S)
    try:
        assert stop_node(proc, timeout=5.0, log=lines.append, wait=wait) == code
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    assert [next(w for w in said if w in ln) for ln in lines] == said, lines
