#!/usr/bin/env python3
"""Derive hair_tracking/data/cmu_131_01_walk_head.csv from the CMU 131_01 walk BVH.

Usage: python scripts/make_head_motion_data.py [path/to/cmu_131_01_walk.bvh] [--out CSV]

Reads the BVH with hair_tracking.motion.bvh.load_bvh_head_motion (Head joint, head-centre origin,
CMU scale 0.056444 m/unit, REP-103 frames) and writes all 994 frames as
``t_s,px,py,pz,qx,qy,qz,qw`` (7 significant digits) with an attribution header.  The source is the
CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu), subject 131 trial 01, as converted
to BVH in the MIT-licensed repository yuki-koyama/bvh11 (resources/131_01.bvh); see
hair_tracking/data/ATTRIBUTION.md.
"""
import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hair_tracking.motion import bvh as mocap, pose_table as tables  # noqa: E402

DEFAULT_BVH = '/work/shared/data/head_motion/cmu_131_01_walk.bvh'

HEADER = (
    'CMU Graphics Lab Motion Capture Database, http://mocap.cs.cmu.edu/ (subject 131, trial 01,',
    '"start, walk, stop"); BVH conversion from github.com/yuki-koyama/bvh11',
    '(resources/131_01.bvh, MIT licence, Copyright (c) 2018 Yuki Koyama).',
    'See ATTRIBUTION.md next to this file. Derived by scripts/make_head_motion_data.py:',
    'Head joint, origin at the head centre (middle of the Head bone), 0.056444 m per BVH unit,',
    'REP-103 frames (world z up; head x forward, y left, z up), quaternion x y z w.',
)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('bvh', nargs='?', default=DEFAULT_BVH)
    ap.add_argument('--out', default=tables.BUNDLED_WALK_CSV)
    args = ap.parse_args(argv)
    motion = mocap.load_bvh_head_motion(args.bvh)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    tables.write_pose_csv(args.out, motion, comments=HEADER)
    print(f'wrote {args.out}: {len(motion)} frames, {motion.duration_s:.3f} s, '
          f'{motion.rate_hz:.2f} Hz')
    return 0


if __name__ == '__main__':
    sys.exit(main())
