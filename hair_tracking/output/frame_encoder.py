"""The serialized output messages of one frame of hair (CDR bytes), for every publisher of it:
the ``hair_sim`` node, ``hair_sim_bag run`` and the ghost shards (``hair_sim_ghosts``).

One frame is up to four messages, each under a key of :data:`OUTPUTS`: the ghosts' cloud
(``points``, sensor_msgs/PointCloud2) and markers (``markers``, visualization_msgs/MarkerArray),
and the guides' (``guide_points``, ``guide_markers``).  Clouds are written straight from the
simulator's state (:meth:`~hair_tracking.simulator.HairSimulator.record_writer`) into a buffer
kept per namespace (:class:`msg_adapters.pointcloud.CloudBuffer`, rewritten in place), with
per-strand colours (:mod:`hair_tracking.output.strand_colors`); markers are ``line_list`` or
``line_strips`` with a DELETEALL in front of the first array of a namespace and whenever its
strand count or style changes, and a lifetime of ``marker_lifetime``.  A full head draws
only some of its strands (``marker_max_strands``) and may send some (``cloud_max_strands``):
evenly spread in their order, which runs along the scalp (:func:`spread_rows`); a cloud's
strands keep their ids and colours.
"""
from typing import Callable, Dict, NamedTuple, Optional, Sequence

import numpy as np

from msg_adapters.marker_cdr import strands_to_marker_array_cdr
from msg_adapters.pointcloud import CloudBuffer, pack_rgb_u32

from hair_tracking.output.settings import Settings
from hair_tracking.output.strand_colors import StrandColorCache

#: The messages of a frame: key -> (guides or not, namespace and colour field of the settings,
#: a cloud or markers).
OUTPUTS = {
    'points': (False, 'hair', 'cloud'),
    'markers': (False, 'hair', 'markers'),
    'guide_points': (True, 'guides', 'cloud'),
    'guide_markers': (True, 'guides', 'markers'),
}


def spread_rows(count: int, most: int) -> Optional[np.ndarray]:
    """``most`` of ``count`` strand indices, evenly spread in order; None for all (``most``
    0 or at least ``count``)."""
    if 0 < most < count:
        return np.linspace(0, count - 1, most).round().astype(np.int64)
    return None


class Encoded(NamedTuple):
    """One message of a frame: ``data`` its CDR bytes (a cloud: a uint8 array valid until the
    next cloud of its namespace), ``fresh`` whether it is a marker array that starts with a
    DELETEALL (sent once: a publisher that repeats a frame repeats only the others)."""

    data: object
    fresh: bool


class FrameEncoder:
    """The messages of a frame as :mod:`this module <hair_tracking.output.frame_encoder>`
    describes, under ``settings`` (:class:`~hair_tracking.output.settings.Settings`, replaced
    by assigning :attr:`settings`)."""

    def __init__(self, settings: Settings):
        self.settings = settings
        self._colors = StrandColorCache(pack_rgb_u32)
        self._shapes: Dict[str, tuple] = {}
        self._clouds: Dict[str, CloudBuffer] = {}

    def colors(self, ns: str, n: int, rgba) -> np.ndarray:
        """(n,) uint32 packed per-strand colours of the cloud (cached)."""
        return self._colors.get(ns, n, rgba)

    def _rgba(self, ns: str, rgba):
        if rgba is not None:
            return rgba
        s = self.settings
        return s.guide_color if ns == 'guides' else s.marker_color

    def cloud(self, n_strands: int, n_points: int, write_xyz: Callable, frame_id: str,
              stamp_ns: int, ns: str = 'hair', rgba=None, first: int = 0,
              total: Optional[int] = None, rows: Optional[np.ndarray] = None) -> np.ndarray:
        """The cloud whose coordinates ``write_xyz(words, stride)`` writes (as
        :meth:`hair_tracking.simulator.HairSimulator.record_writer`'s), in the buffer of
        ``ns``: valid until the next cloud of ``ns``.  ``rgba``: the strands' colour (default:
        ``marker_color``, ``guide_color`` for ``ns`` guides).  ``first``, ``total``: the rows
        are strands ``first`` .. ``first + n_strands - 1`` of ``total`` (a ghost shard's), or
        the strands ``rows`` of ``total``, numbered and coloured as in the cloud of all."""
        buf = self._clouds.get(ns)
        if buf is None:
            buf = self._clouds[ns] = CloudBuffer()
        s = self.settings
        whole = n_strands if total is None else int(total)
        ids = rows if rows is not None else (np.arange(first, first + n_strands) if first
                                             else None)
        rgb = None
        if s.cloud_rgb:
            rgb = self.colors(ns, whole, self._rgba(ns, rgba))
            rgb = rgb[ids] if ids is not None else rgb[:n_strands]
        return buf.encode(n_strands, n_points, write_xyz, frame_id=frame_id, stamp_ns=stamp_ns,
                          packed_rgb=rgb, strand_ids=ids, strand_field=s.cloud_strand)

    def markers(self, strands: np.ndarray, frame_id: str, stamp_ns: int, ns: str = 'hair',
                rgba=None) -> Encoded:
        """The marker array of ``strands`` (S, N, 3) in namespace ``ns``, at most
        ``marker_max_strands`` of them, evenly spread in their order (along the scalp);
        ``fresh`` when it starts with a DELETEALL."""
        s = self.settings
        rows = spread_rows(strands.shape[0], s.marker_max_strands)
        if rows is not None:
            strands = strands[rows]
        shape = (strands.shape[0], s.marker_style)
        fresh = self._shapes.get(ns) != shape
        self._shapes[ns] = shape
        data = strands_to_marker_array_cdr(
            strands, frame_id=frame_id, stamp_ns=stamp_ns, ns=ns, style=s.marker_style,
            width=s.marker_width, color=self._rgba(ns, rgba),
            lifetime_ns=int(round(s.marker_lifetime * 1e9)), delete_all_first=fresh)
        return Encoded(data, fresh)

    def frame(self, sim, keys: Sequence[str], frame_id: str, stamp_ns: int,
              head_frame: bool = False, frame=None) -> Dict[str, Encoded]:
        """The messages ``keys`` (of :data:`OUTPUTS`, in that order) of the hair of ``sim`` (a
        :class:`~hair_tracking.simulator.HairSimulator`) now, in the head frame with
        ``head_frame``.  ``frame``: ``sim.frame(head_frame=head_frame, copy=False)`` if the
        caller has it (else made first when a marker array needs it: the clouds are then
        written from the positions the frame placed)."""
        out: Dict[str, Encoded] = {}
        if frame is None and any(OUTPUTS[k][2] == 'markers' for k in keys):
            frame = sim.frame(head_frame=head_frame, copy=False)
        for key, (guides, ns, kind) in OUTPUTS.items():
            if key not in keys:
                continue
            if kind == 'cloud':
                count = sim.strand_count(guides)
                rows = spread_rows(count, self.settings.cloud_max_strands)
                out[key] = Encoded(self.cloud(*sim.record_writer(guides, head_frame, rows),
                                              frame_id, stamp_ns, ns, total=count, rows=rows),
                                   False)
                continue
            out[key] = self.markers(frame.guides if guides else frame.strands, frame_id,
                                    stamp_ns, ns)
        return out
