"""Process-wide settings: the frozen start-up heap, glibc keeping freed memory for reuse, the
OpenMP wait policy and the executables' options for them.

Each runs in a fresh interpreter: they change the whole process, as an executable's main() does.
"""
import argparse
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


HEAP = '''
import ctypes, sys
from hair_tracking.process_tuning import retain_freed_memory


class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        'arena', 'ordblks', 'smblks', 'hblks', 'hblkhd', 'usmblks', 'fsmblks', 'uordblks',
        'fordblks', 'keepcost')]


libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] != '0':
    print(retain_freed_memory(int(sys.argv[1])), file=sys.stderr)
buf = bytearray(3 << 20)              # a cloud-sized message buffer
mapped = libc.mallinfo2().hblkhd      # bytes in mmap-ed chunks while it is alive
del buf
print(mapped >= 3 << 20, libc.mallinfo2().fordblks >= 3 << 20)
'''


def heap_use(megabytes: int):
    """(the 3 MB buffer was a separate mapping, its bytes stayed in the heap once freed)"""
    out = subprocess.run([sys.executable, '-c', HEAP, str(megabytes)], capture_output=True,
                         text=True, timeout=120, env={**os.environ, 'GLIBC_TUNABLES': ''})
    assert out.returncode == 0, out.stderr
    return tuple(v == 'True' for v in out.stdout.split())


@pytest.mark.skipif(process_tuning._glibc() is None, reason='needs glibc')
def test_retained_memory_keeps_large_buffers_in_the_heap_for_reuse():
    """glibc's rule, read from its own counters (mallinfo2): by default a 3 MB buffer is a
    mapping of its own, unmapped when freed (the next one is faulted in again page by page);
    with freed memory retained it comes from the heap, which keeps its pages once it is freed."""
    assert heap_use(0) == (True, False)
    assert heap_use(256) == (False, True)


def test_retain_freed_memory_leaves_user_choices_alone(monkeypatch):
    assert 'defaults kept' in process_tuning.retain_freed_memory(0)
    monkeypatch.setenv('GLIBC_TUNABLES', 'glibc.malloc.trim_threshold=1000')
    assert 'left as they are' in process_tuning.retain_freed_memory(64)


def test_wait_policy_is_set_before_the_openmp_threads_start_and_only_then(monkeypatch):
    """In fresh interpreters: the policy reaches the environment before numba starts its
    OpenMP threads (libgomp reads it when it is loaded); after the start, or against the
    user's environment, nothing changes and the message says so."""
    code = '''
import os, sys
from hair_tracking.process_tuning import set_omp_wait_policy
policy = sys.argv[1]
print(set_omp_wait_policy(policy))
print(os.environ['OMP_WAIT_POLICY'])
import numpy as np
from numba import njit, prange
@njit(parallel=True)
def bump(a):
    for i in prange(a.size):
        a[i] += 1.0
bump(np.zeros(10000))
os.environ.pop('OMP_WAIT_POLICY')
print(set_omp_wait_policy('passive'))
'''
    env = {k: v for k, v in os.environ.items() if k != 'OMP_WAIT_POLICY'}
    for policy in ('active', 'passive'):
        out = subprocess.run([sys.executable, '-c', code, policy], capture_output=True,
                             text=True, timeout=300, env=env)
        assert out.returncode == 0, out.stderr
        first, value, late = out.stdout.strip().split('\n')
        assert first == f'OpenMP worker threads wait {policy} (OMP_WAIT_POLICY={policy.upper()})'
        assert value == policy.upper()
        assert late == 'OpenMP threads already started: wait policy passive not applied'
    assert process_tuning.set_omp_wait_policy('environment').startswith('OpenMP wait policy')
    monkeypatch.setenv('OMP_WAIT_POLICY', 'ACTIVE')
    assert process_tuning.set_omp_wait_policy('passive') == \
        'OMP_WAIT_POLICY=ACTIVE from the environment kept'
    with pytest.raises(ValueError, match='omp_wait_policy must be one of'):
        process_tuning.set_omp_wait_policy('spin')


def test_process_options_parse_and_apply():
    import argparse
    parser = argparse.ArgumentParser()
    process_tuning.add_arguments(parser)
    args = parser.parse_args([])
    assert (args.malloc_retain_mb, args.omp_wait_policy, args.gc_freeze) == \
        (process_tuning.DEFAULT_RETAIN_MB, 'passive', True)
    args = parser.parse_args(['--malloc-retain-mb', '0', '--omp-wait-policy', 'environment',
                              '--no-gc-freeze'])
    assert not args.gc_freeze
    assert process_tuning.apply(args) == ['OpenMP wait policy: as the environment says',
                                          'malloc retention 0: glibc malloc defaults kept']
    args.malloc_retain_mb = -1
    with pytest.raises(ValueError, match=r'--malloc-retain-mb must be in \[0, 2047\], got -1'):
        process_tuning.apply(args)


def test_offline_run_waits_active_and_the_live_executables_passive():
    """``hair_sim_bag run`` has no executor or DDS threads to leave the cores to, so its OpenMP
    workers spin between parallel regions by default; play and record (which run DDS) sleep."""
    from hair_tracking.ros.bag_cli import build_parser
    parser = build_parser()
    assert parser.parse_args(['run', '-o', 'x.mcap']).omp_wait_policy == 'active'
    assert parser.parse_args(['run', '-o', 'x.mcap', '--omp-wait-policy', 'passive']) \
        .omp_wait_policy == 'passive'
    assert parser.parse_args(['play']).omp_wait_policy == 'passive'
    assert parser.parse_args(['record', '-a', '-o', 'x.mcap']).omp_wait_policy == 'passive'
    with pytest.raises(ValueError, match='omp_wait_policy must be one of'):
        process_tuning.add_arguments(argparse.ArgumentParser(), omp_wait_policy='spin')
