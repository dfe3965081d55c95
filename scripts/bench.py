#!/usr/bin/env python3
"""Core speed benchmark: guides against pypbd, ghost throughput, numba compile time.

    python scripts/bench.py [--json out/bench.json] [--quick]

Guides: one substep of S strands x 16 nodes (S = 100, 1000, 4000) with stretch constraints between
neighbours and bending as second-neighbour distance constraints, 4 iterations, dt = 1/240 s, no
collider, roots pinned, gravity on — our PBD, XPBD and FTL solvers side by side with Jan Bender's
PositionBasedDynamics (PyPI ``pypbd``: the same particles, the same constraints as
``addDistanceConstraint``, NUM_SUB_STEPS 1, MAX_ITERATIONS 4, the same time step), timed in
turns (:func:`interleaved_ms`) so that a change of the machine's phase hits all alike.  Reported:
median ms per step and ns per node-iteration (ms / (S * 16 * iterations)), and the ratio to pypbd.

Ghosts: one tracking substep of 10 k and 100 k ghost strands x 16 nodes (16 ghosts per guide,
default tracking options) on every core (``--ghost-threads``): median ms and million ghost nodes
per second.

Machine reference: one thread's copy bandwidth and numpy's square root, at the start and the
end (this shared machine's speed drifts by phases; see :func:`machine_reference`).

Compile: first use of every kernel of the default scene in a fresh process with an empty numba
cache (compile), and again with that cache filled (cache load).

All timings exclude compilation (every kernel is run before it is timed) and are medians of
repeated runs in this one process."""
import argparse
import json
import os
import sys

# Threads of the guide comparison (numba and pypbd's OpenMP, fixed before they load): --threads N
# (default 1, the fairest comparison on a shared 2-core machine).  The ghost figures use every
# core (--ghost-threads, default 0 = all): their goal is a throughput of this machine.
_THREADS = sys.argv[sys.argv.index('--threads') + 1] if '--threads' in sys.argv else '1'
os.environ['NUMBA_NUM_THREADS'] = str(max(int(_THREADS), os.cpu_count() or 1))
os.environ['OMP_NUM_THREADS'] = _THREADS
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from hair_tracking.executable import use_numba_cache  # noqa: E402
use_numba_cache()      # before numba loads: the cache make install fills

import numba  # noqa: E402
import numpy as np  # noqa: E402

from hair_tracking.core.groom import make_groom  # noqa: E402
from hair_tracking.core.head_track import IDENTITY  # noqa: E402
from hair_tracking.core.model import StrandSet  # noqa: E402
from hair_tracking.core.scene import Scene  # noqa: E402
from hair_tracking.evaluation.provenance import command_line, provenance  # noqa: E402
from cpu_steal import format_share, StealMeter  # noqa: E402  (scripts/cpu_steal.py)
from hair_tracking.ghosts.interface import TrackStep  # noqa: E402
from hair_tracking.ghosts.tracker import GhostTracker  # noqa: E402
from hair_tracking.guides.solver import make_solver  # noqa: E402

NODES = 16
ITERATIONS = 4
DT = 1.0 / 240.0


def median_ms(fn, repeats, warmup=3):
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - start)
    return float(np.median(samples) * 1e3)


def hanging_rest(strands, nodes=NODES, length=0.25):
    """Straight strands hanging down from a row of roots (head frame)."""
    seg = length / (nodes - 1)
    rest = np.zeros((strands, nodes, 3))
    rest[:, :, 0] = (np.arange(strands) * 0.003)[:, None]
    rest[:, :, 2] = -seg * np.arange(nodes)[None, :]
    return rest


def machine_reference(repeats=7):
    """Two numbers that follow this shared machine's phases (its timings swing 1.5-2x within an
    hour): one thread's copy bandwidth over 64 MB arrays [GB/s, read + write] and numpy's
    square root over 1 M doubles [ns per element].  Printed at the start and the end of a run so
    that figures from different runs can be told apart by phase."""
    a = np.ones(8_000_000)
    b = np.empty_like(a)
    c = np.random.default_rng(0).random(1_000_000)
    d = np.empty_like(c)
    copy = median_ms(lambda: np.copyto(b, a), repeats, warmup=1)
    root = median_ms(lambda: np.sqrt(c, out=d), repeats, warmup=1)
    return {'copy_gb_per_s': 2 * a.nbytes / (copy * 1e-3) / 1e9,
            'sqrt_ns_per_element': root * 1e6 / c.size}


def print_reference(label, ref):
    print(f'machine reference ({label}): copy {ref["copy_gb_per_s"]:.1f} GB/s, sqrt '
          f'{ref["sqrt_ns_per_element"]:.2f} ns/element')


def interleaved_ms(fns, repeats, rounds=5, warmup=3):
    """Median ms per call of each function in ``fns``, measured in ``rounds`` rounds that take
    turns (``repeats`` calls of each per round; the median over the rounds' medians): a phase
    change of this shared machine then hits every function alike, and their ratios hold (one
    run timed pypbd and then ours and got 3.0x at 100 strands, 5.3x minutes later)."""
    for fn in fns:
        for _ in range(warmup):
            fn()
    per_round = [[] for _ in fns]
    for _ in range(rounds):
        for i, fn in enumerate(fns):
            per_round[i].append(median_ms(fn, repeats, warmup=0))
    return [float(np.median(r)) for r in per_round]


def ours_step(solver, strands):
    """One substep of our guide solver ``solver`` on ``strands`` hanging strands (a function)."""
    scene = Scene().with_changes(solver__type=solver, solver__iterations=ITERATIONS,
                                 solver__dt=DT, collider__shape='none',
                                 solver__shock_propagation=0.0, solver__bend_stiffness=0.3)
    s = StrandSet.from_rest(hanging_rest(strands))
    gs = make_solver(s, scene)
    gs.reset(IDENTITY)
    return lambda: gs.step(DT, IDENTITY, IDENTITY)


def pypbd_step(strands):
    """(one time step of pypbd on the same strands, its clean-up): a function each."""
    import pypbd as pbd
    sim = pbd.Simulation.getCurrent()
    sim.initDefault()
    model = sim.getModel()
    particles = model.getParticles()
    ts = sim.getTimeStep()
    ts.setValueUInt(pbd.TimeStepController.NUM_SUB_STEPS, 1)
    ts.setValueUInt(pbd.TimeStepController.MAX_ITERATIONS, ITERATIONS)
    pbd.TimeManager.getCurrent().setTimeStepSize(DT)
    rest = hanging_rest(strands)
    for p in rest.reshape(-1, 3):
        particles.addVertex(p.tolist())
    for s in range(strands):
        b = s * NODES
        particles.setMass(b, 0.0)
        particles.setMass(b + 1, 0.0)
        for k in range(NODES - 1):
            model.addDistanceConstraint(b + k, b + k + 1, 1.0)
        for k in range(NODES - 2):
            model.addDistanceConstraint(b + k, b + k + 2, 0.3)

    def cleanup():
        sim.reset()
        model.cleanup()
    return (lambda: ts.step(model)), cleanup


def bench_ghosts(ghosts, repeats):
    per_guide = 16
    scene = Scene().with_changes(groom__guides=ghosts // per_guide,
                                 groom__ghosts_per_guide=per_guide,
                                 groom__guide_nodes=NODES, groom__ghost_nodes=NODES)
    groom = make_groom(scene.groom)
    guides = StrandSet.from_rest(groom.guide_rest)
    gh = StrandSet.from_rest(groom.ghost_rest)
    tracker = GhostTracker(gh, guides, scene, None)
    tracker.reset(IDENTITY)
    guides.place_at(IDENTITY)
    x_old = guides.x.copy()
    phase = [0.0]

    def step():
        phase[0] += 0.05
        np.copyto(x_old, guides.x)
        guides.x[:, 2:, 0] = groom.guide_rest[:, 2:, 0] + 0.01 * np.sin(phase[0])
        tracker.step(TrackStep(DT, 1, x_old, guides.x, IDENTITY))
    return median_ms(step, repeats)


COMPILE_SNIPPET = r'''
import sys, time
sys.path.insert(0, {root!r})
start = time.perf_counter()
from hair_tracking.core.scene import Scene
from hair_tracking.evaluation.demo import warm_up
from hair_tracking.resources import config_path
scene = Scene.from_yaml(config_path('default'))
warm_up(scene)
print(time.perf_counter() - start)
'''


def bench_compile():
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        code = COMPILE_SNIPPET.format(root=ROOT)
        for label in ('cold_cache_s', 'warm_cache_s'):
            proc = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                                  text=True, timeout=900)
            if proc.returncode != 0:
                raise RuntimeError(proc.stderr)
            out[label] = float(proc.stdout.strip().splitlines()[-1])
    return out


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description='hair_tracking core benchmark')
    ap.add_argument('--json', help='write the figures to this JSON file')
    ap.add_argument('--quick', action='store_true', help='fewer repeats and sizes')
    ap.add_argument('--threads', default='1',
                    help='threads of the guide comparison, numba and pypbd (OpenMP); read '
                    'before import')
    ap.add_argument('--ghost-threads', type=int, default=0,
                    help='numba threads of the ghost figures (0: every core)')
    args = ap.parse_args(argv)
    guide_threads = int(_THREADS)
    ghost_threads = args.ghost_threads or numba.config.NUMBA_NUM_THREADS
    reps = 5 if args.quick else 20
    try:
        import pypbd  # noqa: F401
        have_pypbd = True
    except ImportError:
        have_pypbd = False
        print('pypbd not installed: `pip install pypbd` (make bench does) for the peer column')

    result = {'provenance': provenance(command_line('python scripts/bench.py', argv)),
              'machine': {'threads': guide_threads, 'ghost_threads': ghost_threads,
                          'load_average': os.getloadavg()},
              'guides': [], 'ghosts': [], 'compile': {}}
    result['machine']['reference_start'] = ref = machine_reference()
    print_reference('start', ref)
    numba.set_num_threads(guide_threads)
    stolen = result['machine']['cpu_steal_share'] = {}
    steal = StealMeter()
    rounds = 3 if args.quick else 5
    print(f'guides: {NODES} nodes, {ITERATIONS} iterations, dt {DT * 1e3:.3f} ms; pypbd and '
          f'ours take turns, {rounds} rounds of {reps} steps each (median of the round medians)')
    print(f'{"strands":>8} {"solver":>7} {"ms/step":>9} {"ns/node-it":>11} {"vs pypbd":>9}')
    for strands in ((100, 1000) if args.quick else (100, 1000, 4000)):
        names = ['pbd', 'xpbd', 'ftl']
        fns = [ours_step(s, strands) for s in names]
        cleanup = None
        if have_pypbd:
            peer_fn, cleanup = pypbd_step(strands)
            names.insert(0, 'pypbd')
            fns.insert(0, peer_fn)
        try:
            times = interleaved_ms(fns, reps, rounds)
        finally:
            if cleanup is not None:
                cleanup()
        peer = times[0] if have_pypbd else None
        for solver, ms in zip(names, times):
            ns = ms * 1e6 / (strands * NODES * ITERATIONS)
            ratio = peer / ms if peer else None
            result['guides'].append({'strands': strands, 'solver': solver, 'ms_per_step': ms,
                                     'ns_per_node_iteration': ns, 'speedup_vs_pypbd': ratio})
            rs = f'{ratio:8.1f}x' if ratio else '        -'
            print(f'{strands:8d} {solver:>7} {ms:9.3f} {ns:11.2f} {rs}')

    stolen['guides'] = steal.share()
    numba.set_num_threads(ghost_threads)
    print(f'ghosts: 16 nodes, 16 ghosts per guide, default tracking, one substep, '
          f'{ghost_threads} thread(s)')
    print(f'{"ghosts":>8} {"ms/step":>9} {"M nodes/s":>10}')
    for ghosts in ((10_000,) if args.quick else (10_000, 100_000)):
        ms = bench_ghosts(ghosts, max(5, reps // 2))
        mnps = ghosts * NODES / (ms * 1e-3) / 1e6
        result['ghosts'].append({'ghosts': ghosts, 'ms_per_step': ms, 'mnodes_per_s': mnps})
        print(f'{ghosts:8d} {ms:9.3f} {mnps:10.1f}')
    stolen['ghosts'] = steal.share()

    result['machine']['reference_end'] = ref = machine_reference()
    print_reference('end', ref)
    print('CPU time stolen by the hypervisor: ' + ', '.join(
        f'{k} {format_share(v)}' for k, v in stolen.items()))
    comp = bench_compile()
    result['compile'] = comp
    print(f'numba compile, default scene kernels: empty cache {comp["cold_cache_s"]:.1f} s, '
          f'warm cache {comp["warm_cache_s"]:.1f} s (whole process start included)')
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, 'w') as f:
            json.dump(result, f, indent=2)
        print(f'wrote {args.json}')


if __name__ == '__main__':
    main()
