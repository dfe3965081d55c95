"""``hair_sim_eval``: the evaluation of the package, from the command line.

    hair_sim_eval accuracy [--quick] [--motions NAME ...] [--motion FILE ...] [--out DIR]
    hair_sim_eval dominance [--ghosts 4096 16384] [--motion FILE ...] [--out DIR]
    hair_sim_eval stability [--quick] [--only NAME ...] [--out DIR]

``accuracy`` measures error against run time of every method
(:mod:`hair_tracking.evaluation.accuracy`) on the bundled walk recording, a VR head-mounted-display
trace (with ``--vr PATH``), a synthetic head shake and any recording given with ``--motion``,
and writes ``accuracy.csv``, ``accuracy.md`` and PNG plots.  ``dominance`` scores ghost
settings against simulating every strand (:mod:`hair_tracking.evaluation.dominance`).
``stability`` runs the matrix of stiff and extreme cases
(:mod:`hair_tracking.evaluation.stability`) and writes ``stability.csv`` and ``stability.md``; it
exits with status 1 if a case fails.

Every command writes under ``out/eval/<command>/`` of the current folder (figures in its
``figures/``) unless ``--out`` (and ``--figures``) name other folders; the committed reports
under ``docs/`` are refreshed by ``make eval`` and ``make stability``, which name them.
``--motions`` picks built-in motions by name (:data:`MOTIONS`; an unknown name is a usage
error), and ``--motion FILE`` adds a recording read exactly as ``hair_sim_bag import`` reads
it, with its options (:mod:`hair_tracking.bags.recording`); the files come on top of the
built-in motions, in every command alike.

``--quick`` is the CI-sized variant (fewer strands, motions and methods); the default is the
full evaluation, the one ``make eval`` commits under ``docs/``.  Timings are taken
single-threaded by default (``--threads``): on a shared two-core machine numba's and OpenMP's
thread pools are slowed down by an order of magnitude by other load, and one thread treats
every method alike.
"""
import argparse
import os
import sys
import time

from hair_tracking.evaluation.provenance import (command_line as provenance_command_line,
                                                 markdown_lines, provenance)

#: The VR360 headset trace is not bundled (its licence asks for attribution we keep with the
#: data): pass ``--vr PATH`` to include it.
DEFAULT_VR = ''

#: Head-centre offset from the neck pivot in the head frame [m] used for the VR trace, which
#: records orientation only (a head turns about the neck, so its centre moves).
VR_NECK_OFFSET = (0.0, 0.0, 0.1)

#: The built-in motions ``--motions`` names; ``--quick`` runs the walk unless it names others.
MOTIONS = ('walk', 'vr', 'shake')

#: Where a command writes unless ``--out`` says otherwise: ``out/eval/<command>`` of the
#: current folder (``out/`` is ignored by git).
OUT_DIR = os.path.join('out', 'eval')

#: The accuracy and dominance studies settle every method at the first pose until no node moves
#: faster than this [m/s] (``solver.settle_speed``), so the settled shapes they compare are
#: the shapes at rest (a fixed settle of 0.5 s leaves hair still moving 8-11 % L a second).
SETTLE_SPEED = 0.002


def _set_threads(n: int) -> None:
    # must happen before numba kernels run / pypbd is imported (OpenMP reads it at start)
    os.environ['OMP_NUM_THREADS'] = str(n)
    import numba
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def trajectories(names, quick: bool, vr_path: str, log=print):
    """The built-in motions ``names`` (of :data:`MOTIONS`), in that order; the walk lasts 3 s
    with ``quick``; the VR trace is skipped (with a note) without ``vr_path``."""
    from hair_tracking.motion.pose_table import load_bundled_walk, read_vr360
    from hair_tracking.evaluation import synthetic_motion as sm
    from hair_tracking.evaluation.accuracy import Trajectory
    out = []
    for name in names:
        if name == 'walk':
            out.append(Trajectory('walk', load_bundled_walk(),
                                  'CMU 131_01 start-walk-stop, 120 Hz mocap head',
                                  3.0 if quick else None))
        elif name == 'vr' and vr_path and os.path.isfile(vr_path):
            vr = read_vr360(vr_path, neck_offset=VR_NECK_OFFSET)
            start = sm.busiest_window(vr, 10.0)
            vr = sm.window(vr, start, 10.0)
            out.append(Trajectory('vr', vr, f'VR360 user 1 HMD trace, busiest 10 s (from '
                                            f'{start:g} s), 59 Hz, head 10 cm above the neck '
                                            'pivot'))
        elif name == 'vr':
            log(f'VR trace not given or not found ({vr_path or "no --vr"}): skipped')
        elif name == 'shake':
            out.append(Trajectory('shake', sm.named('shake10', 3.0),
                                  'synthetic head shake, 10 rad/s peak at 2 Hz, then 0.5 s '
                                  'still'))
    return out


def study_scene(args):
    """The scene of an accuracy or dominance study: ``--scene`` or the default, every method
    settled until still (``--settle-speed``)."""
    from hair_tracking.core.scene import Scene
    scene = Scene.from_yaml(args.scene) if args.scene else Scene()
    return scene.with_changes(solver__settle_speed=args.settle_speed)


def cmd_accuracy(args) -> int:
    from hair_tracking.evaluation import accuracy as ea
    from hair_tracking.evaluation.methods import make_workload, pypbd_available
    scene = study_scene(args)
    ghosts = args.ghosts or (128 if args.quick else 512)
    workload = make_workload(scene, ghosts)
    missing = pypbd_available()
    if missing:
        print(f'NOTE: {missing}; the pypbd rows are skipped.')
    specs = ea.default_methods(scene, quick=args.quick, with_pypbd=not missing)
    if args.only:
        specs = [s for s in specs if any(o in s.name for o in args.only)]
    reports = []
    t0 = time.perf_counter()
    for tr in trajectories(args.motions, args.quick, args.vr) + args.recorded:
        if args.duration:
            tr.duration_s = args.duration
        reports.append(ea.evaluate(workload, tr, specs, repeats=args.repeats,
                                   timing_frames=60 if args.quick else 120,
                                   convergence_frames=30 if args.quick else 60))
    wall = time.perf_counter() - t0
    notes = [f'Wall time of the evaluation {wall / 60:.1f} min.',
             f'Workload: {workload.count} ghost strands x {workload.ghost_rest.shape[1]} nodes, '
             f'mean length {workload.strand_length.mean():.3f} m; base scene: solver '
             f'{scene.solver.type} dt 1/{1 / scene.solver.dt:.0f} s, collider '
             f'{scene.collider.shape}, damping {scene.damping:g}/s.',
             f'Reference: every ghost strand simulated as a guide, XPBD compliance 0, '
             f'{ea.REFERENCE["substeps"]} substeps per frame (dt 1/'
             f'{int(ea.FRAME_RATE * ea.REFERENCE["substeps"])} s), '
             f'{ea.REFERENCE["iterations"]} iterations, head collider.',
             'ms/frame: median of per-run medians (accuracy run + '
             f'{args.repeats} interleaved timing runs), compile time excluded; the machine '
             'is shared, so timings carry noise of some 20 % (compare the min/max run columns '
             'of the CSV).',
             'Predictable window: hair sliding over the head is chaotic (a strand on the '
             'crown may fall to either side); the reference is rerun with its start perturbed '
             f'by {ea.CHAOS_PERTURBATION * 1e6:g} um and the window ends where the two differ '
             f'by {100 * ea.CHAOS_RMS:g} % L RMS. Errors after it measure that chaos as much as '
             'the method; both are reported.']
    if missing:
        notes.append(f'pypbd skipped: {missing}.')
    paths = ea.write_outputs(reports, args.out, args.figures,
                             provenance(command_line(args), args.threads), notes,
                             time_series=TIME_SERIES)
    for k, p in paths.items():
        print(f'wrote {k}: {p}')
    return 0


#: Methods shown in the error-over-time plots.
TIME_SERIES = ('full FTL dt 1/240', 'full XPBD dt 1/240 4 it', 'ghost 1:16 all on',
               'ghost 1:16 plain copy', 'rigid offset 1:16', 'pypbd dt 1/240 4 it')


def cmd_stability(args) -> int:
    from hair_tracking.evaluation import stability
    cases = stability.matrix(quick=args.quick, tracking_mode=args.tracking_mode)
    if args.only:
        cases = [c for c in cases if any(o in c.name for o in args.only)]
    t0 = time.perf_counter()
    results = stability.run_matrix(cases, log=print)
    wall = time.perf_counter() - t0
    os.makedirs(args.out, exist_ok=True)
    paths = stability.write_outputs(results, args.out,
                                    provenance(command_line(args), args.threads),
                                    [f'Wall time {wall / 60:.1f} min.'])
    for k, p in paths.items():
        print(f'wrote {k}: {p}')
    failed = [r for r in results if not r.passed]
    print(f'{len(results) - len(failed)}/{len(results)} cases passed')
    return 1 if failed else 0


def recorded(args, duration=None):
    """Trajectories of the files named by ``--motion``, read as ``hair_sim_bag import`` reads
    them (:func:`hair_tracking.bags.recording.load_recording`, with the options in ``args``)."""
    from hair_tracking.bags.recording import load_recording
    from hair_tracking.evaluation.accuracy import Trajectory
    out = []
    for path in args.motion:
        motion, note = load_recording(path, args)
        out.append(Trajectory(os.path.splitext(os.path.basename(path.rstrip('/')))[0], motion,
                              f'recorded: {path} ({note})', duration))
    return out


def cmd_dominance(args) -> int:
    import json

    from hair_tracking.evaluation import dominance as dm
    from hair_tracking.evaluation.methods import make_workload
    scene = study_scene(args)
    tracks = trajectories(args.motions, False, args.vr) + args.recorded
    record = provenance(command_line(args), max(args.thread_counts))
    md = ['# Do the ghosts pay for themselves?', ''] + markdown_lines(record) + [
          'Every method simulates the same strands; errors against every strand simulated by '
          'FTL at dt 1/960 s; a ghost setting dominates the baseline (every strand, FTL dt '
          '1/60 s) when it takes at most 1/3 of its time a frame with no more motion error, '
          'stretch <= 1 % and no penetration beyond the collider margin '
          '(`hair_tracking/evaluation/dominance.py`).', '']
    intro = len(md)
    dump, reports = [], []
    for ghosts in args.ghosts:
        workload = make_workload(scene, ghosts)
        for tr in tracks:
            print(f'{tr.name}, {workload.count} strands:', flush=True)
            for rep in dm.study(workload, tr, args.duration, repeats=args.repeats,
                                thread_counts=args.thread_counts):
                reports.append(rep)
                md.append(dm.markdown(rep, rep['threads']))
                dump.append({**{k: v for k, v in rep.items() if k != 'rows'},
                             'rows': [dict(r.__dict__, ms=r.ms) for r in rep['rows']]})
                print(md[-1], flush=True)
    md[intro:intro] = [dm.summary(reports)]
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, 'dominance.md'), 'w', encoding='utf-8') as f:
        f.write('\n'.join(md))
    with open(os.path.join(args.out, 'dominance.json'), 'w', encoding='utf-8') as f:
        json.dump({'provenance': record, 'studies': dump}, f, indent=1)
    os.makedirs(args.figures, exist_ok=True)
    print(f"wrote {os.path.join(args.out, 'dominance.md')}, "
          f"{dm.plot(reports, os.path.join(args.figures, 'dominance.png'))}")
    return 0


def command_line(args) -> str:
    return provenance_command_line('hair_sim_eval', args.argv)


def _outputs(p, command: str, what: str, figures: bool) -> None:
    """``--out`` (and ``--figures``) of ``command``: under :data:`OUT_DIR` by default."""
    out = os.path.join(OUT_DIR, command)
    p.add_argument('--out', default=out, help=f'folder of {what} (default {out}/)')
    if figures:
        p.add_argument('--figures', default=None,
                       help='folder of the PNG plots (default: figures/ in --out)')


def _motions(p, default: str) -> None:
    """``--motions`` (built-in, by name), ``--motion FILE`` and the options of
    ``hair_sim_bag import`` that say how the files are read."""
    from hair_tracking.bags import recording
    p.add_argument('--motions', nargs='*', default=None, metavar='NAME', choices=MOTIONS,
                   help=f'built-in motions among {", ".join(MOTIONS)} (default: {default}; '
                        'none: only the --motion files)')
    p.add_argument('--motion', action='append', default=[], metavar='FILE',
                   help='also a recording of your own, read as hair_sim_bag import reads it: a '
                        'head-pose bag, a BVH capture or a pose table (repeatable); the options '
                        'below are those of hair_sim_bag import')
    recording.add_arguments(p)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(prog='hair_sim_eval', description=__doc__.split('\n')[0])
    sub = p.add_subparsers(dest='cmd', required=True)
    a = sub.add_parser('accuracy', help='error against run time of every method')
    a.add_argument('--quick', action='store_true',
                   help='CI-sized run: 128 ghosts, 3 s of the walk, fewer methods')
    _outputs(a, 'accuracy', 'the CSV/Markdown tables', figures=True)
    a.add_argument('--ghosts', type=int, default=0, help='ghost strands (default 512, quick 128)')
    a.add_argument('--repeats', type=int, default=2, help='timing runs per method')
    a.add_argument('--scene', default='', help='scene YAML (default: the default scene)')
    a.add_argument('--settle-speed', type=float, default=SETTLE_SPEED,
                   help='every method settles at the first pose until no node moves faster '
                        f'[m/s] (solver.settle_speed; default {SETTLE_SPEED}; 0: '
                        'solver.settle_time alone)')
    a.add_argument('--vr', default=DEFAULT_VR, help='VR360 trace (timestamp viewpoint w x y z)')
    _motions(a, 'all of them; --quick: walk')
    a.add_argument('--duration', type=float, default=0.0,
                   help='simulate only the first S seconds of each trajectory')
    a.add_argument('--only', nargs='*', default=None, help='only methods whose name contains')
    a.add_argument('--threads', type=int, default=1, help='numba/OpenMP threads (default 1)')
    d = sub.add_parser('dominance', help='ghost settings against simulating every strand with '
                                         'FTL at dt 1/60 s (same-solver reference)')
    d.add_argument('--ghosts', type=int, nargs='+', default=[4096, 16384],
                   help='strand counts (default 4096 16384)')
    _motions(d, 'all of them')
    d.add_argument('--vr', default=DEFAULT_VR, help='VR360 trace (timestamp viewpoint w x y z)')
    d.add_argument('--duration', type=float, default=3.0, help='seconds of each motion')
    d.add_argument('--repeats', type=int, default=2, help='timing runs per method')
    d.add_argument('--thread-counts', type=int, nargs='+', default=[1],
                   help='numba thread counts to time (default 1)')
    d.add_argument('--scene', default='', help='scene YAML (default: the default scene)')
    d.add_argument('--settle-speed', type=float, default=SETTLE_SPEED,
                   help='every method settles at the first pose until no node moves faster '
                        f'[m/s] (solver.settle_speed; default {SETTLE_SPEED}; 0: '
                        'solver.settle_time alone)')
    _outputs(d, 'dominance', 'dominance.md / .json', figures=True)
    s = sub.add_parser('stability', help='the matrix of stiff and extreme cases')
    s.add_argument('--quick', action='store_true', help='the reduced matrix (CI)')
    _outputs(s, 'stability', 'the tables', figures=False)
    s.add_argument('--only', nargs='*', default=None, help='only cases whose name contains')
    s.add_argument('--threads', type=int, default=1, help='numba threads (default 1)')
    s.add_argument('--tracking-mode', choices=['paper', 'blend', 'turn'], default=None,
                   help='run every case with this ghost tracker (default: the scene default)')
    args = p.parse_args(argv)
    args.argv = argv
    if args.cmd == 'dominance':
        args.threads = max(args.thread_counts)
    if args.threads < 1:
        p.error('--threads must be >= 1')
    if getattr(args, 'repeats', 1) < 0:
        p.error('--repeats must be >= 0')
    if args.cmd == 'dominance' and args.repeats < 1:
        p.error('--repeats must be >= 1 (a setting dominates by its time)')
    if args.cmd == 'dominance' and min(args.ghosts) < 16:
        p.error('--ghosts must be at least 16 (the 1:16 ratio needs one guide)')
    if args.cmd == 'accuracy' and args.ghosts and args.ghosts < 64:
        p.error('--ghosts must be at least 64 (the 1:64 ratio needs one guide)')
    if getattr(args, 'figures', '') is None:
        args.figures = os.path.join(args.out, 'figures')
    if args.cmd in ('accuracy', 'dominance'):
        from hair_tracking.bags.io import BagError
        if args.motions is None:
            args.motions = ['walk'] if getattr(args, 'quick', False) else list(MOTIONS)
        try:                    # every file read before any work, so a bad one costs nothing
            args.recorded = recorded(args)
        except BagError as e:
            p.error(f'--motion: {e}')
        if not args.motions and not args.recorded:
            p.error('nothing to evaluate: --motions names no built-in motion and no --motion '
                    'file is given')
    if args.cmd == 'dominance':
        _set_threads(max(args.thread_counts))
        return cmd_dominance(args)
    _set_threads(args.threads)
    if args.cmd == 'accuracy':
        return cmd_accuracy(args)
    return cmd_stability(args)


if __name__ == '__main__':
    sys.exit(main())
