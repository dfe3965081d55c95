"""Pose tables -> head poses: CSV or whitespace text with a header line naming the columns.

:func:`read_pose_table` reads any such table (columns named as asked, or recognised by
:func:`recognise_columns`), :func:`read_vr360` the ``timestamp viewpoint w x y z``
head-mounted-display traces of Corbillon et al. (2017/2018), and :func:`read_pose_csv` /
:func:`write_pose_csv` the project's own compact format (``t_s,px,py,pz,qx,qy,qz,qw``).
:func:`load_bundled_walk` reads ``data/cmu_131_01_walk_head.csv`` shipped with the package (CMU
Graphics Lab Motion Capture Database, subject 131 trial 01, via the bvh11 repository; see
``data/ATTRIBUTION.md``), made by ``scripts/make_head_motion_data.py``.

The VR360 quaternions need no remapping: their world is z up and their head frame z up too
(user1: the head z axis has a mean cosine of 0.97 with world z, and 63 % of the turning is about
world z, i.e. yaw).  x is taken as the viewing direction, as we read Corbillon et al. (2017):
the stored rotation turns the reference direction (1, 0, 0) into the viewing direction (not
checked against the videos).
"""
import datetime
import decimal
import os

import numpy as np

from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.motion.head_motion import (HeadMotion, HeadMotionError, make_sign_continuous,
                                              PLAUSIBLE_RATE_HZ, timing_problem, UnitsError)
from hair_tracking.resources import data_path

DATA_DIR = data_path('')
BUNDLED_WALK_CSV = os.path.join(DATA_DIR, 'cmu_131_01_walk_head.csv')

POSE_CSV_COLUMNS = ('t_s', 'px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw')

#: Nanoseconds per tick of each time unit a pose table may use ('100ns': the 100 ns ticks of
#: .NET, Unity and Windows, e.g. HoloLens).
TIME_FACTOR_NS = {'s': 10 ** 9, 'ms': 10 ** 6, 'us': 10 ** 3, '100ns': 100, 'ns': 1}
TIME_UNITS = tuple(TIME_FACTOR_NS)
TIME_UNIT_WORDS = {'s': 's', 'ms': 'ms', 'us': 'us', '100ns': '100 ns ticks', 'ns': 'ns'}

#: Last words of a time column's name that say its unit (``t_s``, ``time_ms``, ``stamp_us``,
#: ``timestamp_ns``, ``ticks``).
_NAME_UNITS = {**dict.fromkeys(('s', 'sec', 'secs', 'second', 'seconds'), 's'),
               **dict.fromkeys(('ms', 'msec', 'millis', 'milliseconds'), 'ms'),
               **dict.fromkeys(('us', 'usec', 'micros', 'microseconds'), 'us'),
               **dict.fromkeys(('ticks', '100ns'), '100ns'),
               **dict.fromkeys(('ns', 'nsec', 'nanos', 'nanoseconds'), 'ns')}

#: Epochs of absolute stamps: (name, the units counted from it, seconds from it to 1970-01-01).
TIME_EPOCHS = (('1970-01-01', TIME_UNITS, 0),
               ('0001-01-01 (.NET / Unity DateTime ticks)', ('100ns',), 62_135_596_800),
               ('1601-01-01 (Windows FILETIME)', ('100ns',), 11_644_473_600))
#: An absolute stamp is recognised as a date in 2000 .. 2099 (Unix seconds); in these years the
#: unit / epoch pairs of :data:`TIME_EPOCHS` give disjoint ranges of numbers.
DATE_RANGE_S = (946_684_800, 4_102_444_800)
#: The rates of head trackers and headsets [Hz], preferred when the median step of a table's
#: times fits several units.
TRACKER_RATE_HZ = (20.0, 2_000.0)

_TIME_FLAGS = 'give --time-unit (s, ms, us, 100ns, ns) or --time-scale SECONDS_PER_TICK'

#: Column names pose tables of trackers and headsets use (lower case), tried in this order when
#: a table does not name its columns as asked: time, position (x y z), quaternion (x y z w).
TIME_NAMES = ('t_s', 't', 'time', 'timestamp', 'stamp', 'time_s', 'seconds', 'sec', 'ts')
POSITION_NAMES = (('px', 'py', 'pz'), ('x', 'y', 'z'), ('pos_x', 'pos_y', 'pos_z'),
                  ('position_x', 'position_y', 'position_z'), ('tx', 'ty', 'tz'),
                  ('pos.x', 'pos.y', 'pos.z'), ('position.x', 'position.y', 'position.z'))
QUATERNION_NAMES = (('qx', 'qy', 'qz', 'qw'), ('quat_x', 'quat_y', 'quat_z', 'quat_w'),
                    ('rot_x', 'rot_y', 'rot_z', 'rot_w'),
                    ('orientation_x', 'orientation_y', 'orientation_z', 'orientation_w'),
                    ('ox', 'oy', 'oz', 'ow'), ('q.x', 'q.y', 'q.z', 'q.w'),
                    ('orientation.x', 'orientation.y', 'orientation.z', 'orientation.w'))
#: The largest stamp a ROS time can hold [ns].
MAX_STAMP_NS = 2 ** 63 - 1


def recognise_columns(path: str, delimiter=None):
    """The columns of a pose table by their names, without flags: ``(time, quaternion (x, y, z,
    w) names, position names or None)``, matched case-insensitively against
    :data:`TIME_NAMES`, :data:`QUATERNION_NAMES` and :data:`POSITION_NAMES` (the table's own
    spelling is returned).  Raises HeadMotionError naming the columns it found when a time or
    quaternion column is missing."""
    if not os.path.isfile(path):
        raise HeadMotionError(f'pose table not found: {path}')
    with open(path, 'r', encoding='utf-8', errors='replace') as fh:
        header = next((ln for ln in fh if ln.strip() and not ln.lstrip().startswith('#')), '')
    delim = delimiter if delimiter is not None else (',' if ',' in header else None)
    names = [n.strip() for n in (header.split(delim) if delim else header.split())]
    lower = {n.lower(): n for n in names}
    time = next((lower[t] for t in TIME_NAMES if t in lower), None)
    quat = next((tuple(lower[c] for c in cs) for cs in QUATERNION_NAMES
                 if all(c in lower for c in cs)), None)
    if quat is None and all(c in lower for c in ('w', 'x', 'y', 'z')) and \
            not any(all(c in lower for c in cs) for cs in POSITION_NAMES if cs != ('x', 'y', 'z')):
        quat = tuple(lower[c] for c in ('x', 'y', 'z', 'w'))   # an orientation-only w x y z
    pos = next((tuple(lower[c] for c in cs) for cs in POSITION_NAMES
                if all(c in lower for c in cs) and not (quat and set(cs) & set(quat))), None)
    if time is None or quat is None:
        missing = ' and no '.join(w for w, v in (('time', time), ('quaternion', quat))
                                  if v is None)
        raise HeadMotionError(f'{path}: no {missing} columns recognised among {names} (name '
                              'them with --time-column / --quat-columns)')
    return time, quat, pos


def _median_step(stamps) -> decimal.Decimal:
    """Median of the positive steps between consecutive stamps (0 when there is none)."""
    steps = sorted(b - a for a, b in zip(stamps, stamps[1:]) if b > a)
    return steps[len(steps) // 2] if steps else decimal.Decimal(0)


def _date_epoch(first: decimal.Decimal, unit: str):
    """(epoch name, seconds from it to 1970) of the epoch that makes ``first`` in ``unit`` a date
    in :data:`DATE_RANGE_S`, or None."""
    seconds = first * TIME_FACTOR_NS[unit] / 10 ** 9
    for name, units, offset in TIME_EPOCHS:
        if unit in units and DATE_RANGE_S[0] <= seconds - offset < DATE_RANGE_S[1]:
            return name, offset
    return None


def recognise_time_unit(column: str, stamps, where: str = ''):
    """The unit of a time column when no option names it: ``(unit, seconds from its epoch to
    1970-01-01, words)``; ``stamps`` are the column's finite values (``decimal.Decimal``) in
    file order.

    In this order: the last word of the column's name (``t_s``, ``time_ms``, ``stamp_us``,
    ``timestamp_ns``, ``ticks`` for 100 ns); else the first stamp read as a date of 2000-2099
    (:data:`DATE_RANGE_S`): seconds, ms, us, 100 ns or ns since 1970-01-01, or 100 ns ticks
    since 0001-01-01 (.NET / Unity ``DateTime.Ticks``) or since 1601-01-01 (Windows FILETIME),
    which in those years are disjoint ranges of numbers; else the median step: seconds if that
    gives a rate of 1 Hz to 10 kHz, else the first of ms, us, 100 ns, ns that gives a
    tracker's rate (:data:`TRACKER_RATE_HZ`), else the first that gives 1 Hz to 10 kHz.
    The choice must give a plausible stream
    (:func:`~hair_tracking.motion.head_motion.timing_problem`); otherwise UnitsError says
    which options name the unit.  An epoch other than 1970 makes the times absolute (Unix)
    times; the durations never depend on it.
    """
    step = _median_step(stamps)
    first = stamps[0] if stamps else decimal.Decimal(0)
    unit = _NAME_UNITS.get(column.lower().replace('.', '_').replace(' ', '_').split('_')[-1])
    how = f'from the name {column!r}' if unit else ''
    if unit is None:
        unit = next((u for u in TIME_UNITS if _date_epoch(first, u)), None)
        how = 'the first stamp is a date' if unit else ''

    def rate(u):
        return 1e9 / float(step * TIME_FACTOR_NS[u]) if step > 0 else 0.0

    if unit is None and step > 0:
        lo, hi = PLAUSIBLE_RATE_HZ
        rest = [u for u in TIME_UNITS if u != 's']
        unit = ('s' if lo <= rate('s') <= hi else
                next((u for u in rest if TRACKER_RATE_HZ[0] <= rate(u) <= TRACKER_RATE_HZ[1]),
                     None) or next((u for u in rest if lo <= rate(u) <= hi), None))
        how = f'from the median step {float(step):.6g}'
        if unit is None:
            raise UnitsError(f'{where}time column {column!r}: a median step of {float(step):.6g} '
                             'is no head-pose rate in any unit ('
                             + ', '.join(f'{TIME_UNIT_WORDS[u]}: {rate(u):.3g} Hz'
                                         for u in TIME_UNITS) + f'); {_TIME_FLAGS}')
    if unit is None:
        unit, how = 's', 'one sample'
    span = float((stamps[-1] - stamps[0]) * TIME_FACTOR_NS[unit]) * 1e-9 if stamps else 0.0
    problem = timing_problem(rate(unit), span)
    if problem:
        raise UnitsError(f'{where}time column {column!r} read in {TIME_UNIT_WORDS[unit]} ({how}) '
                         f'gives {problem}; {_TIME_FLAGS}')
    words = TIME_UNIT_WORDS[unit]
    epoch = _date_epoch(first, unit)
    offset = epoch[1] if epoch else 0
    if epoch:
        date = datetime.datetime.fromtimestamp(
            float(first * TIME_FACTOR_NS[unit] / 10 ** 9 - offset), datetime.timezone.utc)
        words += f' since {epoch[0]}'
        how += f', {date:%Y-%m-%d %H:%M:%S} UTC' if how.startswith('the first') else ''
    return unit, offset, (f'{words} (auto: {how}' + (f'; median rate {rate(unit):.4g} Hz)'
                                                     if step > 0 else ')'))


def read_pose_table(path: str, time_column: str = 't_s', time_unit: str = 's',
                    quat_columns=('qx', 'qy', 'qz', 'qw'), quat_order: str = 'xyzw',
                    position_columns=('px', 'py', 'pz'), neck_offset=None, pivot=None,
                    delimiter=None, source: str = '', time_scale=None) -> HeadMotion:
    """Read a pose table: CSV or whitespace-separated text whose first non-comment line names
    the columns.  Blank lines and lines starting with ``#`` are skipped.

    ``time_column`` in ``time_unit`` ('s', 'ms', 'us', '100ns', 'ns', or 'auto': recognised by
    :func:`recognise_time_unit`), or in ticks of ``time_scale`` seconds (e.g. ``'1e-7'`` for
    100 ns ticks; a string is taken exactly), any epoch: times are parsed exactly (no float
    rounding) and the first row's stamp is subtracted before scaling; the times are absolute
    when the first stamp fits a ROS time (int64 ns), else relative to it;
    ``quat_columns`` four column names holding the quaternion components in ``quat_order``
    ('xyzw' or 'wxyz'); ``position_columns`` three column names [m], or None for an
    orientation-only table: then the head origin is ``pivot + R @ neck_offset`` (a head turning
    about a fixed neck pivot; ``neck_offset`` (3,) head frame [m], default zeros; ``pivot`` (3,)
    world [m], default origin).  ``delimiter`` None = ',' if the header contains one, else
    whitespace.

    Rows with a NaN/Inf/zero quaternion, a NaN/Inf position or a time that is NaN or not after
    the previous kept row are kept out and counted in ``HeadMotion.dropped``; quaternions are
    normalised and made sign-continuous.  Missing file/column, a bad header, a row with the
    wrong number of fields or a non-numeric field raise HeadMotionError naming the line.
    """
    if time_unit not in TIME_FACTOR_NS and time_unit != 'auto':
        raise HeadMotionError(f"time_unit must be one of {list(TIME_UNITS)} or 'auto', "
                              f'got {time_unit!r}')
    if time_scale is not None:
        try:
            scale = decimal.Decimal(str(time_scale))
        except decimal.InvalidOperation:
            scale = None
        if scale is None or not scale.is_finite() or scale <= 0:
            raise HeadMotionError(f'time_scale must be a positive number of seconds per tick, '
                                  f'got {time_scale!r}')
        ns_per_tick = scale * 10 ** 9
    elif time_unit != 'auto':
        ns_per_tick = decimal.Decimal(TIME_FACTOR_NS[time_unit])
    if quat_order not in ('xyzw', 'wxyz'):
        raise HeadMotionError(f"quat_order must be 'xyzw' or 'wxyz', got {quat_order!r}")
    if len(quat_columns) != 4:
        raise HeadMotionError(f'quat_columns needs 4 names, got {list(quat_columns)}')
    if position_columns is not None and len(position_columns) != 3:
        raise HeadMotionError(f'position_columns needs 3 names, got {list(position_columns)}')
    if not os.path.isfile(path):
        raise HeadMotionError(f'pose table not found: {path}')
    with open(path, 'r', encoding='utf-8', errors='replace') as fh:
        lines = fh.read().splitlines()

    body = [(k + 1, ln) for k, ln in enumerate(lines)
            if ln.strip() and not ln.lstrip().startswith('#')]
    if not body:
        raise HeadMotionError(f'{path}: empty pose table (no header line)')
    hline, header = body[0]
    delim = delimiter if delimiter is not None else (',' if ',' in header else None)

    def split(s):
        return [c.strip() for c in s.split(delim)] if delim is not None else s.split()

    names = split(header)
    for nm in names:
        try:
            float(nm)
        except ValueError:
            continue
        raise HeadMotionError(f'{path}:{hline}: bad header: expected column names, got '
                              f'{header.strip()!r}')
    if len(set(names)) != len(names) or any(not nm for nm in names):
        raise HeadMotionError(f'{path}:{hline}: bad header: empty or repeated column names in '
                              f'{header.strip()!r}')
    wanted = [time_column, *quat_columns] + list(position_columns or ())
    missing = [nm for nm in wanted if nm not in names]
    if missing:
        raise HeadMotionError(f'{path}:{hline}: missing column(s) {missing}; the header has '
                              f'{names}')
    col = {nm: names.index(nm) for nm in names}

    rows, row_lines = [], []
    for ln_no, ln in body[1:]:
        parts = split(ln)
        if len(parts) != len(names):
            raise HeadMotionError(f'{path}:{ln_no}: {len(parts)} fields, the header names '
                                  f'{len(names)}')
        rows.append(parts)
        row_lines.append(ln_no)
    if not rows:
        raise HeadMotionError(f'{path}: pose table has a header but no rows')
    num_cols = [col[nm] for nm in quat_columns] + [col[nm] for nm in position_columns or ()]
    try:
        vals = np.array([[r[c] for c in num_cols] for r in rows], dtype=np.float64)
    except ValueError:
        for r, ln_no in zip(rows, row_lines):
            for c in num_cols:
                try:
                    float(r[c])
                except ValueError:
                    raise HeadMotionError(f'{path}:{ln_no}: column {names[c]!r} value '
                                          f'{r[c]!r} is not a number') from None
        raise
    t_ns = np.zeros(len(rows), dtype=np.int64)
    t_ok = np.ones(len(rows), dtype=bool)
    tc = col[time_column]
    stamps = []
    for i, (r, ln_no) in enumerate(zip(rows, row_lines)):
        try:
            d = decimal.Decimal(r[tc])
        except decimal.InvalidOperation:
            raise HeadMotionError(f'{path}:{ln_no}: time {r[tc]!r} is not a number') from None
        stamps.append(d if d.is_finite() else None)
        t_ok[i] = d.is_finite()
    first = next((d for d in stamps if d is not None), decimal.Decimal(0))
    epoch_ns, units = 0, ''
    if time_scale is None and time_unit == 'auto':
        time_unit, epoch_s, units = recognise_time_unit(
            time_column, [d for d in stamps if d is not None], f'{path}: ')
        ns_per_tick = decimal.Decimal(TIME_FACTOR_NS[time_unit])
        epoch_ns = epoch_s * 10 ** 9
    origin = int((first * ns_per_tick).to_integral_value(rounding=decimal.ROUND_HALF_EVEN))
    origin -= epoch_ns
    absolute = 0 <= origin <= MAX_STAMP_NS // 2
    for i, d in enumerate(stamps):
        if d is None:
            continue
        rel = int(((d - first) * ns_per_tick).to_integral_value(
            rounding=decimal.ROUND_HALF_EVEN))
        v = rel + (origin if absolute else 0)
        if not -MAX_STAMP_NS <= v <= MAX_STAMP_NS:
            raise HeadMotionError(f'{path}:{row_lines[i]}: time {d} is {rel / 1e9:.3g} s from '
                                  'the first row: more than a ROS time can hold (a wrong '
                                  '--time-unit / --time-scale?)')
        t_ns[i] = v

    q = vals[:, :4] if quat_order == 'xyzw' else vals[:, [1, 2, 3, 0]]
    norm = np.linalg.norm(q, axis=1)
    q_ok = np.isfinite(norm) & (norm > 1e-9)
    p_ok = np.ones(len(rows), dtype=bool)
    if position_columns is not None:
        p_ok = np.all(np.isfinite(vals[:, 4:7]), axis=1)
    keep = q_ok & p_ok & t_ok
    # time must increase over kept rows
    last = None
    for i in np.nonzero(keep)[0]:
        if last is not None and t_ns[i] <= last:
            keep[i] = False
            t_ok[i] = False
        else:
            last = t_ns[i]
    dropped = {'bad_quaternion': int(np.sum(~q_ok)),
               'bad_position': int(np.sum(q_ok & ~p_ok)),
               'bad_time': int(np.sum(q_ok & p_ok & ~t_ok))}
    if not np.any(keep):
        raise HeadMotionError(f'{path}: no usable rows (dropped: {dropped})')
    qk = make_sign_continuous(q[keep] / norm[keep, None])
    if position_columns is not None:
        pos = vals[keep, 4:7]
    else:
        off = np.zeros(3) if neck_offset is None else np.asarray(neck_offset, float).reshape(3)
        piv = np.zeros(3) if pivot is None else np.asarray(pivot, float).reshape(3)
        pos = piv + quat_to_matrix(qk) @ off
    unit = f'{time_scale} s ticks' if time_scale is not None else units or time_unit
    desc = source or (f'{path} (pose table, time {time_column!r} [{unit}]'
                      + ('' if absolute else ', relative to the first row') + ')')
    return HeadMotion(t_ns[keep], pos, qk, source=desc, dropped=dropped, units=units)


def read_vr360(path: str, neck_offset=None, pivot=None) -> HeadMotion:
    """Head-mounted-display trace of Corbillon et al. (MMSys 2017/2018): header
    ``timestamp viewpoint w x y z``, time in seconds, orientation only.

    Positions are ``pivot + R @ neck_offset`` (zeros by default; see :func:`read_pose_table`).
    The quaternion is taken as given (world z up, head z up: see the module doc); following
    Corbillon et al. (2017), "360-Degree Video Head Movement Dataset", the rotation turns the
    reference viewing direction (1, 0, 0) into the viewing direction, i.e. head x is forward as
    in REP-103.  The ``viewpoint`` column (which video viewpoint was shown) is ignored.
    """
    return read_pose_table(path, time_column='timestamp', time_unit='s',
                           quat_columns=('w', 'x', 'y', 'z'), quat_order='wxyz',
                           position_columns=None, neck_offset=neck_offset, pivot=pivot,
                           source=f'{path} (VR360 HMD trace, orientation only)')


def write_pose_csv(path: str, motion: HeadMotion, comments=()) -> None:
    """Write ``t_s,px,py,pz,qx,qy,qz,qw`` rows (time in s to 1 us, 7 significant digits for
    positions [m] and quaternions); ``comments`` are written first as ``# `` lines.
    Times are absolute (``t_ns / 1e9``)."""
    with open(path, 'w', encoding='utf-8', newline='\n') as fh:
        for c in comments:
            for ln in str(c).splitlines() or ['']:
                fh.write(('# ' + ln).rstrip() + '\n')
        fh.write(','.join(POSE_CSV_COLUMNS) + '\n')
        for t, p, q in zip(motion.t_ns, motion.position, motion.quaternion):
            sec, ns = divmod(int(t), 10 ** 9)
            us = int(round(ns / 1000.0))
            if us == 10 ** 6:
                sec, us = sec + 1, 0
            ts = f'{sec}.{us:06d}' if sec >= 0 else f'{t * 1e-9:.6f}'
            fh.write(ts + ',' + ','.join(f'{v:.7g}' for v in (*p, *q)) + '\n')


def read_pose_csv(path: str) -> HeadMotion:
    """Read a file written by :func:`write_pose_csv`."""
    return read_pose_table(path, time_column='t_s', time_unit='s',
                           quat_columns=('qx', 'qy', 'qz', 'qw'), quat_order='xyzw',
                           position_columns=('px', 'py', 'pz'), delimiter=',',
                           source=f'{path} (pose CSV)')


def load_bundled_walk() -> HeadMotion:
    """CMU 131_01 "start, walk, stop" head poses shipped with the package (994 frames, 120 Hz,
    8.3 s; head centre, metres, REP-103 frames; made by scripts/make_head_motion_data.py).
    Attribution: ``data/ATTRIBUTION.md``."""
    if not os.path.isfile(BUNDLED_WALK_CSV):
        raise HeadMotionError(f'bundled walk data missing: {BUNDLED_WALK_CSV} '
                              '(regenerate with scripts/make_head_motion_data.py)')
    m = read_pose_csv(BUNDLED_WALK_CSV)
    m.source = (f'{BUNDLED_WALK_CSV} (CMU mocap 131_01 walk, head centre, '
                'via yuki-koyama/bvh11; see data/ATTRIBUTION.md)')
    return m
