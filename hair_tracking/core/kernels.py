"""What every compiled kernel of the package shares: its fast-math flags, the block of strands
one thread takes, and the size at which a problem runs the parallel variants."""

#: Below this many nodes a problem runs the serial variants of the kernels (``<kernel>_serial``:
#: the same block bodies in a plain loop on the calling thread): the work is then smaller than
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


#: Strands one thread processes together.  The constraint sweeps interleave the strands of a
#: block (strand index innermost), so the CPU overlaps their independent dependency chains.
BLOCK = 8

#: LLVM fast-math flags of every kernel: only ``contract`` (fused multiply-add). Results are
#: deterministic for a given build, agree with the numpy references to ~1e-15 relative, and NaN /
#: infinity semantics are kept (no ``nnan``/``ninf``).
FASTMATH = {'contract'}
