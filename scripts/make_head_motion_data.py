#!/usr/bin/env python3
"""Derive the bundled head poses and the test fixtures from the recorded head motion.

Usage: python scripts/make_head_motion_data.py WALK_BVH VR_TRACE [--out CSV] [--fixtures DIR]

WALK_BVH is the CMU Graphics Lab Motion Capture Database's subject 131 trial 01 as converted
to BVH in the MIT-licensed repository yuki-koyama/bvh11 (``resources/131_01.bvh``); VR_TRACE is
``rawNavigationTrace/user1_quaternion.txt`` of the MIT-licensed repository
xmar/MultiViewpoint360_MMSys18.  Sources and licences: hair_tracking/data/ATTRIBUTION.md and
test/data/ATTRIBUTION.md.  Writes

* ``--out`` (hair_tracking/data/cmu_131_01_walk_head.csv): the head poses of all 994 frames,
  read with hair_tracking.motion.bvh.load_bvh_head_motion (Head joint, head-centre origin,
  CMU scale 0.056444 m/unit, REP-103 frames), as ``t_s,px,py,pz,qx,qy,qz,qw`` (7 significant
  digits) with an attribution header;
* ``--fixtures``/cmu_131_01_walk_excerpt.bvh (test/data): frames 360-719 of the BVH (3.0-6.0 s:
  the head snap at 3.3 s and the walk), the hierarchy without the right leg and the right arm,
  the channel values of the joints kept as written;
* ``--fixtures``/vr360_user1_excerpt.txt: the header and the rows stamped 80-92 s (calm viewing,
  then fast turns; the quaternion's sign flips in places) as written.

It prints the head angular speed of both whole recordings (median, p95, p99, max in deg/s) to
compare with what their publishers report.
"""
import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hair_tracking.motion import bvh as mocap, head_motion as hm  # noqa: E402
from hair_tracking.motion import pose_table as tables  # noqa: E402

HEADER = (
    'CMU Graphics Lab Motion Capture Database, http://mocap.cs.cmu.edu/ (subject 131, trial 01,',
    '"start, walk, stop"); BVH conversion from github.com/yuki-koyama/bvh11',
    '(resources/131_01.bvh, MIT licence, Copyright (c) 2018 Yuki Koyama).',
    'See ATTRIBUTION.md next to this file. Derived by scripts/make_head_motion_data.py:',
    'Head joint, origin at the head centre (middle of the Head bone), 0.056444 m per BVH unit,',
    'REP-103 frames (world z up; head x forward, y left, z up), quaternion x y z w.',
)
FIXTURES = os.path.join(ROOT, 'test', 'data')
WALK_EXCERPT = 'cmu_131_01_walk_excerpt.bvh'
VR_EXCERPT = 'vr360_user1_excerpt.txt'
#: frames of the walk excerpt, and the joints left out with everything below them
WALK_FRAMES = (360, 720)
WALK_DROPPED = ('RHipJoint', 'RightCollar')
#: timestamps [s] of the VR excerpt's rows (from, to)
VR_WINDOW_S = (80.0, 92.0)


def bvh_excerpt(path: str, frames, dropped) -> str:
    """Text of a BVH with the frames ``frames[0]:frames[1]`` and without the joints ``dropped``
    (and their descendants): their hierarchy blocks and channel columns go, every other line
    and value is kept as written."""
    bvh = mocap.read_bvh(path)
    with open(path, encoding='utf-8') as fh:
        lines = fh.read().splitlines()
    motion_at = next(k for k, ln in enumerate(lines) if ln.strip().upper() == 'MOTION')
    gone = {k for k, j in enumerate(bvh.joints)
            if any(bvh.index(d) in bvh.chain(j.name) for d in dropped)}
    columns = [c for k, j in enumerate(bvh.joints) if k not in gone
               for c in range(j.first_channel, j.first_channel + len(j.channels))]
    cut = set()
    for name in dropped:
        start = bvh.joints[bvh.index(name)].line - 1
        depth = 0
        for end in range(start, motion_at):
            depth += lines[end].count('{') - lines[end].count('}')
            if depth == 0 and '}' in lines[end]:
                break
        cut.update(range(start, end + 1))
    first, stop = frames
    rows = lines[motion_at + 3 + first:motion_at + 3 + stop]
    out = [ln for k, ln in enumerate(lines[:motion_at]) if k not in cut]
    out += ['MOTION', f'Frames: {len(rows)}', lines[motion_at + 2]]
    out += [' '.join(row.split()[c] for c in columns) for row in rows]
    return '\n'.join(out) + '\n'


def vr_excerpt(path: str, window_s) -> str:
    """Text of the trace's header and its rows stamped within ``window_s`` [s], as written."""
    with open(path, encoding='utf-8') as fh:
        lines = fh.read().splitlines()
    rows = [ln for ln in lines[1:] if window_s[0] <= float(ln.split()[0]) < window_s[1]]
    return '\n'.join([lines[0]] + rows) + '\n'


def _write(path: str, text: str) -> None:
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with open(path, 'w', encoding='utf-8', newline='\n') as fh:
        fh.write(text)


def _speed_line(name: str, motion) -> str:
    w = np.degrees(hm.angular_speed(motion))
    return (f'{name}: head angular speed median {np.median(w):.1f}, p95 '
            f'{np.percentile(w, 95):.1f}, p99 {np.percentile(w, 99):.1f}, max {w.max():.1f} deg/s')


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('walk_bvh', help='cmu_131_01_walk.bvh (bvh11 resources/131_01.bvh)')
    ap.add_argument('vr_trace', help='vr360_user1_quaternion.txt (user1_quaternion.txt)')
    ap.add_argument('--out', default=tables.BUNDLED_WALK_CSV, help='the bundled head-pose CSV')
    ap.add_argument('--fixtures', default=FIXTURES, help='folder of the test excerpts')
    args = ap.parse_args(argv)
    try:
        walk = mocap.load_bvh_head_motion(args.walk_bvh)
        vr = tables.read_vr360(args.vr_trace)
    except hm.HeadMotionError as e:
        ap.exit(2, f'make_head_motion_data: {e}\n')
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    tables.write_pose_csv(args.out, walk, comments=HEADER)
    print(f'wrote {args.out}: {len(walk)} frames, {walk.duration_s:.3f} s, '
          f'{walk.rate_hz:.2f} Hz')
    path = os.path.join(args.fixtures, WALK_EXCERPT)
    _write(path, bvh_excerpt(args.walk_bvh, WALK_FRAMES, WALK_DROPPED))
    part = mocap.load_bvh_head_motion(path)
    first, stop = WALK_FRAMES
    assert np.array_equal(part.quaternion, walk.quaternion[first:stop])
    assert np.allclose(part.position, walk.position[first:stop], rtol=0, atol=1e-12)
    print(f'wrote {path}: frames {first}-{stop - 1}, {len(mocap.read_bvh(path).joints)} joints')
    path = os.path.join(args.fixtures, VR_EXCERPT)
    _write(path, vr_excerpt(args.vr_trace, VR_WINDOW_S))
    print(f'wrote {path}: {len(tables.read_vr360(path))} rows, {VR_WINDOW_S[0]:g}-'
          f'{VR_WINDOW_S[1]:g} s')
    print(_speed_line('walk', walk))
    print(_speed_line('vr', vr))
    return 0


if __name__ == '__main__':
    sys.exit(main())
