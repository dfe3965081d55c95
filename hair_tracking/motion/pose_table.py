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
import decimal
import os

import numpy as np

from hair_tracking.core.transforms import quat_to_matrix
from hair_tracking.motion.head_motion import HeadMotion, HeadMotionError, make_sign_continuous
from hair_tracking.resources import data_path

DATA_DIR = data_path('')
BUNDLED_WALK_CSV = os.path.join(DATA_DIR, 'cmu_131_01_walk_head.csv')

POSE_CSV_COLUMNS = ('t_s', 'px', 'py', 'pz', 'qx', 'qy', 'qz', 'qw')

_TIME_FACTOR_NS = {'s': 10 ** 9, 'ms': 10 ** 6, 'us': 10 ** 3, 'ns': 1}

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


def read_pose_table(path: str, time_column: str = 't_s', time_unit: str = 's',
                    quat_columns=('qx', 'qy', 'qz', 'qw'), quat_order: str = 'xyzw',
                    position_columns=('px', 'py', 'pz'), neck_offset=None, pivot=None,
                    delimiter=None, source: str = '', time_scale=None) -> HeadMotion:
    """Read a pose table: CSV or whitespace-separated text whose first non-comment line names
    the columns.  Blank lines and lines starting with ``#`` are skipped.

    ``time_column`` in ``time_unit`` ('s', 'ms', 'us', 'ns'), or in ticks of ``time_scale``
    seconds (e.g. ``'1e-7'`` for 100 ns ticks; a string is taken exactly), any epoch: times are
    parsed exactly (no float rounding) and the first row's stamp is subtracted before scaling;
    the times are absolute when the first stamp fits a ROS time (int64 ns), else relative to it;
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
    if time_unit not in _TIME_FACTOR_NS:
        raise HeadMotionError(f'time_unit must be one of {sorted(_TIME_FACTOR_NS)}, '
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
    else:
        ns_per_tick = decimal.Decimal(_TIME_FACTOR_NS[time_unit])
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
    origin = int((first * ns_per_tick).to_integral_value(rounding=decimal.ROUND_HALF_EVEN))
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
    unit = f'{time_scale} s ticks' if time_scale is not None else time_unit
    desc = source or (f'{path} (pose table, time {time_column!r} [{unit}]'
                      + ('' if absolute else ', relative to the first row') + ')')
    return HeadMotion(t_ns[keep], pos, qk, source=desc, dropped=dropped)


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
