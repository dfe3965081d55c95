"""Do the ghosts pay for themselves?  Ghost settings against simulating every strand.

For one workload (the same strands for every method) and one head motion, every method is
scored against a **same-solver reference** -- every strand simulated by Follow-The-Leader at
:data:`REFERENCE_SUBSTEPS` substeps per 60 Hz frame -- and timed:

* **motion error**: RMS over the strands' nodes and the frames from the first frame in which the
  head has moved (more than 1 mm or 1 mrad from its start) of the error of the *displacement*
  from the settled state, against the reference's displacement, in % of the strand length
  (:class:`~hair_tracking.evaluation.accuracy.Scorer`'s ``motion``); the error already present in
  the settled shape is reported apart (``settled error``);
* **stretch** (largest ``|l / l0 - 1|``) and **penetration** (deepest node inside the bare head
  collider, and with ``body.bust`` inside the bare bust) over the run: a setting is admitted
  only with stretch <= 1 % and penetration <= the collider's margin (the bust's);
* **ms per frame**: guides, ghosts and everything a frame needs, medians over ``repeats`` timing
  runs interleaved across the methods (compile time excluded), min and median reported.

A ghost setting **dominates** the baseline, every strand simulated by FTL at dt 1/60 s, when it
is admitted, takes at most 1/3 of the baseline's ms per frame and has no more motion error.

    hair_sim_eval dominance --ghosts 4096 16384 [--motion FILE] [--threads 1 2]
"""
from dataclasses import dataclass, field, fields, replace
import math
import time
from typing import Callable, Dict, List

import numba
import numpy as np

from hair_tracking.core.metrics import position_error
from hair_tracking.core.scene import Scene
from hair_tracking.core.transforms import quat_angle
from hair_tracking.evaluation.accuracy import (HeadSchedule, record_reference, run_frames,
                                               Scorer, Trajectory)
from hair_tracking.evaluation.methods import (BlendTracking, FullSim, GhostTracking,
                                              TurnTracking, Workload)

#: Substeps per 60 Hz frame of the same-solver reference (FTL at dt 1/960 s).
REFERENCE_SUBSTEPS = 16
#: Admission: largest stretch [1] ...
MAX_STRETCH = 0.01
#: ... and the share of the baseline's time a dominating setting may take.
TIME_SHARE = 1.0 / 3.0
BASELINE = 'full FTL dt 1/60'


@dataclass
class Candidate:
    """One method of the study: a name and how to build it from (workload, scene)."""

    name: str
    build: Callable[[Workload, Scene], object]
    dt: float
    ghost: bool = True


def _ftl(scene: Scene, dt: float) -> Scene:
    return scene.with_changes(solver__type='ftl', solver__dt=dt, solver__max_substeps=10_000)


def candidates(scene: Scene, ratio: int = 16) -> List[Candidate]:
    """The baseline, the paper's tracker once per frame, the blend tracker with guides at
    three substeps and with one guide a ghost (TressFX's follow hair) at two substeps, and the
    turn tracker with guides at two substeps."""
    out = [Candidate(BASELINE, lambda w, s: FullSim(BASELINE, w, _ftl(s, 1 / 60)), 1 / 60,
                     ghost=False)]
    for sub in (1, 2, 4):
        dt = 1.0 / (60 * sub)
        name = f'blend 1:{ratio}, guides dt 1/{60 * sub}'
        out.append(Candidate(name, lambda w, s, dt=dt, name=name:
                             BlendTracking(name, w, _ftl(s, dt), ratio), dt))
    name = f'blend 1:{ratio} one guide, guides dt 1/120'
    out.append(Candidate(name, lambda w, s, name=name:
                         BlendTracking(name, w, _ftl(s, 1 / 120), ratio, k=1), 1 / 120))
    for sub in (1, 2):
        dt = 1.0 / (60 * sub)
        name = f'turn 1:{ratio}, guides dt 1/{60 * sub}'
        out.append(Candidate(name, lambda w, s, dt=dt, name=name:
                             TurnTracking(name, w, _ftl(s, dt), ratio), dt))
    name = f'paper 1:{ratio} once per frame, guides dt 1/240'
    out.append(Candidate(name, lambda w, s, name=name: GhostTracking(
        name, w, _ftl(s, 1 / 240).with_changes(tracking__every_substep=False), ratio),
        1 / 240))
    return out


@dataclass
class Row:
    name: str
    ghost: bool
    frame_ms: List[float] = field(default_factory=list)      # median of each timing run
    motion_err: float = math.nan                             # % L
    settled_err: float = math.nan                            # % L
    stretch: float = math.nan                                # [1]
    penetration_mm: float = math.nan
    body_mm: float = math.nan                                # deepest in the bare bust
    admitted: bool = False
    dominates: bool = False

    @property
    def ms(self) -> float:
        return float(np.median(self.frame_ms)) if self.frame_ms else math.nan


def first_moving_frame(schedule: HeadSchedule, tol: float = 1e-3) -> int:
    """The first frame whose head pose differs from the start by more than ``tol`` metres or
    radians (0 if the head moves in the first frame)."""
    start = schedule.start()
    for j, poses in enumerate(schedule.poses(1)):
        h = poses[-1]
        turn = quat_angle(h.quaternion, start.quaternion)
        if np.linalg.norm(h.position - start.position) > tol or turn > tol:
            return j
    return schedule.frames


def study(workload: Workload, trajectory: Trajectory, duration_s: float, repeats: int = 2,
          timing_frames: int = 120, thread_counts=None, log=print) -> List[Dict]:
    """Score every :func:`candidates` method on one motion once, then time them on each of
    ``thread_counts`` (numba threads; default: as set); returns one report dict per thread
    count (the errors do not depend on it)."""
    scene = workload.scene
    schedule = HeadSchedule(trajectory.motion, duration_s=duration_s)
    ref_scene = _ftl(scene, 1.0 / (60 * REFERENCE_SUBSTEPS))
    ref_frames, ref_settled, _ = record_reference(workload, schedule, ref_scene, log=log)
    scorer = Scorer(workload, ref_frames, ref_settled)
    moving = first_moving_frame(schedule)
    margin_mm = 1e3 * float(scene.collider.margin) if scene.collider.shape != 'none' else 0.0
    cands = candidates(scene)
    body = scorer.colliders.extra or scene.body.bust
    body_margin_mm = 1e3 * float(scene.body.margin) if body else 0.0
    rows = {c.name: Row(c.name, c.ghost, stretch=0.0, penetration_mm=0.0, body_mm=0.0)
            for c in cands}
    for c in cands:                                           # accuracy runs
        method = c.build(workload, scene)
        motion = []
        x0 = np.empty(workload.ghost_rest.shape)
        row = rows[c.name]

        def score(j, x, head, row=row, x0=x0, motion=motion):
            if j < 0:
                x0[...] = x
                row.settled_err = 100.0 * position_error(x, ref_settled,
                                                         workload.strand_length)[0]
                return
            m = scorer.frame(j, x, head, x0)
            if j >= moving:
                motion.append(m['motion'])
            row.stretch = max(row.stretch, m['stretch'])
            row.penetration_mm = max(row.penetration_mm, 1e3 * m['pen'])
            row.body_mm = max(row.body_mm, 1e3 * m['pen_body'])
        t0 = time.perf_counter()
        run_frames(method, schedule, schedule.frames, score, scene.solver.settle_time,
                   scene.solver.settle_speed)
        row.motion_err = 100.0 * float(np.sqrt(np.mean(np.square(motion)))) if motion \
            else math.nan
        log(f'    {c.name}: motion error {row.motion_err:.2f} % L, stretch '
            f'{100 * row.stretch:.3f} %, penetration {row.penetration_mm:.2f} mm, bust '
            f'{row.body_mm:.2f} mm '
            f'({time.perf_counter() - t0:.1f} s)')
    frames = min(timing_frames, schedule.frames)
    reports = []
    for threads in thread_counts or [numba.get_num_threads()]:
        numba.set_num_threads(threads)
        timed = {c.name: replace(rows[c.name], frame_ms=[]) for c in cands}
        built = {c.name: c.build(workload, scene) for c in cands}
        for _ in range(repeats):                              # timing runs, interleaved
            for c in cands:
                secs = run_frames(built[c.name], schedule, frames, None, 0.1)
                timed[c.name].frame_ms.append(1e3 * float(np.median(secs)))
        base = timed[BASELINE]
        for r in timed.values():
            r.admitted = r.stretch <= MAX_STRETCH and r.penetration_mm <= margin_mm + 1e-6 \
                and r.body_mm <= body_margin_mm + 1e-6
            r.dominates = r.ghost and r.admitted and r.ms <= TIME_SHARE * base.ms and \
                r.motion_err <= base.motion_err
        reports.append({'motion': trajectory.name, 'description': trajectory.description,
                        'strands': workload.count, 'frames': schedule.frames,
                        'moving_from': moving, 'threads': threads,
                        'reference': f'FTL dt 1/{60 * REFERENCE_SUBSTEPS} s, every strand',
                        'margin_mm': margin_mm, 'body_margin_mm': body_margin_mm,
                        'nodes': workload.ghost_rest.shape[1], 'body': bool(body),
                        'rows': list(timed.values())})
    return reports


def markdown(report: Dict, threads: int) -> str:
    """The report of :func:`study` as a Markdown table."""
    base = next(r for r in report['rows'] if r.name == BASELINE)
    body = report.get('body', False)
    lines = [f"#### {report['motion']}, {report['strands']} strands x "
             f"{report.get('nodes', 16)} nodes, {threads} thread(s)"
             + (', on the bust' if body else ''),
             '',
             f"{report['description']}; {report['frames']} frames at 60 Hz, the head moves from "
             f"frame {report['moving_from']}; reference: {report['reference']}.",
             '',
             '| method | ms/frame (median, min) | share of baseline | motion error [% L] | '
             'settled error [% L] | max stretch [%] | penetration [mm] | '
             + ('in the bust [mm] | ' if body else '') + 'dominates |',
             '|---|---:|---:|---:|---:|---:|---:|' + ('---:|' if body else '') + ':---:|']
    for r in report['rows']:
        share = r.ms / base.ms if base.ms > 0 else math.nan
        mark = 'yes' if r.dominates else ('' if not r.ghost else
                                          ('no' if r.admitted else 'not admitted'))
        lines.append(f'| {r.name} | {r.ms:.2f}, {min(r.frame_ms):.2f} | {share:.2f} | '
                     f'{r.motion_err:.2f} | {r.settled_err:.2f} | {100 * r.stretch:.3f} | '
                     f'{r.penetration_mm:.2f} | '
                     + (f'{r.body_mm:.2f} | ' if body else '') + f'{mark} |')
    return '\n'.join(lines) + '\n'


def family(name: str) -> str:
    """The kind of a method from its name: ``full``, ``blend``, ``turn`` or ``paper``."""
    return name.split()[0]


def summary(reports: List[Dict]) -> str:
    """The headline of a study -- in how many cases (a motion, a size, a thread count) some
    ghost setting dominates the baseline, and how many of them each kind of tracker wins --
    and a table of each case's cheapest dominating setting."""
    kinds = list(dict.fromkeys(family(r.name) for rep in reports for r in rep['rows']
                               if r.ghost))
    wins = dict.fromkeys(kinds, 0)
    lines = ['| motion | strands | threads | baseline ms, motion error [% L] | cheapest '
             'dominating setting | ms | share of baseline | motion error [% L] |',
             '|---|---:|---:|---|---|---:|---:|---:|']
    dominated = 0
    for rep in reports:
        base = next(r for r in rep['rows'] if r.name == BASELINE)
        winners = [r for r in rep['rows'] if r.dominates]
        for kind in {family(r.name) for r in winners}:
            wins[kind] += 1
        cells = '| - | | | |'
        if winners:
            dominated += 1
            best = min(winners, key=lambda r: r.ms)
            cells = (f'| {best.name} | {best.ms:.2f} | {best.ms / base.ms:.2f} | '
                     f'{best.motion_err:.2f} |')
        lines.append(f"| {rep['motion']} | {rep['strands']} | {rep['threads']} | "
                     f'{base.ms:.2f}, {base.motion_err:.2f} ' + cells)
    head = (f'**A ghost setting dominates the baseline in {dominated}/{len(reports)} cases**; '
            'cases won by each tracker: '
            + ', '.join(f'{kind} {n}/{len(reports)}' for kind, n in wins.items()) + '.')
    return '\n'.join([head, ''] + lines) + '\n'


def rows_from_json(report: Dict) -> Dict:
    """A report as :func:`study` returns it, from its ``dominance.json`` form."""
    names = {f.name for f in fields(Row)}
    return {**report, 'rows': [Row(**{k: v for k, v in r.items() if k in names})
                               for r in report['rows']]}


def plot(reports: List[Dict], path: str) -> str:
    """Every ghost setting of every report as a point: its share of the baseline's time against
    its motion error relative to the baseline's; a point in the shaded box (time <= 1/3, error
    <= 1) dominates (drawn with a black edge).  One marker per thread count, one colour per
    method.  Writes a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=110)
    ax.add_patch(plt.Rectangle((0.0, 0.0), TIME_SHARE, 1.0, color='#d8f0d8', zorder=0))
    names = [r.name for r in reports[0]['rows'] if r.ghost] if reports else []
    colours = plt.cm.viridis(np.linspace(0.0, 0.85, max(1, len(names))))
    markers = {1: 'o', 2: 's'}
    seen = set()
    lowest = 1.0
    for rep in reports:
        base = next(r for r in rep['rows'] if r.name == BASELINE)
        for r in rep['rows']:
            if not r.ghost or not base.ms > 0 or not base.motion_err > 0:
                continue
            i = names.index(r.name)
            label = r.name if r.name not in seen else None
            seen.add(r.name)
            lowest = min(lowest, r.motion_err / base.motion_err)
            ax.scatter(r.ms / base.ms, r.motion_err / base.motion_err, color=colours[i],
                       marker=markers.get(rep.get('threads'), '^'), s=28, label=label,
                       edgecolors='k' if r.dominates else 'none', linewidths=0.6)
    ax.axvline(TIME_SHARE, color='g', lw=0.8)
    ax.axhline(1.0, color='g', lw=0.8)
    ax.set_xlabel('ms per frame / full FTL dt 1/60 (circles 1 thread, squares 2)')
    ax.set_ylabel('motion error / full FTL dt 1/60')
    ax.set_xlim(left=0.0)
    ax.set_ylim(bottom=max(0.0, lowest - 0.1))
    ax.set_title('Ghost settings against every strand simulated (shaded: dominates)',
                 fontsize=10)
    ax.legend(fontsize=7, loc='upper right')
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path
