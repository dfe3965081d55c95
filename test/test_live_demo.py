"""``make demo`` stops its node as a user would: SIGINT, then SIGTERM, SIGKILL only as the last
resort, and says so (live_demo.stop_node, on stand-in processes)."""
import subprocess
import sys

import pytest

from hair_tracking.ros.live_demo import stop_node

#: A process that says it is ready, then waits; ``{ignore}`` lists the signals it ignores.
CHILD = '''
import signal, sys, time
ignore = {ignore}
for name in ignore:
    signal.signal(getattr(signal, name), signal.SIG_IGN)
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
    proc = _child(ignore)
    lines = []
    try:
        assert stop_node(proc, timeout=5.0, log=lines.append) == code
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()
    assert [next(w for w in said if w in ln) for ln in lines] == said, lines
