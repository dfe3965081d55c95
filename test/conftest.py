"""Test-wide settings: ROS message field checks on, discovery kept on this machine, and numba's
cache keyed by the package's sources (importing :mod:`hair_tracking` sets that up, see its
docstring: an edit to one kernel module must not leave a stale compiled caller behind).
"""
import os

import pytest

os.environ.setdefault('ROS_PYTHON_CHECK_FIELDS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

import hair_tracking  # noqa: E402,F401  (before numba: it points NUMBA_CACHE_DIR at the hash)


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


@pytest.fixture(autouse=True)
def _keep_omp_wait_policy():
    """A test that runs an executable's main() in this process (``hair_sim_bag run``) sets
    OMP_WAIT_POLICY as that executable would; the processes later tests start must not inherit
    it."""
    before = os.environ.get('OMP_WAIT_POLICY')
    yield
    if before is None:
        os.environ.pop('OMP_WAIT_POLICY', None)
    else:
        os.environ['OMP_WAIT_POLICY'] = before
