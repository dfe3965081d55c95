"""hair_sim_node as a process of its own: what the tests of the executable do with it."""
import signal
import time


def until_ready_then_ctrl_c(proc, timeout: float = 120.0) -> str:
    """Read the node's output until it says ready (at most ``timeout`` seconds), send Ctrl-C,
    wait for it to exit; returns everything it printed."""
    lines = []
    try:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if 'ready:' in line:
                break
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return ''.join(lines) + out
