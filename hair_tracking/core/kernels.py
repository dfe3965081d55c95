"""What every compiled kernel of the package shares: its fast-math flags, the block of strands
one thread takes, the size at which a problem runs the parallel variants, and how the two
variants of a kernel are compiled from its one body (:func:`parallel_and_serial`)."""
import types

from numba import njit

#: Below this many nodes a problem runs the serial variants of the kernels (``<kernel>_serial``:
#: the same body on the calling thread, :func:`parallel_and_serial`): the work is then smaller than
#: a parallel region's launch.  The default groom's 64 guides (1 k nodes) stay serial, its 512
#: ghosts (8 k nodes) run the parallel kernels.  Results do not depend on the thread count
#: (tested).
PARALLEL_MIN_NODES = 1 << 12


def runs_parallel(nodes: int) -> bool:
    """Whether a problem of ``nodes`` nodes runs the parallel kernels (at least
    PARALLEL_MIN_NODES nodes) rather than their serial variants, whatever the numba thread
    count: on one thread a parallel kernel costs a launch but is not slower otherwise, and
    where LLVM compiles a loop body differently in the two variants the parallel one was the
    faster, so every method runs the same code at any thread count.  The simulator decides
    once, from the whole scene's node counts, and hands the decision to each stage."""
    return nodes >= PARALLEL_MIN_NODES


def parallel_and_serial(body, **flags):
    """The kernel ``body`` (a plain function whose outer loop is written with ``prange``)
    compiled twice with the numba ``flags``: ``(parallel, serial)``, the first with
    ``parallel=True`` (the loop split over the threads), the second on the calling thread
    (numba compiles ``prange`` as ``range`` without ``parallel``).  Both are cached; the
    serial one is compiled from a copy of ``body`` named ``<name>_serial``, so that each has
    its own entry in numba's cache (the cache names an entry by the function's qualified name
    and line, not by its compile flags)."""
    parallel = njit(cache=True, nogil=True, parallel=True, **flags)(body)
    twin = types.FunctionType(body.__code__, body.__globals__, body.__name__ + '_serial',
                              body.__defaults__, body.__closure__)
    twin.__qualname__ = body.__qualname__ + '_serial'
    twin.__module__ = body.__module__
    twin.__doc__ = f':func:`{body.__name__}` on the calling thread (the same results).'
    return parallel, njit(cache=True, nogil=True, **flags)(twin)


#: Strands one thread processes together.  The constraint sweeps interleave the strands of a
#: block (strand index innermost), so the CPU overlaps their independent dependency chains.
BLOCK = 8

#: LLVM fast-math flags of every kernel: only ``contract`` (fused multiply-add). Results are
#: deterministic for a given build, agree with the numpy references to ~1e-15 relative, and NaN /
#: infinity semantics are kept (no ``nnan``/``ninf``).
FASTMATH = {'contract'}
