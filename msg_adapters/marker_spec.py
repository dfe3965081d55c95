"""Validated parameters shared by both MarkerArray builders (message objects and CDR bytes).

Both paths call :func:`prepare_markers`, so they accept the same inputs and produce the same
message. rviz semantics kept here:
- a marker is identified by ``(ns, id)``; ADD (= MODIFY) replaces the marker with that key;
- ``'line_list'``: ONE LINE_LIST marker (id ``first_id``) whose points are the segment pairs
  ``(p[s, i], p[s, i + 1])`` of every strand — the fast way to draw thousands of strands;
- ``'line_strips'``: one LINE_STRIP per strand, id ``first_id + s``;
- ``colors`` is empty (rviz uses ``color``) or holds exactly one colour per point;
- ``scale.x`` is the line width [m]; ``lifetime`` 0 means forever, a few publishing periods
  makes a dead publisher's markers disappear;
- pose is identity (x, y, z, w = 0, 0, 0, 1), so points are in ``frame_id`` [m];
- an optional DELETEALL marker first (same ``frame_id``, which rviz requires, and same ``ns``)
  clears stale markers, e.g. strips left over when the strand count drops. rviz2 scopes a
  DELETEALL with a non-empty ``ns`` to that namespace (ros2/rviz#685, 2021); ``ns=''``
  clears every namespace of the display.
"""
from dataclasses import dataclass

from msg_adapters.arrays import as_color, as_colors, as_strands
from msg_adapters.stamps import as_int, INT32_MAX, split_ns

STYLES = ('line_list', 'line_strips')
# visualization_msgs/Marker constants (checked against the message class in the tests).
LINE_STRIP = 4
LINE_LIST = 5
ADD = 0
DELETEALL = 3


@dataclass(frozen=True)
class MarkerSpec:
    """Everything but the arrays; all scalars exact Python types, floats float32-exact."""

    style: str
    frame_id: str
    stamp: tuple          # (sec, nanosec)
    ns: str
    width: float          # scale.x [m]
    color: tuple          # RGBA floats, float32-exact
    lifetime: tuple       # (sec, nanosec)
    first_id: int
    delete_all_first: bool

    def marker_type(self):
        return LINE_LIST if self.style == 'line_list' else LINE_STRIP


def _text(value, name, allow_empty):
    if not isinstance(value, str):
        raise TypeError(f'{name} must be a str, got {type(value).__name__}')
    if '\x00' in value:
        raise ValueError(f'{name} {value!r} contains a NUL character')
    if not allow_empty and not value:
        raise ValueError(f'{name} must not be empty (rviz needs a frame to draw markers in)')
    return value


def check_frame_id(frame_id):
    return _text(frame_id, 'frame_id', allow_empty=False)


def check_ns(ns):
    return _text(ns, 'ns', allow_empty=True)


def prepare_markers(strands, *, frame_id, stamp_ns=0, ns='strands', style='line_list',
                    width=0.001, color=(1.0, 1.0, 1.0, 1.0), colors=None, lifetime_ns=0,
                    first_id=0, delete_all_first=False):
    """Validate builder inputs -> ``(MarkerSpec, strands (S, N, 3) float64, colors)``.

    ``colors`` comes back as float32 ``(S, 1, 4)`` (per strand), ``(S, N, 4)`` (per point) or
    None. Strands need N >= 2 points and finite coordinates (ValueError otherwise).
    """
    if style not in STYLES:
        raise ValueError(f'style must be one of {STYLES}, got {style!r}')
    x = as_strands(strands, min_points=2)
    n_strands, n_points = x.shape[:2]
    cols = as_colors(colors, n_strands, n_points)
    w = float(width)
    if not 0.0 < w < float('inf'):
        raise ValueError(f'width must be a finite line width > 0 m, got {width!r}')
    first_id = as_int(first_id, 'first_id')
    last_id = first_id + (max(n_strands, 1) - 1 if style == 'line_strips' else 0)
    if first_id < -INT32_MAX - 1 or last_id > INT32_MAX:
        raise ValueError(f'marker ids {first_id}..{last_id} do not fit int32')
    spec = MarkerSpec(style=style, frame_id=check_frame_id(frame_id),
                      stamp=split_ns(stamp_ns, 'stamp_ns'), ns=check_ns(ns), width=w,
                      color=as_color(color), lifetime=split_ns(lifetime_ns, 'lifetime_ns'),
                      first_id=first_id, delete_all_first=bool(delete_all_first))
    return spec, x, cols
