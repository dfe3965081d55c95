"""Process-wide tuning: the frozen start-up heap and glibc keeping freed memory for reuse.

Both run in a fresh interpreter: they change the whole process, and the page-fault count of a
fresh process is what the node sees.
"""
import os
import subprocess
import sys

import pytest

from hair_tracking import process_tuning


def run_python(code: str) -> str:
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_freeze_heap_collects_then_freezes_the_start_up_objects():
    """In a fresh interpreter: garbage made before the call is collected, every live object is
    frozen (so later full collections no longer walk them), and new garbage is still collected."""
    code = '''
import gc, weakref
from hair_tracking.process_tuning import freeze_heap
class Cycle:
    pass
def make():
    a, b = Cycle(), Cycle()
    a.b, b.a = b, a
    return weakref.ref(a)
assert gc.get_freeze_count() == 0
before = make()
freeze_heap()
assert before() is None, 'garbage from before the freeze was not collected'
assert gc.get_freeze_count() > 1000, gc.get_freeze_count()
after = make()
gc.collect()
assert after() is None, 'garbage made after the freeze is not collected'
print('ok')
'''
    assert run_python(code) == 'ok'


FAULTS = '''
import resource, sys
from hair_tracking.process_tuning import retain_freed_memory
MB = 1 << 20
if sys.argv[1] != '0':
    print(retain_freed_memory(int(sys.argv[1])), file=sys.stderr)
def cycle():
    # a message's way through one process: several fresh 3 MB copies alive at once, then freed
    a = bytearray(3 * MB); b = bytearray(3 * MB); c = bytearray(3 * MB)
    del a, b, c
cycle()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    cycle()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
'''


def page_faults(megabytes: int) -> int:
    out = subprocess.run([sys.executable, '-c', FAULTS, str(megabytes)], capture_output=True,
                         text=True, timeout=120, env={**os.environ,
                                                      'GLIBC_TUNABLES': ''})
    assert out.returncode == 0, out.stderr
    return int(out.stdout.strip())


@pytest.mark.skipif(process_tuning._glibc() is None, reason='needs glibc')
def test_retained_memory_is_reused_without_page_faults():
    """Twenty rounds of three fresh 3 MB buffers: with glibc's defaults each round maps and
    faults in its pages again (about 2300 faults a round); with freed memory retained the
    buffers reuse the pages of the first round."""
    default = page_faults(0)
    retained = page_faults(256)
    assert default > 20 * 1000, default          # the cost this setting removes is there
    assert retained < 500, retained


def test_retain_freed_memory_leaves_user_choices_alone(monkeypatch):
    assert 'defaults kept' in process_tuning.retain_freed_memory(0)
    monkeypatch.setenv('GLIBC_TUNABLES', 'glibc.malloc.trim_threshold=1000')
    assert 'left as they are' in process_tuning.retain_freed_memory(64)
