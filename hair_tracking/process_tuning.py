"""Process-wide settings that keep a long-running hair process free of start-up-sized pauses.

Two causes of pauses that have nothing to do with the simulation itself:

* the cyclic garbage collector walking every object rclpy and numba created at start-up
  (:func:`freeze_heap`);
* page faults on large message buffers (:func:`retain_freed_memory`).  A 10 k-strand cloud is
  3.2 MB, and on its way from the encoder to a subscriber in the same process it is copied into
  fresh buffers five times (encoder, rclpy's serialized message, the DDS change, the reader's
  sample, the subscriber's ``bytes``).  glibc returns freed memory at the top of a heap to the
  system once more than ``M_TRIM_THRESHOLD`` is free (its dynamic rule sets that to twice the
  largest freed ``mmap`` chunk: 6.4 MB here), so each new buffer is mapped again and every one of
  its 4 KiB pages is faulted in and zeroed by the kernel.  Measured with perf in
  ``scripts/bench_latency.py`` at 10 k ghosts: page faults, page clearing and the memory cgroup's
  accounting took more CPU than the simulation, and ``munmap`` holding the address-space lock
  slowed the numba threads too (node step 13 ms against 4.8 ms standalone).  Keeping freed
  memory mapped cut the pose-to-cloud latency from 32-34 ms to 12 ms median in the same run.
"""
import ctypes
import ctypes.util
import gc
import os
from typing import Optional

#: Default of the node's ``malloc_retain_mb`` and what the bag tools (record, play, the live
#: demo) use: a few clouds' worth of copies, small next to a desktop's memory.
DEFAULT_RETAIN_MB = 256
# mallopt(3) parameter numbers (glibc malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
# glibc refuses an mmap threshold above HEAP_MAX_SIZE / 2 (32 MiB on 64-bit systems)
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024


def freeze_heap() -> None:
    """Take every object alive now out of the cyclic garbage collector's reach (``gc.freeze``).

    Call it once the process is set up (modules imported, kernels loaded, the hair built).  A
    full collection walks every tracked object: with rclpy and numba loaded (about 120 k
    objects) that is 67 ms on this machine, a pause that lands on whatever frame triggers it.
    Frozen objects are never examined again; what the loop allocates later is collected as
    usual.  Garbage made before the call is collected first.
    """
    gc.collect()
    gc.freeze()


def _glibc() -> Optional[ctypes.CDLL]:
    name = ctypes.util.find_library('c')
    if not name:
        return None
    try:
        libc = ctypes.CDLL(name)
        libc.gnu_get_libc_version       # only glibc has it (musl, macOS do not)
        libc.mallopt
    except (OSError, AttributeError):
        return None
    libc.mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    libc.mallopt.restype = ctypes.c_int
    return libc


def retain_freed_memory(megabytes: int) -> str:
    """Let glibc keep up to ``megabytes`` of freed heap memory mapped for reuse.

    Sets ``M_TRIM_THRESHOLD`` to ``megabytes`` and ``M_MMAP_THRESHOLD`` to 32 MiB, so message
    buffers up to 32 MiB come from the heap and, once freed, are reused without page faults
    (see the module docstring for the measurement).  The cost is memory: the process keeps up
    to ``megabytes`` more resident than it uses at a time.  Process-wide, and can be called at
    any time.

    Returns what was done, for the log: nothing when ``megabytes`` is 0, when ``GLIBC_TUNABLES``
    already sets malloc tunables (the user's choice wins) or when the C library is not glibc.
    """
    if megabytes <= 0:
        return 'malloc_retain_mb 0: glibc malloc defaults kept'
    if 'glibc.malloc.' in os.environ.get('GLIBC_TUNABLES', ''):
        return 'GLIBC_TUNABLES sets malloc tunables: left as they are'
    libc = _glibc()
    if libc is None:
        return 'not glibc: malloc settings left as they are'
    trim = min(int(megabytes), 2047) * 1024 * 1024       # mallopt takes an int
    ok = libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_MAX) == 1
    ok = libc.mallopt(M_TRIM_THRESHOLD, trim) == 1 and ok
    if not ok:
        return 'mallopt refused the settings: glibc malloc defaults kept'
    return f'malloc keeps up to {trim >> 20} MB of freed memory for reuse'


#: Values of the node's ``omp_wait_policy``.
OMP_WAIT_POLICIES = ('passive', 'active', 'environment')


def _openmp_started() -> bool:
    """True once libgomp is mapped into the process (numba's OpenMP layer launched): it reads
    ``OMP_WAIT_POLICY`` when it is loaded, not later."""
    try:
        with open('/proc/self/maps', encoding='utf-8', errors='replace') as f:
            return any('libgomp' in line or 'libiomp' in line for line in f)
    except OSError:
        return False


def set_omp_wait_policy(policy: str) -> str:
    """How numba's idle OpenMP worker threads wait for the next parallel region.

    libgomp's default (``active`` for a while) spins: after each parallel region the worker
    burns its core until the next one or a spin limit.  Measured here: a 10 k-element parallel
    loop followed by a 2 ms sleep cost 1.86 ms of CPU per round with the default against 0.04
    ms passive.  A node shares its two cores with the rclpy executor, the DDS threads and, in
    ``scripts/bench_latency.py``, the probe taking each cloud; spinning workers took that time
    from them (10 k ghosts, six alternated pairs: pose -> cloud p99 16.1-18.3 ms with the
    default, 14.6-16.3 ms in five of six runs passive, medians alike).  ``passive`` sets
    ``OMP_WAIT_POLICY=PASSIVE`` before the OpenMP layer starts: workers sleep at once.

    Only takes effect before numba launches its threads (call it before ``set_num_threads``
    or any parallel kernel) and only when the environment does not set the variable already
    (the user's choice wins); ``environment`` leaves it alone.  Returns what was done.
    """
    if policy not in OMP_WAIT_POLICIES:
        raise ValueError(f'omp_wait_policy must be one of {", ".join(OMP_WAIT_POLICIES)}, '
                         f'got {policy!r}')
    if policy == 'environment':
        return 'OpenMP wait policy: as the environment says'
    if 'OMP_WAIT_POLICY' in os.environ:
        return f'OMP_WAIT_POLICY={os.environ["OMP_WAIT_POLICY"]} from the environment kept'
    if _openmp_started():
        return f'OpenMP threads already started: wait policy {policy} not applied'
    os.environ['OMP_WAIT_POLICY'] = policy.upper()
    return f'OpenMP worker threads wait {policy} (OMP_WAIT_POLICY={policy.upper()})'
