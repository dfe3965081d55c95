"""Per-strand colours of the published hair (ROS-free: shared by the node and offline runs)."""
from typing import Callable, Dict, Tuple

import numpy as np


def strand_colors(n: int, rgba) -> np.ndarray:
    """(n, 4) per-strand colours: ``rgba`` with a fixed +-15 % brightness variation per strand.

    The variation (a hash of the strand index, so stable across frames and rebuilds) lets rviz
    tell strands apart when colouring the cloud by ``rgb``.
    """
    idx = np.arange(n, dtype=np.uint64)
    h = (idx * np.uint64(2654435761)) % np.uint64(1000)
    shade = 0.85 + 0.3 * (h.astype(np.float64) / 999.0)
    out = np.empty((n, 4))
    out[:, :3] = np.clip(np.asarray(rgba[:3], dtype=np.float64)[None, :] * shade[:, None],
                         0.0, 1.0)
    out[:, 3] = rgba[3]
    return out


class StrandColorCache:
    """The last :func:`strand_colors` of each namespace, recomputed only when the strand count
    or the colour changes (the node and ``FrameEncoder`` ask once per published frame).

    ``pack``: the function applied to the colours before they are cached (the publishers pass
    ``msg_adapters.pointcloud.pack_rgb_u32``, so a frame does not pack them again).  The
    cached arrays are read-only (every frame shares them)."""

    def __init__(self, pack: Callable[[np.ndarray], np.ndarray]):
        self._pack = pack
        self._cache: Dict[str, Tuple[tuple, np.ndarray]] = {}

    def get(self, ns: str, n: int, rgba) -> np.ndarray:
        key = (n, tuple(rgba))
        c = self._cache.get(ns)
        if c is None or c[0] != key:
            colors = self._pack(strand_colors(n, rgba))
            colors.flags.writeable = False      # shared by every frame that uses it
            c = self._cache[ns] = (key, colors)
        return c[1]
