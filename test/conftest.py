"""Test-wide settings: ROS message field checks on, discovery kept on this machine, and numba's
cache in the folder keyed by the package's sources that the executables use (set before numba is
imported; :mod:`hair_tracking.executable` says why: an edit to one kernel module must not leave
a stale compiled caller behind).  The processes the tests start inherit all three.
"""
import os

import pytest

os.environ.setdefault('ROS_PYTHON_CHECK_FIELDS', '1')
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')

from hair_tracking import executable  # noqa: E402

executable.use_numba_cache()           # before numba is imported (it reads the variable then)


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
