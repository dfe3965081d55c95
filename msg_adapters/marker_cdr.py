"""Strands ``(S, N, 3)`` -> serialized visualization_msgs/MarkerArray CDR bytes, with numpy.

Byte for byte the MarkerArray that :func:`msg_adapters.markers.strands_to_marker_array` builds
(same arguments, same validation), as ``rclpy.serialization.serialize_message`` would write it
(padding zeroed, see :mod:`msg_adapters.cdr`), without creating one Python object per point.
``Publisher.publish`` accepts the bytes as they are; ``deserialize_message`` reads them back.

How: the fixed fields of a marker are laid out once by :class:`~msg_adapters.cdr.CdrWriter`
with holes for the points and colours; the points go in with one strided numpy copy. For
'line_strips' a marker's layout depends only on its start offset modulo 8, so the layouts
repeat: a block of one period is a template row, and all full blocks are filled as one 2-D
array, column by column (the template's fixed bytes, ids, points, colours). For Marker the
period is 1 after at most one leading marker (the 8-aligned pose resets the phase); the plan
does not rely on that.
"""
import numpy as np

from msg_adapters.cdr import CdrWriter, MessageBuffer, put_pieces
from msg_adapters.marker_spec import ADD, DELETEALL, prepare_markers

# visualization_msgs/Marker fields in the order written below (Jazzy); the tests compare this
# with Marker.get_fields_and_field_types() of the installed message package.
MARKER_FIELDS = ('header', 'ns', 'id', 'type', 'action', 'pose', 'scale', 'color', 'lifetime',
                 'frame_locked', 'points', 'colors', 'texture_resource', 'texture',
                 'uv_coordinates', 'text', 'mesh_resource', 'mesh_file',
                 'mesh_use_embedded_materials')
POINT_BYTES = 24     # geometry_msgs/Point: 3 float64
COLOR_BYTES = 16     # std_msgs/ColorRGBA: 4 float32


def write_marker(w, *, stamp, frame_id, ns, mid=0, mtype=0, action=ADD, scale=(0.0, 0.0, 0.0),
                 color=(0.0, 0.0, 0.0, 0.0), lifetime=(0, 0), n_points=0, n_colors=0):
    """Lay out one Marker (empty texture, uv, text, mesh) -> body offsets of id/points/colors.

    Points and colours are holes of ``n_points`` / ``n_colors`` elements for the caller to
    fill; their offsets are None when empty.
    """
    w.time(*stamp)                              # header.stamp
    w.string(frame_id)                          # header.frame_id
    w.string(ns)
    at_id = w.int32(mid)
    w.int32(mtype)
    w.int32(action)
    for v in (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0):   # pose: position, orientation (identity)
        w.float64(v)
    for v in scale:
        w.float64(v)
    for v in color:
        w.float32(v)
    w.time(*lifetime)
    w.boolean(False)                            # frame_locked
    w.uint32(n_points)
    at_points = w.hole(n_points * POINT_BYTES, 8) if n_points else None
    w.uint32(n_colors)
    at_colors = w.hole(n_colors * COLOR_BYTES, 4) if n_colors else None
    w.string('')                                # texture_resource
    w.time(0, 0)                                # texture: sensor_msgs/CompressedImage
    w.string('')                                # texture.header.frame_id
    w.string('')                                # texture.format
    w.uint32(0)                                 # texture.data
    w.uint32(0)                                 # uv_coordinates
    w.string('')                                # text
    w.string('')                                # mesh_resource
    w.string('')                                # mesh_file.filename
    w.uint32(0)                                 # mesh_file.data
    w.boolean(False)                            # mesh_use_embedded_materials
    return at_id, at_points, at_colors


def _add_marker(w, spec, mid, n_points, with_colors):
    return write_marker(w, stamp=spec.stamp, frame_id=spec.frame_id, ns=spec.ns, mid=mid,
                        mtype=spec.marker_type(), action=ADD, scale=(spec.width, 0.0, 0.0),
                        color=spec.color, lifetime=spec.lifetime, n_points=n_points,
                        n_colors=n_points if with_colors else 0)


def _void(a, nbytes):
    """View a C-contiguous array's last axis (``nbytes`` long) as one opaque element."""
    return np.ascontiguousarray(a).view(np.dtype((np.void, nbytes)))[..., 0]


def _pairs(v):
    """(S, N) opaque elements -> (S, N - 1) elements of twice the size, ``(v[i], v[i + 1])``.

    A view, since the two are adjacent in memory: the LINE_LIST segments without a copy.
    """
    size = v.dtype.itemsize
    return np.ndarray(shape=(v.shape[0], v.shape[1] - 1), dtype=np.dtype((np.void, 2 * size)),
                      buffer=v, strides=(v.strides[0], size))


def _slots(body, at, shape, size):
    """``body[at:]`` as an array of ``shape`` opaque elements of ``size`` bytes."""
    n = int(np.prod(shape)) * size
    return body[at:at + n].view(np.dtype((np.void, size))).reshape(shape)


def _fill_line_list(body, at_points, at_colors, x, cols):
    n_strands, n_points = x.shape[:2]
    if at_points is None:
        return
    pairs = (n_strands, n_points - 1)
    _slots(body, at_points, pairs, 2 * POINT_BYTES)[...] = _pairs(_void(x, POINT_BYTES))
    if at_colors is not None:
        c = _void(cols, COLOR_BYTES)                    # (S, 1) or (S, N)
        if c.shape[1] == 1:
            _slots(body, at_colors, pairs + (2,), COLOR_BYTES)[...] = c[:, :, None]
        else:
            _slots(body, at_colors, pairs, 2 * COLOR_BYTES)[...] = _pairs(c)


def _strip_runs(spec, start, n_points, with_colors, n_strands):
    """Plan S consecutive LINE_STRIP markers from body offset ``start``.

    A marker's layout depends only on its start offset modulo 8, so the layouts repeat after a
    few markers. Returns runs ``(first strand, reps, layouts)``: ``reps`` repetitions of the
    block of ``len(layouts)`` markers, each layout ``(template, at_id, at_points, at_colors)``
    with offsets relative to the marker start.
    """
    seen, layouts, at = {}, [], start
    while at % 8 not in seen and len(layouts) < n_strands:
        seen[at % 8] = len(layouts)
        w = CdrWriter(origin=at)
        offs = _add_marker(w, spec, 0, n_points, with_colors)
        layouts.append((w.template(),) + tuple(None if o is None else o - at for o in offs))
        at = w.offset
    mu = seen.get(at % 8, len(layouts))
    runs = [(0, 1, layouts[:mu])] if mu else []
    cycle = layouts[mu:]
    if cycle:
        reps, tail = divmod(n_strands - mu, len(cycle))
        if reps:
            runs.append((mu, reps, cycle))
        if tail:
            runs.append((mu + reps * len(cycle), 1, cycle[:tail]))
    return runs


def _runs_size(runs):
    return sum(reps * sum(len(t[0]) for t in layouts) for _, reps, layouts in runs)


def _fill_strips(body, at, runs, ids, x, cols):
    """Write the LINE_STRIP markers planned by :func:`_strip_runs` from body offset ``at``."""
    n_strands, n_points = x.shape[:2]
    x_rows = _void(x.reshape(n_strands, n_points * 3), n_points * POINT_BYTES)
    if cols is not None:
        c_points = _void(cols, COLOR_BYTES)                # (S, 1) or (S, N)
    for first, reps, layouts in runs:
        period = len(layouts)
        width = sum(len(t[0]) for t in layouts)
        rows = body[at:at + reps * width].reshape(reps, width)
        col = 0
        for j, (tmpl, at_id, at_pts, at_col) in enumerate(layouts):
            sel = slice(first + j, first + j + period * reps, period)
            holes = [(at_id, 4), (at_pts, n_points * POINT_BYTES)]
            if cols is not None:
                holes.append((at_col, n_points * COLOR_BYTES))
            fixed = 0                           # template bytes between the holes
            for start, size in holes + [(len(tmpl), 0)]:
                if start > fixed:
                    kind = np.dtype((np.void, start - fixed))
                    rows[:, col + fixed:col + start].view(kind)[:, 0] = \
                        np.frombuffer(tmpl[fixed:start], kind)[0]
                fixed = start + size
            rows[:, col + at_id:col + at_id + 4].view('<i4')[:, 0] = ids[sel]
            rows[:, col + at_pts:col + at_pts + n_points * POINT_BYTES].view(
                x_rows.dtype)[:, 0] = x_rows[sel]
            if cols is not None:
                rows[:, col + at_col:col + at_col + n_points * COLOR_BYTES].view(
                    c_points.dtype)[...] = c_points[sel]
            col += len(tmpl)
        at += reps * width
    return at


def strands_to_marker_array_cdr(strands, *, frame_id, stamp_ns=0, ns='strands',
                                style='line_list', width=0.001, color=(1.0, 1.0, 1.0, 1.0),
                                colors=None, lifetime_ns=0, first_id=0, delete_all_first=False):
    """Serialized MarkerArray (``bytes``, CDR little-endian) of ``strands`` (S, N >= 2, 3) [m].

    Same arguments, validation and message as
    :func:`msg_adapters.markers.strands_to_marker_array`.
    """
    spec, x, cols = prepare_markers(
        strands, frame_id=frame_id, stamp_ns=stamp_ns, ns=ns, style=style, width=width,
        color=color, colors=colors, lifetime_ns=lifetime_ns, first_id=first_id,
        delete_all_first=delete_all_first)
    n_strands, n_points = x.shape[:2]
    line_list = spec.style == 'line_list'
    n_markers = (1 if line_list else n_strands) + int(spec.delete_all_first)

    head = CdrWriter()
    head.uint32(n_markers)
    if spec.delete_all_first:
        write_marker(head, stamp=spec.stamp, frame_id=spec.frame_id, ns=spec.ns,
                     action=DELETEALL)
    if line_list:
        n_list = 2 * n_strands * (n_points - 1)
        _, at_points, at_colors = _add_marker(head, spec, spec.first_id, n_list,
                                              cols is not None)
        buf = MessageBuffer(head.offset)
        put_pieces(buf.body, head.pieces())
        _fill_line_list(buf.body, at_points, at_colors, x, cols)
        return buf.finish()

    runs = _strip_runs(spec, head.offset, n_points, cols is not None, n_strands)
    total = head.offset + _runs_size(runs)
    buf = MessageBuffer(total)
    put_pieces(buf.body, head.pieces())
    ids = np.arange(spec.first_id, spec.first_id + n_strands, dtype='<i4')
    end = _fill_strips(buf.body, head.offset, runs, ids, x, cols)
    assert end == total, (end, total)
    return buf.finish()
