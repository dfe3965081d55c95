"""Cost of the contact model (hair_tracking.colliders): per node and shape, and a five-capsule
bust against the ghosts of the default hair, beside the copy bandwidth and the ghost trackers'
frames measured in the same run.

1. Per node, on one thread, over points around each shape (about half inside): the bound test
   (``bounds.near``), each shape's inside test (sphere, capsule, the ellipsoid in its axes as
   the guide solver tests it and as a world quadric as the stateless trackers do, plane) and
   its push-out with friction (``contact.contact_of``).
2. The bust (``body.bust``, height 1.70 m, on the neck frame under the head) against every
   ghost node of the default scene at ``--ghosts`` ghosts of 16 nodes after a few poses, held
   in blocks of 64 lanes node-major as the ghost kernels hold them: the stateless trackers'
   contact (inside test of every lane a vector pass a shape, slide and push of the lanes
   inside) with no bound test, with the bound test of the block's box at each node index
   first (only the capsules that box may touch run), and node by node with the node's bound
   test (the guide solver's order). Beside it: a copy of the same positions (read + write),
   the numpy copy bandwidth (``bench_blend.copy_bandwidth``), and the blend and turn
   trackers' frames at the same ghost count and thread count without a body and with the
   scene's bust (``body.bust``: the trackers' ``kernels.slide_push_strands`` after the
   placement), whose ratio is the bust's cost in the product.

    python scripts/bench_colliders.py [--ghosts 100000] [--threads 1] [--rounds 9] [--json f]
"""
import argparse
import json
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills
import numba  # noqa: E402
from numba import njit  # noqa: E402
import numpy as np  # noqa: E402

from hair_tracking.colliders import body, bounds, contact, pose  # noqa: E402
from hair_tracking.colliders import slide as stateless  # noqa: E402
from hair_tracking.colliders.shapes import (CAPSULE, KIND, Shape, shape_table)  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from hair_tracking.ghosts.interface import TrackStep  # noqa: E402
from hair_tracking.simulator import HairSimulator  # noqa: E402

from bench_blend import copy_bandwidth, moved  # noqa: E402  (scripts/, this script's folder)

FASTMATH = contact.FASTMATH
LANES = 64
HEIGHT = 1.7


# ----------------------------------------------------------------------------- per node
@njit(fastmath=FASTMATH, error_model='numpy')
def per_node(x, sh, k, what):
    """One pass over the points ``x`` (n, 3) against shape ``k``: 0 the bound test, 1 the
    inside test of the guide solver (the ellipsoid in its axes), 2 the stateless trackers'
    level (the ellipsoid's world quadric), 3 the push-out with friction.  Returns a count
    (so nothing is optimised away)."""
    hits = 0
    kind = int(sh[k, KIND])
    for i in range(x.shape[0]):
        x0, x1, x2 = x[i, 0], x[i, 1], x[i, 2]
        if what == 0:
            hits += bounds.near(x0, x1, x2, sh, k)
        elif what == 1:
            hits += not contact.outside_within(x0, x1, x2, sh, k, 0.0)
        elif what == 2:
            hits += stateless.level(x0, x1, x2, sh, k) < 0.0
        else:
            moved, y0, y1, y2 = contact.contact_of(kind, x0, x1, x2, x0, x1, x2, sh, k, 0.3)
            hits += moved
    return hits


# ----------------------------------------------------------------------------- the bust
@njit(inline='always')
def near_shapes(lo0, lo1, lo2, hi0, hi1, hi2, sh, out):
    """The shapes of the table ``sh`` that the box ``lo .. hi`` may touch, in table order, into
    ``out`` (int64, at least one entry a shape); returns their count."""
    m = 0
    for k in range(sh.shape[0]):
        if bounds.box_near(lo0, lo1, lo2, hi0, hi1, hi2, sh, k):
            out[m] = k
            m += 1
    return m


@njit(inline='always')
def lane_box(xs, ys, zs, n):
    """The box ``(lo0, lo1, lo2, hi0, hi1, hi2)`` of ``n`` lanes whose coordinates are the
    first ``n`` entries of the rows ``xs``, ``ys``, ``zs`` (a block's lanes at one node
    index).  A coordinate that is not finite is left out (the other lanes keep their bound;
    no finite lane gives an empty box, near no shape)."""
    lo0 = lo1 = lo2 = math.inf
    hi0 = hi1 = hi2 = -math.inf
    for i in range(n):
        v = xs[i]
        lo0 = v if v < lo0 else lo0
        hi0 = v if v > hi0 else hi0
        v = ys[i]
        lo1 = v if v < lo1 else lo1
        hi1 = v if v > hi1 else hi1
        v = zs[i]
        lo2 = v if v < lo2 else lo2
        hi2 = v if v > hi2 else hi2
    return lo0, lo1, lo2, hi0, hi1, hi2


@njit(inline='always')
def _contacts(xb, out, seg, b, j, sh, k, lev):
    """Node ``j`` of block ``b``: the level of every lane against capsule ``k`` (one vector
    pass), then the slide and push of the lanes inside."""
    lanes = xb.shape[3]
    inside = 0
    for lane in range(lanes):
        lev[lane] = stateless.level_round(out[b, j, 0, lane], out[b, j, 1, lane],
                                          out[b, j, 2, lane], sh, k)
        inside += 1 if lev[lane] < 0.0 else 0
    if inside == 0:
        return 0
    for lane in range(lanes):
        if lev[lane] < 0.0:
            out[b, j, 0, lane], out[b, j, 1, lane], out[b, j, 2, lane] = \
                stateless.slide_push_of(CAPSULE, out[b, j, 0, lane], out[b, j, 1, lane],
                                        out[b, j, 2, lane], out[b, j - 1, 0, lane],
                                        out[b, j - 1, 1, lane], out[b, j - 1, 2, lane],
                                        seg[b, j, lane], True, sh, k)
    return inside


@njit(fastmath=FASTMATH, error_model='numpy')
def bust_pass(xb, out, seg, sh, mode):
    """The bust against every node of ``xb`` (B, N, 3, lanes) into ``out``: ``mode`` 0 every
    capsule's level at every node index, 1 the block's box at the node index first
    (``lane_box``, ``near_shapes``), 2 node by node, each node's bound test
    first.  Returns ``(contacts, exact tests run)``."""
    blocks, n, _, lanes = xb.shape
    lev = np.empty(lanes)
    near = np.empty(sh.shape[0], dtype=np.int64)
    contacts = 0
    passes = 0
    for b in range(blocks):
        for lane in range(lanes):
            for a in range(3):
                out[b, 0, a, lane] = xb[b, 0, a, lane]
                out[b, 1, a, lane] = xb[b, 1, a, lane]
        for j in range(2, n):
            for a in range(3):
                for lane in range(lanes):
                    out[b, j, a, lane] = xb[b, j, a, lane]
            if mode == 0:
                for k in range(sh.shape[0]):
                    contacts += _contacts(xb, out, seg, b, j, sh, k, lev)
                    passes += lanes
            elif mode == 1:
                lo0, lo1, lo2, hi0, hi1, hi2 = lane_box(out[b, j, 0], out[b, j, 1],
                                                        out[b, j, 2], lanes)
                m = near_shapes(lo0, lo1, lo2, hi0, hi1, hi2, sh, near)
                for i in range(m):
                    contacts += _contacts(xb, out, seg, b, j, sh, near[i], lev)
                passes += m * lanes
            else:
                for lane in range(lanes):
                    x0, x1, x2 = out[b, j, 0, lane], out[b, j, 1, lane], out[b, j, 2, lane]
                    for k in range(sh.shape[0]):
                        if not bounds.near(x0, x1, x2, sh, k):
                            continue
                        passes += 1
                        if stateless.level_round(x0, x1, x2, sh, k) < 0.0:
                            x0, x1, x2 = stateless.slide_push_of(
                                CAPSULE, x0, x1, x2, out[b, j - 1, 0, lane],
                                out[b, j - 1, 1, lane], out[b, j - 1, 2, lane],
                                seg[b, j, lane], True, sh, k)
                            contacts += 1
                    out[b, j, 0, lane], out[b, j, 1, lane], out[b, j, 2, lane] = x0, x1, x2
    return contacts, passes


@njit
def copy_pass(xb, out):
    for b in range(xb.shape[0]):
        for j in range(xb.shape[1]):
            for a in range(3):
                for lane in range(xb.shape[3]):
                    out[b, j, a, lane] = xb[b, j, a, lane]
    return 0, 0


def lane_blocks(x):
    """Strands (S, N, 3) as blocks (B, N, 3, LANES), the last block padded with copies of the
    last strand; their segment lengths (B, N, LANES) at row j for segment j - 1."""
    s, n, _ = x.shape
    pad = -s % LANES
    x = np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])
    xb = np.ascontiguousarray(x.reshape(-1, LANES, n, 3).transpose(0, 2, 3, 1))
    seg = np.zeros((xb.shape[0], n, LANES))
    seg[:, 1:] = np.linalg.norm(np.diff(xb, axis=1), axis=2)
    return xb, seg


# ----------------------------------------------------------------------------- timing
def shapes_around(rng, n):
    """One shape of every kind (and the two ellipsoid tests) with points around it."""
    shapes = [Shape('sphere', frame='fixed', radius=0.06, margin=0.004, friction=0.3),
              Shape('capsule', frame='fixed', radius=0.05, half_length=0.1, margin=0.004,
                    friction=0.3),
              Shape('ellipsoid', frame='fixed', radii=(0.095, 0.08, 0.105), margin=0.004,
                    friction=0.3),
              Shape('plane', frame='fixed', margin=0.004, friction=0.3)]
    sh = pose.posed(shape_table(shapes), *pose.frames_at(np.eye(3), np.zeros(3)))
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    pts = np.ascontiguousarray(u * rng.uniform(0.0, 0.2, size=(n, 1)))
    return sh, pts


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--ghosts', type=int, default=100_000)
    ap.add_argument('--threads', type=int, default=1)
    ap.add_argument('--rounds', type=int, default=9)
    ap.add_argument('--points', type=int, default=1_000_000)
    ap.add_argument('--json')
    args = ap.parse_args(argv)
    numba.set_num_threads(args.threads)
    rng = np.random.default_rng(1)
    result = {'threads': args.threads}

    # 1. per node
    sh, pts = shapes_around(rng, args.points)
    names = ('near', 'inside (guide solver)', 'level (stateless trackers)', 'push-out')
    kinds = ('sphere', 'capsule', 'ellipsoid', 'plane')
    per_node(pts[:10], sh, 0, 0)
    runs = {(kind, name): [] for kind in kinds for name in names}
    for _ in range(args.rounds):                   # alternate, so load changes hit all alike
        for k, kind in enumerate(kinds):
            for what, name in enumerate(names):
                t = time.perf_counter()
                per_node(pts, sh, k, what)
                runs[kind, name].append(time.perf_counter() - t)
    per = {kind: {name: statistics.median(runs[kind, name]) / len(pts) * 1e9 for name in names}
           for kind in kinds}
    for kind in kinds:
        print(f'{kind:>9}: ' + ', '.join(f'{name} {ns:.2f} ns' for name, ns in per[kind].items())
              + ' a node', flush=True)
    result['ns_per_node'] = per

    # 2. the bust against the default hair
    guides = max(1, args.ghosts // 16)
    base = Scene().with_changes(groom__guides=guides, groom__ghosts_per_guide=16,
                                solver__settle_time=0.0)
    sims = {(mode, on): moved(HairSimulator(base.with_changes(tracking__mode=mode,
                                                              body__bust=on)), 1)
            for mode in ('blend', 'turn') for on in (False, True)}
    for k in range(2, 5):
        for sim in sims.values():
            moved(sim, k)
    sim = sims['blend', False]
    x = np.ascontiguousarray(sim.ghost_tracker.positions(), dtype=np.float64)
    head = sim.head
    neck = body.neck_frame(head.rotation, head.position, HEIGHT)
    local = shape_table(body.bust(HEIGHT, frame='neck', margin=0.004, friction=0.3))
    bust = pose.posed(local, *pose.frames_at(head.rotation, head.position, [neck]))
    xb, seg = lane_blocks(x)
    out = np.empty_like(xb)
    nodes = x.shape[0] * x.shape[1]
    passes = {'copy': lambda: copy_pass(xb, out),
              'bust, no bound': lambda: bust_pass(xb, out, seg, bust, 0),
              'bust, box bound a node index': lambda: bust_pass(xb, out, seg, bust, 1),
              'bust, node bound (node by node)': lambda: bust_pass(xb, out, seg, bust, 2)}
    counts = {name: f() for name, f in passes.items()}
    frames = {}
    for (mode, with_bust), s in sims.items():
        tr = s.ghost_tracker

        def frame(tr=tr, s=s):
            tr.step(TrackStep(s.scene.solver.dt, 1, s.guides.x.copy(), s.guides.x, s.head))
            tr.positions()
        frames[f'{mode} frame' + (', bust' if with_bust else '')] = frame
        frame()
    times = {}
    for _ in range(args.rounds):                   # alternate, so load changes hit all alike
        for name, f in list(passes.items()) + list(frames.items()):
            t = time.perf_counter()
            f()
            times.setdefault(name, []).append(time.perf_counter() - t)
    med = {name: statistics.median(ts) * 1e3 for name, ts in times.items()}
    copy_bw = 2 * xb.nbytes / (med['copy'] / 1e3)
    numpy_bw = copy_bandwidth()
    print(f'{x.shape[0]} ghosts x {x.shape[1]} nodes ({nodes} nodes), {args.threads} '
          f'thread(s); copy of the positions {med["copy"]:.2f} ms ({copy_bw / 1e9:.1f} GB/s; '
          f'numpy copy of 64 MB {numpy_bw / 1e9:.1f} GB/s)')
    for name in frames:
        print(f'  {name}: {med[name]:.2f} ms')
    for mode in ('blend', 'turn'):
        added = med[f'{mode} frame, bust'] / med[f'{mode} frame'] - 1.0
        result[f'{mode}_bust_added'] = added
        print(f'  the bust adds {100 * added:.0f} % to the {mode} frame '
              f'(slide_push_strands after the placement)')
    rows = {}
    for name in passes:
        if name == 'copy':
            continue
        contacts, runs = counts[name]
        added = med[name] - med['copy']         # the pass copies the positions too
        rows[name] = {'median_ms': med[name], 'added_ms': added, 'contacts': int(contacts),
                      'exact_tests_per_node': runs / nodes,
                      'over_copy': med[name] / med['copy'],
                      'share_of_blend_frame': med[name] / med['blend frame'],
                      'share_of_turn_frame': med[name] / med['turn frame'],
                      'added_share_of_blend_frame': added / med['blend frame'],
                      'added_share_of_turn_frame': added / med['turn frame']}
        print(f'  {name}: {med[name]:.2f} ms ({med[name] / med["copy"]:.1f} x the copy; '
              f'{100 * med[name] / med["blend frame"]:.0f} % of the blend frame, '
              f'{100 * med[name] / med["turn frame"]:.0f} % of the turn frame; less the copy '
              f'{100 * added / med["blend frame"]:.0f} % and '
              f'{100 * added / med["turn frame"]:.0f} %); '
              f'{contacts} contacts, {runs / nodes:.2f} exact tests a node', flush=True)
    result.update({'ghosts': int(x.shape[0]), 'nodes': int(nodes), 'median_ms': med,
                   'copy_bandwidth_GBps': copy_bw / 1e9,
                   'numpy_copy_bandwidth_GBps': numpy_bw / 1e9, 'bust': rows})
    if args.json:
        record = provenance(command_line('python scripts/bench_colliders.py', argv),
                            args.threads)
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump({'provenance': record, 'results': result}, f, indent=2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
