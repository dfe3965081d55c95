"""Do the guide kernels' lane sweeps compile to vector instructions on this machine?

The PBD and XPBD sweeps process a block of strands side by side ([node][axis][strand], see
``hair_tracking.guides.pbd_constraints``) so that LLVM can vectorise the loop over the block's
strands; signed indices or a run-time lane count make it fall back to scalar code, several times
slower.  This script compiles each sweep afresh (numba shows no IR of cached code), calls it as
the kernels call it (the gap a literal, the node count a run-time value) and looks for a vector
square root in the LLVM IR.  What LLVM emits depends on the CPU and the LLVM build, so this is a
check to run by hand or from ``make bench``, not a unit test.

    python scripts/check_simd.py        # exit status 1 if a sweep is scalar
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numba  # noqa: E402
import numpy as np  # noqa: E402

from hair_tracking.guides import pbd_constraints  # noqa: E402


def vectorised(name: str) -> bool:
    fn = getattr(pbd_constraints, name)
    options = {k: v for k, v in fn.targetoptions.items() if k not in ('nopython', 'cache')}
    fresh = numba.njit(**options)(fn.py_func)
    n, lanes = 6, pbd_constraints.LANES
    p = np.random.default_rng(0).normal(size=n * 3 * lanes)
    rd, w = np.full((n - 1) * lanes, 0.1), np.full((n - 1) * 2 * lanes, 0.5)
    if name == 'pbd_sweep_lanes':
        @numba.njit
        def call(p, rd, w, n):
            fresh(p, rd, w, n, 1, 0.9)
    else:
        @numba.njit
        def call(p, rd, w, n):
            fresh(p, w[:n * lanes], rd, rd, np.zeros_like(rd), n, 1, 0.5)
    call(p, rd, w, n)
    ir = '\n'.join(fresh.inspect_llvm(sig) for sig in fresh.signatures)
    return re.search(r'llvm\.sqrt\.v\d+f64', ir) is not None


def main() -> int:
    ok = True
    for name in ('pbd_sweep_lanes', 'xpbd_sweep_lanes'):
        vec = vectorised(name)
        ok = ok and vec
        print(f'{name}: {"vector" if vec else "SCALAR"} square roots in the LLVM IR')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
