"""hair_tracking: real-time hair that follows a head pose.

Guide (target) strands are simulated with position-based dynamics; many ghost strands track them
(Park & Kim, "PBD-based Framework for Efficiently Controlling the Movement of Strands in Hair").
The core modules of this package import numpy, numba and yaml only.

numba's on-disk cache (``cache=True``) checks only the timestamp of the file that defines a
kernel, not of the files whose jitted functions the kernel inlines (the ghost kernels inline
functions of ``guides.collision``, ``guides.ftl`` and ``ghosts.weights``), so editing one module
could leave a stale
compiled caller behind.  Unless ``NUMBA_CACHE_DIR`` is set, the package therefore points numba's
cache at a directory keyed by a hash of its own sources (:func:`numba_cache_dir`): any edit
starts from a fresh cache, unchanged sources reuse the compiled kernels.
"""
import glob
import hashlib
import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))


def source_hash() -> str:
    """12 hex digits of the SHA-1 of every ``hair_tracking/**/*.py`` (paths relative to the
    package and contents, sorted by path), so an edit in any subpackage changes it."""
    h = hashlib.sha1()
    paths = glob.glob(os.path.join(_HERE, '**', '*.py'), recursive=True)
    for path in sorted(os.path.relpath(p, _HERE) for p in paths):
        h.update(path.encode())
        with open(os.path.join(_HERE, path), 'rb') as f:
            h.update(f.read())
    return h.hexdigest()[:12]


def numba_cache_dir() -> str:
    """``hair_tracking/__pycache__/numba-<source hash>`` when that is writable, else
    ``$XDG_CACHE_HOME`` (or ``~/.cache``) ``/hair_tracking/numba-<source hash>``."""
    name = f'numba-{source_hash()}'
    local = os.path.join(_HERE, '__pycache__')
    if os.access(local if os.path.isdir(local) else _HERE, os.W_OK):
        return os.path.join(local, name)
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return os.path.join(base, 'hair_tracking', name)


if not os.environ.get('NUMBA_CACHE_DIR'):
    os.environ['NUMBA_CACHE_DIR'] = numba_cache_dir()
    if 'numba' in sys.modules:          # numba read its configuration already
        sys.modules['numba'].config.CACHE_DIR = os.environ['NUMBA_CACHE_DIR']
