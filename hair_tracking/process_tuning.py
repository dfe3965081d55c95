"""Process-wide settings for the executables that run the hair for a long time.

Each is applied only by an executable's ``main()`` (``hair_sim_node``, ``hair_sim_bag``, the live
demo), never by a library call or a constructor, and each is switchable from that executable's
command line (:func:`add_arguments`, :func:`apply`):

* ``--malloc-retain-mb`` (:func:`retain_freed_memory`): glibc keeps freed memory mapped for reuse,
  so the large message buffers a cloud is copied through are not faulted in page by page again;
* ``--omp-wait-policy`` (:func:`set_omp_wait_policy`): numba's idle OpenMP workers sleep instead of
  spinning, leaving the cores to the executor and DDS threads (``passive``, the default), or
  spin between parallel regions (``active``, the default of ``hair_sim_bag run``, which has no
  such threads);
* ``--no-gc-freeze`` (:func:`freeze_heap`, on by default): the objects made at start-up are taken
  out of the cyclic garbage collector's reach once the process is set up.
"""
import ctypes
import ctypes.util
import gc
import os
from typing import List, Optional

#: Default of ``--malloc-retain-mb``: a few clouds' worth of copies, small next to a desktop's
#: memory.
DEFAULT_RETAIN_MB = 256
# mallopt(3) parameter numbers (glibc malloc.h)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
# glibc refuses an mmap threshold above HEAP_MAX_SIZE / 2 (32 MiB on 64-bit systems)
MMAP_THRESHOLD_MAX = 32 * 1024 * 1024


def freeze_heap() -> None:
    """Take every object alive now out of the cyclic garbage collector's reach (``gc.freeze``).

    Call it once the process is set up (modules imported, kernels loaded, the hair built).  A
    full collection walks every tracked object (some 10^5 with rclpy and numba loaded), a pause
    of tens of milliseconds on whatever frame triggers it; frozen objects are never examined
    again, what the loop allocates later is collected as usual.  Garbage made before the call is
    collected first.
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
    buffers up to 32 MiB come from the heap and, once freed, are reused without page faults.
    glibc's own rule returns freed memory at the top of the heap once more than twice the
    largest freed chunk is free, so a process that copies multi-megabyte clouds maps and faults
    in fresh pages for every copy.  The cost is memory: the process keeps up
    to ``megabytes`` more resident than it uses at a time.  Process-wide, and can be called at
    any time.

    Returns what was done, for the log: nothing when ``megabytes`` is 0, when ``GLIBC_TUNABLES``
    already sets malloc tunables (the user's choice wins) or when the C library is not glibc.
    """
    if megabytes <= 0:
        return 'malloc retention 0: glibc malloc defaults kept'
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


#: Values of ``--omp-wait-policy``.
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

    libgomp's default (the variable unset) spins a while after each parallel region, then
    sleeps: CPU time a node needs for its executor and DDS threads.  ``passive`` sets
    ``OMP_WAIT_POLICY=PASSIVE`` before the OpenMP layer starts: workers sleep at once, and each
    parallel region pays a wake-up.  ``active`` sets ``ACTIVE``: workers spin between regions
    (for an executable whose own loop is its only other busy thread).

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


def add_arguments(parser, omp_wait_policy: str = 'passive') -> None:
    """Add the process settings to an executable's ``argparse`` parser; ``omp_wait_policy`` is
    the default of ``--omp-wait-policy`` (``active`` for an executable whose only other busy
    thread is its own loop, as ``hair_sim_bag run``'s: no executor or DDS threads wait for the
    cores, and a sleeping worker costs a wake-up at every parallel region)."""
    if omp_wait_policy not in OMP_WAIT_POLICIES:
        raise ValueError(f'omp_wait_policy must be one of {", ".join(OMP_WAIT_POLICIES)}')
    g = parser.add_argument_group(
        'process settings', 'process-wide, applied once at start by this executable')
    g.add_argument('--malloc-retain-mb', type=int, default=DEFAULT_RETAIN_MB, metavar='MB',
                   help='freed memory glibc keeps mapped for reuse, so large message buffers '
                        'are not faulted in again page by page; 0 keeps glibc\'s defaults; '
                        'GLIBC_TUNABLES wins (default: %(default)s)')
    g.add_argument('--omp-wait-policy', choices=OMP_WAIT_POLICIES, default=omp_wait_policy,
                   help='how idle OpenMP worker threads of the numba kernels wait: passive '
                        'sleeps, active spins between parallel regions, environment leaves '
                        'OMP_WAIT_POLICY alone (unset: libgomp spins a while, then sleeps); '
                        'an OMP_WAIT_POLICY in the environment wins (default: %(default)s)')
    g.add_argument('--no-gc-freeze', dest='gc_freeze', action='store_false',
                   help='do not freeze the objects made at start-up out of the garbage '
                        "collector's reach once set up (default: freeze)")


def apply(args) -> List[str]:
    """Apply the memory and thread settings of :func:`add_arguments` (before numba starts its
    threads); returns what was done, for the log.  The GC freeze is the caller's, once set up."""
    if not 0 <= args.malloc_retain_mb <= 2047:
        raise ValueError(f'--malloc-retain-mb must be in [0, 2047], got {args.malloc_retain_mb}')
    return [set_omp_wait_policy(args.omp_wait_policy),
            retain_freed_memory(args.malloc_retain_mb)]
