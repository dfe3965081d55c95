#!/usr/bin/env python3
"""How many placements the FTL pass makes a node the head collider pushed, on an imported groom
and on a procedural groom of the same counts.

    python scripts/restore_placements.py [--strands 10000] [--vertices 100] [--substeps 10]

Writes the synthetic ``.data`` groom of scripts/bench_groom.py (scripts/make_groom_file.py)
into a temporary folder, runs the default scene (FTL guides, one guide per 16 strands) on it
and on a procedural groom of the same strand count along the bundled walk at 60 Hz, and every
fourth frame from the 20th on takes one more substep with the FTL pass run in Python
(:func:`~hair_tracking.guides.ftl.ftl_pass_block`'s ``py_func`` with a copy of
:func:`~hair_tracking.guides.ftl.restore_node` that counts), then puts the state back.  It
prints, for each groom, the nodes the collider pushed a substep and how many of them left
:func:`~hair_tracking.guides.ftl.restore_node` after 1, 2, ... placements.
"""
import argparse
import collections
import os
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'scripts'))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills

import make_groom_file  # noqa: E402
from hair_tracking.bags import io as bag_io  # noqa: E402
from hair_tracking.core.model import HeadPose  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.core.transforms import quat_to_matrix  # noqa: E402
from hair_tracking.colliders import head as collision  # noqa: E402
from hair_tracking.guides import ftl  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402


def counting_restore_node(hist):
    """:func:`ftl.restore_node`'s loop in Python, counting the placements into ``hist``."""
    def restore_node(p, b, r, e, rot, ellipsoid, first):
        px, py, pz = p
        bx, by, bz = b
        ex, ey, ez = e
        cx, cy, cz, ax, ay, az, refine = ellipsoid
        ix, iy, iz = 1.0 / (ax * ax), 1.0 / (ay * ay), 1.0 / (az * az)
        f_ok = ftl.restore_f_ok(ax, ay, az)
        for k in range(first, ftl.RESTORE_ITERATIONS + 1):
            dx, dy, dz, f = ftl.ftl_direction(px - bx, py - by, pz - bz, r, ex, ey, ez, rot)
            px, py, pz = bx + f * dx, by + f * dy, bz + f * dz
            if k == ftl.RESTORE_ITERATIONS:
                break
            qx, qy, qz = collision.to_head(px, py, pz, rot, cx, cy, cz)
            if qx * qx * ix + qy * qy * iy + qz * qz * iz >= f_ok:
                break
            yx, yy, yz = ftl.surface_point(qx, qy, qz, ax, ay, az, refine)
            px = rot[0, 0] * yx + rot[0, 1] * yy + rot[0, 2] * yz + cx
            py = rot[1, 0] * yx + rot[1, 1] * yy + rot[1, 2] * yz + cy
            pz = rot[2, 0] * yx + rot[2, 1] * yy + rot[2, 2] * yz + cz
        hist[k + 1] += 1
        return px, py, pz
    return restore_node


def placements(scene, substeps):
    """``(pushed nodes a substep, {placements: nodes})`` of ``scene`` along the bundled walk."""
    hist = collections.Counter()
    poses = bag_io.read_head_poses(bag_io.bundled_bag())
    sim = HairSimulator(scene)
    names = ('restore_node', 'contact_node', 'ftl_pass_block', 'ftl_block',
             'ftl_collide_block', 'ftl_collide_step', 'ftl_collide_step_serial')
    compiled = {name: getattr(ftl, name) for name in names}
    python = {'restore_node': counting_restore_node(hist),
              'contact_node': ftl.contact_node.py_func,
              'ftl_pass_block': ftl.ftl_pass_block.py_func,
              'ftl_block': ftl.ftl_block.py_func,
              'ftl_collide_block': ftl.ftl_collide_block.py_func,
              'ftl_collide_step': ftl.ftl_collide_step_serial.py_func,
              'ftl_collide_step_serial': ftl.ftl_collide_step_serial.py_func}
    taken = 0
    for k in range(0, len(poses.t_ns) - 1, 2):
        t = int(poses.t_ns[k])
        sim.push_pose(t, poses.position[k], poses.quaternion[k])
        sim.advance_to(t)
        if k < 40 or k % 8 or taken == substeps:
            continue
        x, v = sim.guides.x.copy(), sim.guides.v.copy()
        q = poses.quaternion[k + 1]
        nxt = HeadPose(poses.position[k + 1], q, quat_to_matrix(q))
        for name in names:
            setattr(ftl, name, python[name])
        try:
            sim.guide_solver.step(scene.solver.dt, sim.head, nxt)
        finally:
            for name in names:
                setattr(ftl, name, compiled[name])
        sim.guides.x[...] = x
        sim.guides.v[...] = v
        taken += 1
    return sum(hist.values()) / max(1, taken), dict(sorted(hist.items()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--strands', type=int, default=10_000)
    ap.add_argument('--vertices', type=int, default=100)
    ap.add_argument('--substeps', type=int, default=10)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, 'groom.data')
        make_groom_file.main([path, '--strands', str(args.strands), '--vertices',
                              str(args.vertices)])
        guides = max(1, args.strands // 16)
        scenes = {'imported': Scene().with_changes(groom__file=path, groom__guides=guides),
                  'procedural': Scene().with_changes(groom__guides=guides,
                                                     groom__ghosts_per_guide=16)}
        for name, scene in scenes.items():
            pushed, hist = placements(scene, args.substeps)
            total = sum(hist.values())
            shares = ', '.join(f'{n}: {100.0 * c / total:.2f} %' for n, c in hist.items())
            print(f'{name:10s} pushed nodes a substep {pushed:.0f}; placements: {shares}',
                  flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
