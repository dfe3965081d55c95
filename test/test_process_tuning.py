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


def test_passive_wait_policy_stops_idle_openmp_workers_from_spinning(monkeypatch):
    """In fresh interpreters: set before numba's threads start, passive makes a parallel loop
    followed by a sleep cost far less CPU than libgomp's spinning default; after the start,
    or against the environment, nothing changes and the message says so."""
    code = '''
import os, resource, sys, time
from hair_tracking.process_tuning import set_omp_wait_policy
policy = sys.argv[1]
print(set_omp_wait_policy(policy))
import numpy as np
from numba import njit, prange
@njit(parallel=True)
def bump(a):
    for i in prange(a.size):
        a[i] += 1.0
a = np.zeros(10000)
bump(a)
os.environ.pop('OMP_WAIT_POLICY')
print(set_omp_wait_policy('passive'))
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
c0 = cpu()
for _ in range(100):
    bump(a)
    time.sleep(0.002)
print((cpu() - c0) / 100 * 1e3)
'''
    env = {k: v for k, v in os.environ.items() if k != 'OMP_WAIT_POLICY'}
    runs = {}
    for policy in ('active', 'passive'):
        out = subprocess.run([sys.executable, '-c', code, policy], capture_output=True,
                             text=True, timeout=300, env=env)
        assert out.returncode == 0, out.stderr
        first, late, ms = out.stdout.strip().split('\n')
        assert first == f'OpenMP worker threads wait {policy} (OMP_WAIT_POLICY={policy.upper()})'
        assert late == 'OpenMP threads already started: wait policy passive not applied'
        runs[policy] = float(ms)
    # spinning fills most of each 2 ms sleep with a worker's CPU time; passive does not
    assert runs['passive'] < 0.5 * runs['active'], runs
    assert process_tuning.set_omp_wait_policy('environment').startswith('OpenMP wait policy')
    monkeypatch.setenv('OMP_WAIT_POLICY', 'ACTIVE')
    assert process_tuning.set_omp_wait_policy('passive') == \
        'OMP_WAIT_POLICY=ACTIVE from the environment kept'
    with pytest.raises(ValueError, match='omp_wait_policy must be one of'):
        process_tuning.set_omp_wait_policy('spin')
