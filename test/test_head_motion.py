"""Recorded head motion: BVH forward kinematics, pose tables, the bundled walk clip.

The recordings are excerpts in test/data (test/recordings.py): frames 360-719 of the CMU 131_01
walk BVH (3.0-6.0 s: the head snap, then the walk) without the right leg and arm, and 12 s of
the VR360 headset trace.  Reference statistics of the whole walk come from the README of the
recordings (measured independently of this code) and are checked on the bundled CSV, which the
excerpt must equal frame by frame.
"""
import os

import numpy as np
import pytest

from hair_tracking.core.transforms import (matrices_to_quats, matrix_to_quat, quat_angle,
                                           quat_from_axis_angle, quat_to_matrix)
from hair_tracking.motion import bvh as mocap, head_motion as hm, pose_table as tables

from recordings import VR_START_S, VR_TRACE as VR_TXT, WALK_BVH, WALK_FIRST_FRAME

# README of the recordings: head angular speed of the whole walk, deg/s (median, p95, p99, max)
WALK_STATS = (27.7, 207.8, 321.2, 379.2)
WALK_FRAMES = 360                                    # in the excerpt
WALK_START_S = WALK_FIRST_FRAME / 120.0              # where the excerpt starts in the recording


def _stats_deg(motion):
    w = np.degrees(hm.angular_speed(motion))
    return (np.median(w), np.percentile(w, 95), np.percentile(w, 99), w.max())


def _assert_stats(motion, ref, rel=0.03):
    got = _stats_deg(motion)
    for name, g, r in zip(('median', 'p95', 'p99', 'max'), got, ref):
        assert abs(g - r) <= rel * r, f'{name} angular speed {g:.2f} deg/s, README says {r}'


@pytest.fixture(scope='module')
def walk_bvh():
    return mocap.read_bvh(WALK_BVH)


@pytest.fixture(scope='module')
def walk():
    return mocap.load_bvh_head_motion(WALK_BVH)


@pytest.fixture(scope='module')
def vr():
    return tables.read_vr360(VR_TXT)


def _bvh_lines():
    with open(WALK_BVH, encoding='utf-8') as f:
        lines = f.read().splitlines()
    return lines, lines.index('MOTION')


# ------------------------------------------------------------------ BVH: the CMU walk
def test_walk_frames_and_rate(walk_bvh, walk):
    assert walk_bvh.frame_count == WALK_FRAMES and len(walk) == WALK_FRAMES
    assert walk_bvh.motion.shape == (WALK_FRAMES, 60)            # 20 joints with channels
    assert abs(walk.rate_hz - 120.0) < 0.01
    assert abs(walk.duration_s - (WALK_FRAMES - 1) / 120.0) < 1e-4
    assert walk.t_ns[0] == 0 and walk.t_ns.dtype == np.int64
    # per-joint channel orders as written: root 6 channels, arms ZXY, spine ZYX
    by = {j.name: j for j in walk_bvh.joints}
    assert by['Hips'].channels == ('Xposition', 'Yposition', 'Zposition',
                                   'Zrotation', 'Yrotation', 'Xrotation')
    assert by['LeftElbow'].channels == ('Zrotation', 'Xrotation', 'Yrotation')
    assert by['Head'].channels == ('Zrotation', 'Yrotation', 'Xrotation')
    assert [walk_bvh.joints[i].name for i in walk_bvh.chain('Head')] == [
        'Hips', 'lowerback', 'Chest', 'Chest2', 'lowerneck', 'Neck', 'Head']


def test_walk_quaternions_unit_and_continuous(walk):
    assert np.allclose(np.linalg.norm(walk.quaternion, axis=1), 1.0, atol=1e-12)
    assert np.all(np.sum(walk.quaternion[1:] * walk.quaternion[:-1], axis=1) >= 0.0)


def test_walk_head_height_plausible(walk_bvh, walk):
    allp = walk_bvh.all_positions() @ mocap.BVH_TO_WORLD.T * mocap.CMU_SCALE_M
    floor = allp[..., 2].min()                       # lowest point of the body (left toes)
    _, walking = hm.walking_direction(walk.position, walk.t_ns)
    centre = np.median(walk.position[walking, 2]) - floor
    top = allp[:, walk_bvh.index('Head_End'), 2].max() - floor
    assert 1.3 <= centre <= 1.9, f'head-centre height while walking {centre:.3f} m'
    assert 1.4 <= top <= 1.9, f'head-top height {top:.3f} m'
    # the head centre lies above the Head joint along head z, by half the head bone
    joint = mocap.load_bvh_head_motion(WALK_BVH, origin='joint')
    up = walk.rotation()[:, :, 2]
    d = walk.position - joint.position
    assert np.allclose(d, up * np.linalg.norm(d, axis=1, keepdims=True), atol=1e-3)
    assert np.allclose(np.linalg.norm(d, axis=1), 0.5 * 1.63304 * mocap.CMU_SCALE_M, atol=1e-3)


def test_walk_moves_forward_a_few_metres(walk):
    _, walking = hm.walking_direction(walk.position, walk.t_ns)
    first, last = np.flatnonzero(walking)[[0, -1]]
    disp = walk.position[last] - walk.position[first]
    assert 1.5 < np.linalg.norm(disp[:2]) < 4.0      # about 2 s of walking
    assert abs(disp[2]) < 0.2
    fwd0 = walk.rotation()[first][:, 0]              # facing as the walk starts
    assert np.dot(disp[:2], fwd0[:2]) > 1.5          # walked forward, not backward


def test_walk_head_axes_follow_walking_and_up(walk):
    direction, walking = hm.walking_direction(walk.position, walk.t_ns)
    assert walking.sum() > 120                       # more than a second of walking
    r = walk.rotation()
    x = r[walking, :2, 0]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    cos_fwd = np.mean(np.sum(x * direction[walking], axis=1))
    assert cos_fwd > 0.9, f'head x vs walking direction: mean cos {cos_fwd:.3f}'
    assert np.mean(r[:, 2, 2]) > 0.85                # head z up, bent down at the start
    assert np.mean(r[walking, 2, 2]) > 0.95
    assert np.all(np.abs(np.linalg.det(r) - 1.0) < 1e-9)


def test_head_axes_inferred_from_data_match_constant(walk_bvh):
    axes = mocap.infer_head_axes(walk_bvh)
    assert np.array_equal(axes, mocap.CMU_HEAD_AXES)
    # a wrong mapping makes the walking check fail (the check can fail)
    wrong = mocap.load_bvh_head_motion(WALK_BVH, head_axes=np.eye(3))
    direction, walking = hm.walking_direction(wrong.position, wrong.t_ns)
    x = wrong.rotation()[walking, :2, 0]
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    assert np.mean(np.sum(x * direction[walking], axis=1)) < 0.5


def test_walk_head_snap_matches_readme(walk):
    w = np.degrees(hm.angular_speed(walk))
    assert abs(w.max() - WALK_STATS[3]) <= 0.03 * WALK_STATS[3]          # the clip's maximum
    assert abs(WALK_START_S + (np.argmax(w) + 0.5) / 120.0 - 3.3) < 0.1  # near t = 3.3 s


def _reference_fk(bvh, frame):
    """Plain per-frame FK with 4x4 matrices and axis-angle quaternions (independent path)."""
    world = {}
    out = np.empty((len(bvh.joints), 3))
    for i, j in enumerate(bvh.joints):
        local = np.eye(4)
        local[:3, 3] = j.offset
        rot = np.eye(3)
        for k, ch in enumerate(j.channels):
            v = bvh.motion[frame, j.first_channel + k]
            axis = {'X': [1, 0, 0], 'Y': [0, 1, 0], 'Z': [0, 0, 1]}[ch[0]]
            if ch.endswith('position'):
                local[:3, 3] += v * np.array(axis)
            else:
                q = quat_from_axis_angle(axis, np.radians(v))
                x, y, z, w = q
                m = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                              [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                              [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
                rot = rot @ m
        local[:3, :3] = rot
        world[i] = local if j.parent < 0 else world[j.parent] @ local
        out[i] = world[i][:3, 3]
    return out, world


def test_fk_matches_reference_for_all_joints(walk_bvh):
    allp = walk_bvh.all_positions()
    _, head_rot = walk_bvh.forward_kinematics('Head')
    hi = walk_bvh.index('Head')
    for frame in (0, 39, WALK_FRAMES - 1):
        ref, world = _reference_fk(walk_bvh, frame)
        assert np.allclose(allp[frame], ref, atol=1e-9)     # incl. the ZXY-ordered arm joints
        assert np.allclose(head_rot[frame], world[hi][:3, :3], atol=1e-12)
    # swapping an arm joint's channel order moves the wrist: the order is really used
    pos, _ = walk_bvh.forward_kinematics('LeftWrist')
    j = walk_bvh.joints[walk_bvh.index('LeftShoulder')]
    saved = j.channels
    try:
        j.channels = ('Zrotation', 'Yrotation', 'Xrotation')
        swapped, _ = walk_bvh.forward_kinematics('LeftWrist')
    finally:
        j.channels = saved
    assert np.max(np.linalg.norm(swapped - pos, axis=1)) > 0.1


def test_excerpt_keeps_the_values_of_the_joints_it_keeps(tmp_path, walk_bvh):
    """scripts/make_head_motion_data.py's cut, applied to the excerpt itself: frames and joints
    go, the values of what stays are the same numbers."""
    from make_head_motion_data import bvh_excerpt
    path = _write(tmp_path / 'part.bvh', bvh_excerpt(WALK_BVH, (10, 30), ('LeftCollar',)))
    part = mocap.read_bvh(path)
    kept = [j.name for j in walk_bvh.joints
            if walk_bvh.index('LeftCollar') not in walk_bvh.chain(j.name)]
    assert part.joint_names == kept and 'LeftWrist' not in kept
    cols = [c for j in walk_bvh.joints if j.name in kept
            for c in range(j.first_channel, j.first_channel + len(j.channels))]
    assert np.array_equal(part.motion, walk_bvh.motion[10:30, cols])
    assert part.frame_time == walk_bvh.frame_time
    head, _ = part.forward_kinematics('Head')
    assert np.array_equal(head, walk_bvh.forward_kinematics('Head')[0][10:30])


# ------------------------------------------------------------------ bundled data
def test_bundled_walk_loads_without_raw_data():
    m = tables.load_bundled_walk()
    assert len(m) == 994 and abs(m.rate_hz - 120.0) < 0.01
    assert np.all(np.sum(m.quaternion[1:] * m.quaternion[:-1], axis=1) >= 0.0)
    assert 'CMU' in m.source
    pose = m.pose(500)
    assert np.allclose(pose.to_world(np.array([[0.1, 0.0, 0.0]]))[0],
                       m.position[500] + 0.1 * m.rotation()[500][:, 0])
    _assert_stats(m, WALK_STATS)
    assert os.path.isfile(os.path.join(tables.DATA_DIR, 'ATTRIBUTION.md'))
    assert os.path.isfile(os.path.join(tables.DATA_DIR, 'LICENSE_cmu_bvh11_repo_MIT.txt'))


def test_bundled_csv_equals_bvh_import(walk):
    b = tables.load_bundled_walk()
    rows = slice(WALK_FIRST_FRAME, WALK_FIRST_FRAME + WALK_FRAMES)
    t = b.t_ns[rows] - b.t_ns[WALK_FIRST_FRAME]
    assert np.max(np.abs(t - walk.t_ns)) <= 1000                 # both written to 1 us
    assert np.allclose(b.position[rows], walk.position, rtol=0, atol=5e-6)
    assert np.allclose(b.quaternion[rows], walk.quaternion, rtol=0, atol=1e-6)


def test_every_recording_in_test_data_is_attributed():
    from recordings import FIXTURES
    with open(os.path.join(FIXTURES, 'ATTRIBUTION.md'), encoding='utf-8') as f:
        text = f.read()
    names = sorted(os.listdir(FIXTURES))
    assert {'LICENSE_cmu_bvh11_repo_MIT.txt', 'LICENSE_vr360_MIT.txt'} <= set(names)
    for name in names:
        if name != 'ATTRIBUTION.md':
            assert f'`{name}`' in text or f'({name})' in text, f'{name}: not in ATTRIBUTION.md'


# ------------------------------------------------------------------ VR trace
def _vr_rows():
    return np.loadtxt(VR_TXT, skiprows=1)


def test_vr_trace_imports(vr):
    raw = _vr_rows()
    assert len(vr) == len(raw) > 600 and sum(vr.dropped.values()) == 0
    assert VR_START_S <= raw[0, 0] < VR_START_S + 0.1
    assert abs(vr.duration_s - (raw[-1, 0] - raw[0, 0])) < 1e-6
    assert 58.0 < vr.rate_hz < 60.0
    assert np.all(vr.position == 0.0)
    assert np.allclose(np.linalg.norm(vr.quaternion, axis=1), 1.0, atol=1e-12)
    # angular speed: the angle between consecutive rows over their time step
    q = raw[:, 2:6] / np.linalg.norm(raw[:, 2:6], axis=1, keepdims=True)
    angle = 2.0 * np.arccos(np.minimum(np.abs(np.sum(q[1:] * q[:-1], axis=1)), 1.0))
    assert np.allclose(hm.angular_speed(vr), angle / np.diff(raw[:, 0]), rtol=1e-6, atol=1e-5)
    # head z mostly up: the trace needs no axis remapping
    assert np.mean(vr.rotation()[:, 2, 2]) > 0.9


def test_vr_sign_flips_removed(vr):
    raw = _vr_rows()[:, [3, 4, 5, 2]]
    assert np.sum(np.sum(raw[1:] * raw[:-1], axis=1) < 0) > 0   # the file does flip
    assert np.all(np.sum(vr.quaternion[1:] * vr.quaternion[:-1], axis=1) >= 0.0)
    assert np.allclose(np.abs(np.sum(vr.quaternion * raw, axis=1)), 1.0, atol=1e-9)


def test_vr_neck_offset(vr):
    off = np.array([0.02, 0.0, 0.1])
    m = tables.read_vr360(VR_TXT, neck_offset=off, pivot=[0.0, 0.0, 1.5])
    expect = np.array([0.0, 0.0, 1.5]) + vr.rotation() @ off
    assert np.allclose(m.position, expect, atol=1e-12)
    assert np.allclose(np.linalg.norm(m.position - [0, 0, 1.5], axis=1), np.linalg.norm(off))


# ------------------------------------------------------------------ pose tables
def _write(path, text):
    path.write_text(text)
    return str(path)


def test_pose_table_drops_bad_rows_and_fixes_signs(tmp_path):
    q1 = quat_from_axis_angle([0, 0, 1], 0.1)
    q2 = -quat_from_axis_angle([0, 0, 1], 0.2)                 # sign flipped
    rows = ['time_ms,X,Y,Z,QW,QX,QY,QZ',
            f'0,1,2,3,{q1[3]},{q1[0]},{q1[1]},{q1[2]}',
            '# a comment',
            '10,1,2,3,nan,0,0,1',                               # NaN quaternion
            '20,1,2,3,0,0,0,0',                                 # zero quaternion
            '30,nan,2,3,1,0,0,0',                               # NaN position
            f'40,1,2,3,{2 * q2[3]},{2 * q2[0]},{2 * q2[1]},{2 * q2[2]}',   # unnormalised
            '40,1,2,3,1,0,0,0',                                 # repeated time
            '35,1,2,3,1,0,0,0',                                 # time going back
            'nan,1,2,3,1,0,0,0',                                # no time
            '50.5,4,5,6,1,0,0,0']
    m = tables.read_pose_table(_write(tmp_path / 'poses.csv', '\n'.join(rows) + '\n'),
                               time_column='time_ms', time_unit='ms',
                               quat_columns=('QW', 'QX', 'QY', 'QZ'), quat_order='wxyz',
                               position_columns=('X', 'Y', 'Z'))
    assert list(m.t_ns) == [0, 40_000_000, 50_500_000]
    assert m.dropped == {'bad_quaternion': 2, 'bad_position': 1, 'bad_time': 3}
    assert np.allclose(m.position, [[1, 2, 3], [1, 2, 3], [4, 5, 6]])
    assert np.allclose(np.linalg.norm(m.quaternion, axis=1), 1.0)
    assert np.all(np.sum(m.quaternion[1:] * m.quaternion[:-1], axis=1) >= 0.0)
    assert quat_angle(m.quaternion[1], q2) < 1e-9
    assert np.allclose(np.degrees(hm.angular_speed(m))[0], np.degrees(0.1) / 0.04)


def test_pose_table_whitespace_xyzw_and_exact_times(tmp_path):
    text = ('stamp qx qy qz qw\n'
            '1700000000123456789 0 0 0 1\n'
            '1700000000123456790 0 0 0.0 -1\n')
    m = tables.read_pose_table(_write(tmp_path / 'p.txt', text), time_column='stamp',
                               time_unit='ns', position_columns=None)
    assert m.t_ns.tolist() == [1700000000123456789, 1700000000123456790]
    assert np.all(m.quaternion[:, 3] > 0)                      # -1 flipped to +1
    s = tables.read_pose_table(_write(tmp_path / 's.txt', 't qx qy qz qw\n1700000000.000000001 '
                                      '0 0 0 1\n'), time_column='t', position_columns=None)
    assert s.t_ns[0] == 1700000000000000001
    u = tables.read_pose_table(_write(tmp_path / 'u.txt', 't qx qy qz qw\n2.5 0 0 0 1\n'),
                               time_column='t', time_unit='us', position_columns=None)
    assert u.t_ns[0] == 2500


def test_pose_csv_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = hm.make_sign_continuous(q)
    t = 1_700_000_000_000_000_000 + np.cumsum(rng.integers(1_000_000, 30_000_000, 50))
    t = (t // 1000) * 1000                                     # the format keeps 1 us
    m = hm.HeadMotion(t, rng.normal(size=(50, 3)), q, source='random')
    path = str(tmp_path / 'rt.csv')
    tables.write_pose_csv(path, m, comments=['made by a test', 'second line'])
    with open(path) as fh:
        assert fh.readline() == '# made by a test\n'
    r = tables.read_pose_csv(path)
    assert np.array_equal(r.t_ns, m.t_ns)
    assert np.allclose(r.position, m.position, rtol=1e-6, atol=1e-7)
    assert np.allclose(r.quaternion, m.quaternion, atol=1e-6)


# ------------------------------------------------------------------ helpers vs references
def test_matrices_to_quats_agrees_with_reference():
    rng = np.random.default_rng(7)
    q = rng.normal(size=(400, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[:4] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]   # each branch
    m = quat_to_matrix(q)
    got = matrices_to_quats(m)
    for g, mm, qq in zip(got, m, q):
        ref = matrix_to_quat(mm)
        assert abs(abs(np.dot(g, ref)) - 1.0) < 1e-12
        assert abs(abs(np.dot(g, qq)) - 1.0) < 1e-12


def test_angular_speed_agrees_with_reference():
    rng = np.random.default_rng(11)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q = hm.make_sign_continuous(q)
    t = np.cumsum(rng.integers(1_000_000, 50_000_000, 200))
    m = hm.HeadMotion(t, np.zeros((200, 3)), q)
    ref = [quat_angle(q[i], q[i + 1]) / ((t[i + 1] - t[i]) * 1e-9) for i in range(199)]
    assert np.allclose(hm.angular_speed(m), ref, rtol=1e-9, atol=1e-9)
    flipped = q.copy()
    flipped[::2] *= -1                                          # sign-insensitive
    assert np.allclose(hm.angular_speed(hm.HeadMotion(t, np.zeros((200, 3)), flipped)), ref,
                       rtol=1e-9, atol=1e-9)


# ------------------------------------------------------------------ errors
def test_truncated_bvh_raises_with_line(tmp_path):
    lines, motion = _bvh_lines()
    rows = motion + 3                                # first frame's line index
    cut_motion = _write(tmp_path / 'cut.bvh', '\n'.join(lines[:rows + 100]) + '\n')
    with pytest.raises(hm.HeadMotionError,
                       match=rf'cut\.bvh:\d+: .*Frames: {WALK_FRAMES}.*truncated'):
        mocap.read_bvh(cut_motion)
    k = rows + 50
    cut_line = _write(tmp_path / 'half.bvh', '\n'.join(lines[:k]) + '\n'
                      + lines[k][:len(lines[k]) // 2] + '\n')
    with pytest.raises(hm.HeadMotionError, match=rf'half\.bvh:{k + 1}: .*values'):
        mocap.read_bvh(cut_line)
    cut_hier = _write(tmp_path / 'hier.bvh', '\n'.join(lines[:motion - 20]) + '\n')
    with pytest.raises(hm.HeadMotionError, match='no MOTION'):
        mocap.read_bvh(cut_hier)
    assert lines[motion - 1] == '}'                  # the root's closing brace
    no_close = _write(tmp_path / 'brace.bvh', '\n'.join(lines[:motion - 1] + lines[motion:]))
    with pytest.raises(hm.HeadMotionError, match='unbalanced'):
        mocap.read_bvh(no_close)


def test_bad_bvh_header_and_channels(tmp_path):
    lines, motion = _bvh_lines()
    bad = _write(tmp_path / 'b.bvh', '\n'.join(['HIERARCY'] + lines[1:]))
    with pytest.raises(hm.HeadMotionError, match=r'b\.bvh:1: .*HIERARCHY'):
        mocap.read_bvh(bad)
    chan = list(lines)
    k = [i for i, ln in enumerate(lines) if 'CHANNELS 3' in ln][0]
    chan[k] = '\t\tCHANNELS 3 Zrotation Yrotation Wrotation'
    with pytest.raises(hm.HeadMotionError, match=rf'c\.bvh:{k + 1}: .*Wrotation'):
        mocap.read_bvh(_write(tmp_path / 'c.bvh', '\n'.join(chan)))
    ft = list(lines)
    assert ft[motion + 2].startswith('Frame Time:')
    ft[motion + 2] = 'Frame Time: fast'
    with pytest.raises(hm.HeadMotionError, match=rf'f\.bvh:{motion + 3}: .*frame time'):
        mocap.read_bvh(_write(tmp_path / 'f.bvh', '\n'.join(ft)))
    num = list(lines)
    k = motion + 3 + 10
    num[k] = 'abc ' + num[k].split(' ', 1)[1]
    with pytest.raises(hm.HeadMotionError, match=rf'n\.bvh:{k + 1}: .*not a number'):
        mocap.read_bvh(_write(tmp_path / 'n.bvh', '\n'.join(num)))


def test_unknown_joint_lists_available(walk_bvh):
    with pytest.raises(hm.HeadMotionError, match=r"no joint named 'Skull'.*Head.*LeftWrist"):
        mocap.load_bvh_head_motion(WALK_BVH, joint='Skull')
    with pytest.raises(hm.HeadMotionError, match='Neck2'):
        walk_bvh.forward_kinematics('Neck2')


def test_missing_files_raise(tmp_path):
    with pytest.raises(hm.HeadMotionError, match='not found'):
        mocap.read_bvh(str(tmp_path / 'none.bvh'))
    with pytest.raises(hm.HeadMotionError, match='not found'):
        tables.read_pose_csv(str(tmp_path / 'none.csv'))


def test_pose_table_errors(tmp_path):
    ok = 't_s,px,py,pz,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n'
    with pytest.raises(hm.HeadMotionError, match=r"m\.csv:1: missing column\(s\) \['qw'\]"):
        tables.read_pose_csv(_write(tmp_path / 'm.csv', ok.replace(',qw', ',w')))
    with pytest.raises(hm.HeadMotionError, match=r'h\.csv:1: bad header'):
        tables.read_pose_csv(_write(tmp_path / 'h.csv', '0,0,0,0,0,0,0,1\n1,0,0,0,0,0,0,1\n'))
    with pytest.raises(hm.HeadMotionError, match=r'r\.csv:3: 7 fields'):
        tables.read_pose_csv(_write(tmp_path / 'r.csv', ok + '1,0,0,0,0,0,1\n'))
    with pytest.raises(hm.HeadMotionError, match=r"v\.csv:2: column 'py' value 'x'"):
        tables.read_pose_csv(_write(tmp_path / 'v.csv', ok.replace('0,0,0,0,0,0,0,1',
                                                                   '0,0,x,0,0,0,0,1')))
    with pytest.raises(hm.HeadMotionError, match=r"t\.csv:2: time 'soon'"):
        tables.read_pose_csv(_write(tmp_path / 't.csv', ok.replace('\n0,', '\nsoon,')))
    with pytest.raises(hm.HeadMotionError, match='no usable rows'):
        tables.read_pose_csv(_write(tmp_path / 'z.csv', ok.replace(',0,0,0,1', ',0,0,0,0')))
    with pytest.raises(hm.HeadMotionError, match='time_unit'):
        tables.read_pose_table(_write(tmp_path / 'o.csv', ok), time_unit='min')
    with pytest.raises(hm.HeadMotionError, match='empty'):
        tables.read_pose_csv(_write(tmp_path / 'e.csv', '# only a comment\n'))


def test_head_motion_validates():
    with pytest.raises(hm.HeadMotionError, match='strictly increasing'):
        hm.HeadMotion(np.array([0, 5, 5]), np.zeros((3, 3)), np.tile([0, 0, 0, 1.0], (3, 1)))
    with pytest.raises(hm.HeadMotionError, match=r'\(2, 3\)'):
        hm.HeadMotion(np.array([0, 5]), np.zeros((3, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))
    with pytest.raises(hm.HeadMotionError, match='unit'):
        hm.HeadMotion(np.array([0, 5]), np.zeros((2, 3)), np.tile([0, 0, 0, 2.0], (2, 1)))
    m = hm.HeadMotion(np.array([0, 5]), np.zeros((2, 3)), np.array([[0, 0, 0, 1.0],
                                                                   [0, 0, 0, -1.0]]))
    assert np.array_equal(m.quaternion[1], [0, 0, 0, 1.0])
    with pytest.raises(hm.HeadMotionError, match='integer'):
        hm.HeadMotion(np.array([0.0, 5.0]), np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))


def test_pose_table_columns_are_recognised_by_their_names(tmp_path):
    text = ('timestamp,x,y,z,quat_w,quat_x,quat_y,quat_z\n'
            '10.0,0.1,0.2,1.6,1,0,0,0\n10.5,0.1,0.2,1.7,1,0,0,0\n')
    path = _write(tmp_path / 'tracker.csv', text)
    assert tables.recognise_columns(str(path)) == (
        'timestamp', ('quat_x', 'quat_y', 'quat_z', 'quat_w'), ('x', 'y', 'z'))
    hmd = _write(tmp_path / 'hmd.txt', 'time w x y z\n0 1 0 0 0\n')
    assert tables.recognise_columns(str(hmd)) == ('time', ('x', 'y', 'z', 'w'), None)
    with pytest.raises(hm.HeadMotionError, match=r"no time and no quaternion columns recognised "
                                                 r"among \['a', 'b'\]"):
        tables.recognise_columns(str(_write(tmp_path / 'bad.csv', 'a,b\n1,2\n')))


def test_headset_ticks_since_year_one_import_with_a_time_scale(tmp_path):
    """A trace stamped in 100 ns ticks since 0001-01-01 (about 6.4e17 ticks, 6.4e19 ns: more
    than int64 ns hold): the first stamp is subtracted exactly before scaling, so the durations
    are right, and the times are relative to the first row."""
    t0 = 638_680_000_000_000_000
    rows = [f'{t0 + k * 111_111},0,0,1.6,0,0,0,1' for k in range(10)]   # 90 Hz
    path = _write(tmp_path / 'ticks.csv', 't,px,py,pz,qx,qy,qz,qw\n' + '\n'.join(rows) + '\n')
    m = tables.read_pose_table(str(path), time_column='t', time_scale='1e-7')
    assert m.t_ns[0] == 0 and m.t_ns[1] == 11_111_100 and m.t_ns[-1] == 9 * 11_111_100
    assert 'relative to the first row' in m.source
    # the same ticks read as microseconds still fit relative to the first row, and absurd
    # spans are refused with a message instead of an overflow
    us = tables.read_pose_table(str(path), time_column='t', time_unit='us')
    assert us.t_ns[1] - us.t_ns[0] == 111_111_000
    far = _write(tmp_path / 'far.csv', 't,px,py,pz,qx,qy,qz,qw\n0,0,0,1,0,0,0,1\n'
                 '1e30,0,0,1,0,0,0,1\n')
    with pytest.raises(hm.HeadMotionError, match='more than a ROS time can hold'):
        tables.read_pose_table(str(far), time_column='t')
    with pytest.raises(hm.HeadMotionError, match='time_scale must be a positive number'):
        tables.read_pose_table(str(path), time_column='t', time_scale='-1')


def test_import_takes_a_table_named_its_own_way(tmp_path, capsys):
    from hair_tracking.bags.cli import main
    t0 = 638_680_000_000_000_000
    rows = [f'{t0 + k * 111_111} 0 0 1.6 0 0 0 1' for k in range(91)]
    path = _write(tmp_path / 'ticks.txt', 'timestamp x y z qx qy qz qw\n' + '\n'.join(rows))
    assert main(['import', str(path), '-o', str(tmp_path / 'o.mcap'), '--time-scale', '1e-7']) == 0
    out = capsys.readouterr().out
    assert "time 'timestamp' [1e-7 s ticks]" in out and 'position x,y,z' in out
    assert '1.000 s' in out                    # 90 intervals of 11.11 ms
    assert main(['import', str(path), '-o', str(tmp_path / 'p.mcap'), '--time-unit', 'us']) == 0
    assert 'Traceback' not in capsys.readouterr().err
