"""What every executable of the package does in its ``main()``, and the console entry points.

An executable's ``main()`` begins with ``with executable.started() as stop:``, which

* points numba's on-disk cache at a folder keyed by a hash of the package's sources
  (:func:`use_numba_cache`), unless ``NUMBA_CACHE_DIR`` is set already;
* installs the process's stop request (:mod:`hair_tracking.shutdown`): SIGINT and SIGTERM ask
  it to stop, and it stops with exit code 0.

Then it applies its process settings from its own command line (:func:`add_arguments`,
:func:`apply`, :func:`freeze_heap`); no library call or constructor changes the process.

The console scripts (``setup.py``) are the functions at the end of this module: each does the
above before it imports its executable's module, so numba reads its cache folder when it is
first imported, and a signal during those imports is already a stop request.

numba's cache (``cache=True``) checks only the time stamp of the file that defines a kernel, not
of the files whose jitted functions the kernel inlines (the ghost kernels inline functions of
``colliders.head``, ``guides.ftl`` and ``ghosts.weights``), so one cache folder for all sources
could keep a stale compiled caller after an edit.  A folder per source hash starts afresh after
any edit and reuses the compiled kernels while the sources are unchanged.

Process settings (each on the executable's command line; docs/node.md, "Process settings"):

* ``--malloc-retain-mb`` (:func:`retain_freed_memory`): glibc keeps freed memory mapped for
  reuse, so large message buffers are not faulted in page by page again;
* ``--omp-wait-policy`` (:func:`set_omp_wait_policy`): how numba's idle OpenMP workers wait;
  setting it also pins numba's threading layer to OpenMP, the only layer that reads it;
* ``--no-gc-freeze`` (:func:`freeze_heap`): the objects made at start-up are taken out of the
  cyclic garbage collector's reach once the process is set up.
"""
import contextlib
import ctypes
import ctypes.util
import gc
import glob
import hashlib
import importlib
import os
import sys
from typing import List, Optional

from hair_tracking import shutdown

_PACKAGE = os.path.dirname(os.path.abspath(__file__))


# ==================================================================== numba's cache folder
def source_hash() -> str:
    """12 hex digits of the SHA-1 of every ``hair_tracking/**/*.py`` (paths relative to the
    package and contents, sorted by path), so an edit in any subpackage changes it."""
    h = hashlib.sha1()
    paths = glob.glob(os.path.join(_PACKAGE, '**', '*.py'), recursive=True)
    for path in sorted(os.path.relpath(p, _PACKAGE) for p in paths):
        h.update(path.encode())
        with open(os.path.join(_PACKAGE, path), 'rb') as f:
            h.update(f.read())
    return h.hexdigest()[:12]


def cache_dir(kind: str) -> str:
    """``hair_tracking/__pycache__/<kind>-<source hash>`` when that is writable, else
    ``$XDG_CACHE_HOME`` (or ``~/.cache``) ``/hair_tracking/<kind>-<source hash>``: a folder of
    things made from the sources as they are (not created here)."""
    name = f'{kind}-{source_hash()}'
    local = os.path.join(_PACKAGE, '__pycache__')
    if os.access(local if os.path.isdir(local) else _PACKAGE, os.W_OK):
        return os.path.join(local, name)
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'hair_tracking', name)


def numba_cache_dir() -> str:
    """numba's cache folder: :func:`cache_dir` ``numba``."""
    return cache_dir('numba')


def use_numba_cache() -> str:
    """Set ``NUMBA_CACHE_DIR`` to :func:`numba_cache_dir` unless it is set; returns the folder.

    numba reads the variable when it is first imported: call this before that (the tests'
    ``conftest.py`` and the scripts do so too, and so share the cache ``make install`` fills).
    """
    if not os.environ.get('NUMBA_CACHE_DIR'):
        os.environ['NUMBA_CACHE_DIR'] = numba_cache_dir()
        if 'numba' in sys.modules:
            print(f'warning: numba was loaded before its cache folder was set, so it keeps '
                  f'its own; run the console script, or set NUMBA_CACHE_DIR='
                  f'{os.environ["NUMBA_CACHE_DIR"]}', file=sys.stderr)
    return os.environ['NUMBA_CACHE_DIR']


@contextlib.contextmanager
def started():
    """What an executable's ``main()`` does first: numba's cache folder and the stop request
    (:class:`hair_tracking.shutdown.StopRequest`, yielded; its signal handlers are removed at
    the end, so a test can call ``main()`` in its own process)."""
    use_numba_cache()
    with shutdown.installed() as stop:
        yield stop


# ==================================================================== process settings
#: Default of ``--malloc-retain-mb``: a few clouds' worth of copies, small next to a desktop's
#: memory (what it buys: docs/node.md, "Process settings").
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

    Sets ``M_TRIM_THRESHOLD`` to ``megabytes`` and ``M_MMAP_THRESHOLD`` to 32 MiB (mallopt(3)),
    so message buffers up to 32 MiB come from the heap and, once freed, are reused without page
    faults.  glibc's own rule returns freed memory at the top of the heap once more than twice
    the largest freed chunk is free, so a process that copies multi-megabyte clouds maps and
    faults in fresh pages for every copy.  The cost is memory: the process keeps up to
    ``megabytes`` more resident than it uses at a time.  Process-wide.

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
    sleeps.  ``passive`` sets ``OMP_WAIT_POLICY=PASSIVE``: workers sleep at once, and each
    parallel region pays a wake-up.  ``active`` sets ``ACTIVE``: workers spin between regions.
    Only OpenMP reads the variable, so numba's threading layer is pinned to ``omp``
    (``numba.config.THREADING_LAYER``) and its threads are started here, while the variable
    is fresh; without numba's OpenMP layer the policy is not applied.

    Nothing changes when the environment sets ``OMP_WAIT_POLICY`` (the user's choice wins), or
    a ``NUMBA_THREADING_LAYER`` other than ``omp``, or when numba's threads run already;
    ``environment`` leaves everything alone.  Returns what was done, for the log.
    """
    if policy not in OMP_WAIT_POLICIES:
        raise ValueError(f'omp_wait_policy must be one of {", ".join(OMP_WAIT_POLICIES)}, '
                         f'got {policy!r}')
    if policy == 'environment':
        return 'OpenMP wait policy: as the environment says'
    if 'OMP_WAIT_POLICY' in os.environ:
        return f'OMP_WAIT_POLICY={os.environ["OMP_WAIT_POLICY"]} from the environment kept'
    layer = os.environ.get('NUMBA_THREADING_LAYER', '')
    if layer and layer != 'omp':
        return (f'NUMBA_THREADING_LAYER={layer} from the environment kept: wait policy '
                f'{policy} not applied')
    if _openmp_started():
        return f'OpenMP threads already started: wait policy {policy} not applied'
    import numba
    os.environ['OMP_WAIT_POLICY'] = policy.upper()
    numba.config.THREADING_LAYER = 'omp'
    try:
        numba.get_num_threads()          # starts the threads: libgomp reads the policy
    except ValueError:                   # numba cannot load its OpenMP layer here
        numba.config.THREADING_LAYER = 'default'
        del os.environ['OMP_WAIT_POLICY']
        return f"numba's OpenMP threading layer is not available: wait policy {policy} not applied"
    return (f'OpenMP worker threads wait {policy} (numba threading layer omp, '
            f'OMP_WAIT_POLICY={policy.upper()})')


def add_arguments(parser, omp_wait_policy: Optional[str] = 'passive',
                  gc_freeze: bool = True) -> None:
    """Add the process settings to an executable's ``argparse`` parser.

    ``omp_wait_policy``: the default of ``--omp-wait-policy`` (``passive``: what the
    benchmarks show on a machine whose cores the executable shares, docs/node.md), None for an
    executable that runs no parallel kernel (no such option then); ``gc_freeze``: whether it
    has ``--no-gc-freeze`` (one that freezes its start-up heap once set up).
    """
    if omp_wait_policy is not None and omp_wait_policy not in OMP_WAIT_POLICIES:
        raise ValueError(f'omp_wait_policy must be one of {", ".join(OMP_WAIT_POLICIES)}')
    g = parser.add_argument_group(
        'process settings', 'process-wide, applied once at start by this executable')
    g.add_argument('--malloc-retain-mb', type=int, default=DEFAULT_RETAIN_MB, metavar='MB',
                   help='freed memory glibc keeps mapped for reuse, so large message buffers '
                        'are not faulted in again page by page; 0 keeps glibc\'s defaults; '
                        'GLIBC_TUNABLES wins (default: %(default)s)')
    if omp_wait_policy is not None:
        g.add_argument('--omp-wait-policy', choices=OMP_WAIT_POLICIES, default=omp_wait_policy,
                       help='how idle OpenMP worker threads of the numba kernels wait: passive '
                            'sleeps, active spins between parallel regions (both pin numba\'s '
                            'threading layer to OpenMP), environment leaves OMP_WAIT_POLICY '
                            'and the layer alone (unset: libgomp spins a while, then sleeps); '
                            'an OMP_WAIT_POLICY in the environment wins (default: %(default)s)')
    if gc_freeze:
        g.add_argument('--no-gc-freeze', dest='gc_freeze', action='store_false',
                       help='do not freeze the objects made at start-up out of the garbage '
                            "collector's reach once set up (default: freeze)")


def apply(args) -> List[str]:
    """Apply the memory and thread settings of :func:`add_arguments` (before numba starts its
    threads); returns what was done, for the log.  The GC freeze is the caller's, once set up."""
    if not 0 <= args.malloc_retain_mb <= 2047:
        raise ValueError(f'--malloc-retain-mb must be in [0, 2047], got {args.malloc_retain_mb}')
    done = []
    if getattr(args, 'omp_wait_policy', None) is not None:
        done.append(set_omp_wait_policy(args.omp_wait_policy))
    done.append(retain_freed_memory(args.malloc_retain_mb))
    return done


# ==================================================================== console entry points
def _main_of(module: str, interruptible: bool = False) -> int:
    """``module``'s ``main()``, imported once numba's cache folder and the stop request are set
    up; ``interruptible``: plain Python and numba work, which a stop interrupts anywhere (exit
    code 0)."""
    with started() as stop:
        main = importlib.import_module(module).main
        if not interruptible:
            return main()
        try:
            with stop.interruptible():
                return main()
        except KeyboardInterrupt:
            print(f'stopped ({stop.signal_name or "interrupted"})', file=sys.stderr)
            return 0


def hair_sim_node() -> int:
    """``hair_sim_node``: :func:`hair_tracking.ros.node.main`."""
    return _main_of('hair_tracking.ros.node')


def hair_sim_ghosts() -> int:
    """``hair_sim_ghosts``: :func:`hair_tracking.ros.ghosts.main`."""
    return _main_of('hair_tracking.ros.ghosts')


def hair_sim_bag() -> int:
    """``hair_sim_bag``: :func:`hair_tracking.ros.bag_cli.main`."""
    return _main_of('hair_tracking.ros.bag_cli')


def hair_sim_groom() -> int:
    """``hair_sim_groom``: :func:`hair_tracking.bags.groom_cli.main`."""
    return _main_of('hair_tracking.bags.groom_cli')


def hair_sim_eval() -> int:
    """``hair_sim_eval``: :func:`hair_tracking.evaluation.cli.main`."""
    return _main_of('hair_tracking.evaluation.cli', interruptible=True)


def hair_sim_demo() -> int:
    """``hair_sim_demo``: :func:`hair_tracking.evaluation.demo.main`."""
    return _main_of('hair_tracking.evaluation.demo', interruptible=True)


def hair_sim_warmup() -> int:
    """``hair_sim_warmup``: :func:`hair_tracking.bags.warmup.main`."""
    return _main_of('hair_tracking.bags.warmup')


def hair_sim_ctl() -> int:
    """``hair_sim_ctl``: :func:`hair_tracking.ros.ctl.main`."""
    return _main_of('hair_tracking.ros.ctl')


def hair_sim_view() -> int:
    """``hair_sim_view``: :func:`hair_tracking.ros.view.main`."""
    return _main_of('hair_tracking.ros.view')
