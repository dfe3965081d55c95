"""Test-wide settings: ROS message field checks on, discovery kept on this machine, and a numba
cache keyed by the kernels' sources.

numba's on-disk cache (``cache=True``) only checks the timestamp of the file that defines a kernel,
not of the files whose jitted functions it inlines, so an edit to one kernel module can leave a
stale compiled caller behind.  Keying the cache directory by a hash of every core source file
makes any edit start from a fresh cache, while unchanged sources reuse the compiled kernels.
"""
import glob
import hashlib
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

os.environ.setdefault('ROS_PYTHON_CHECK_FIELDS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def _source_hash() -> str:
    h = hashlib.sha1()
    for path in sorted(glob.glob(os.path.join(ROOT, 'hair_tracking', '*.py'))):
        with open(path, 'rb') as f:
            h.update(f.read())
    return h.hexdigest()[:12]


os.environ.setdefault('NUMBA_CACHE_DIR', os.path.join(ROOT, '.numba_cache', _source_hash()))


@pytest.fixture(scope='module')
def one_numba_thread():
    """numba on one thread for a module that checks behaviour, not speed: numba's thread pool
    stalls on a loaded two-core machine (measured 30x slower there); restored afterwards.
    (numba is imported here, not at the top: it reads NUMBA_CACHE_DIR when first imported.)"""
    import numba
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    yield
    numba.set_num_threads(before)
