#!/usr/bin/env python3
"""What each process setting of the executables buys (docs/node.md, "Process settings"): each
default against its alternative, written as a Markdown report that starts with its provenance.

    python scripts/bench_process_settings.py --md docs/results/process_settings.md [--runs N]

Every run is a fresh process; the settings of a case alternate run by run, so a change in the
machine's load falls on all of them.  The cases:

* ``--malloc-retain-mb`` 256 against 0: ``scripts/bench_latency.py --ghosts 100000 --seconds 4
  --modes on_pose`` (32 MB clouds), six runs of each;
* ``--omp-wait-policy`` passive against environment: the same at 10 k ghosts, 6 s, three runs;
* the heap freeze against ``--no-gc-freeze``: the same at 10 k ghosts, three runs; measured is
  one full collection bench_latency makes in the node's process after the stream;
* ``hair_sim_bag run`` of the bundled walk with each ``--omp-wait-policy``, four runs: the
  summary's time per pose.

The report gives the median over the runs of each case's figures (the full collection: its
range over the runs).
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from hair_tracking.evaluation.provenance import command_line, markdown_lines  # noqa: E402
from hair_tracking.evaluation.provenance import provenance  # noqa: E402

LATENCY = [sys.executable, os.path.join(ROOT, 'scripts', 'bench_latency.py'), '--modes',
           'on_pose']
BAG = [sys.executable, '-c', 'import sys; from hair_tracking.executable import hair_sim_bag; '
       'sys.argv[0] = "hair_sim_bag"; sys.exit(hair_sim_bag())']
#: (option, its default, the alternative, case arguments, runs of each)
LATENCY_CASES = (
    ('--malloc-retain-mb', '256', '0', ['--ghosts', '100000', '--seconds', '4'], 6),
    ('--omp-wait-policy', 'passive', 'environment', ['--ghosts', '10000', '--seconds', '6'], 3),
    ('--no-gc-freeze', 'freeze', 'no freeze', ['--ghosts', '10000', '--seconds', '6'], 3),
)
POLICIES = ('passive', 'active', 'environment')
BAG_RUNS = 4


def _env():
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    return dict(os.environ, PYTHONPATH=path, PYTHONUNBUFFERED='1')


def latency_run(case_args, setting, folder):
    """One bench_latency run; -> its case's figures [ms]."""
    out = os.path.join(folder, 'latency.json')
    subprocess.run(LATENCY + case_args + setting + ['--json', out], check=True, env=_env(),
                   stdout=subprocess.DEVNULL)
    with open(out, encoding='utf-8') as f:
        r = json.load(f)['results'][0]
    return {'publish': r['publish']['median_ms'], 'latency': r['latency']['median_ms'],
            'p99': r['latency']['p99_ms'], 'full_gc': r['gc']['full_ms']}


def bag_run(policy, folder):
    """One ``hair_sim_bag run`` of the bundled walk; -> its time per pose [ms]."""
    out = os.path.join(folder, 'walk.mcap')
    done = subprocess.run(BAG + ['run', '-o', out, '-q', '--overwrite', '--omp-wait-policy',
                                 policy], check=True, env=_env(), capture_output=True,
                          text=True)
    return float(re.search(r'= ([0-9.]+) ms per pose', done.stdout).group(1))


def setting_args(option, value):
    if option == '--no-gc-freeze':
        return ['--no-gc-freeze'] if value == 'no freeze' else []
    return [option, value]


def measure(runs=None):
    """Every case, alternating its settings; -> the report's rows."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for option, default, other, case_args, n in LATENCY_CASES:
            got = {default: [], other: []}
            for _ in range(runs or n):
                for value in (default, other):
                    got[value].append(latency_run(case_args, setting_args(option, value),
                                                  folder))
            case = f'`bench_latency.py {" ".join(case_args)} --modes on_pose`, {runs or n} runs'
            keys = (('full_gc', 'one full collection after the stream [ms], range'),) \
                if option == '--no-gc-freeze' else (
                    ('publish', 'node publish median [ms]'),
                    ('latency', 'pose -> cloud latency median [ms]'),
                    ('p99', 'pose -> cloud latency p99 [ms]'))
            for key, what in keys:
                cells = []
                for value in (default, other):
                    v = [r[key] for r in got[value]]
                    cells.append(f'{min(v):.3g}-{max(v):.3g}' if key == 'full_gc'
                                 else f'{statistics.median(v):.3g}')
                rows.append((f'`{option}`', case, what, f'{default}: {cells[0]}',
                             f'{other}: {cells[1]}'))
        per_pose = {p: [] for p in POLICIES}
        for _ in range(runs or BAG_RUNS):
            for policy in POLICIES:
                per_pose[policy].append(bag_run(policy, folder))
        med = {p: f'{p}: {statistics.median(v):.3g}' for p, v in per_pose.items()}
        rows.append(('`--omp-wait-policy`', f'`hair_sim_bag run` of the bundled walk, '
                     f'{runs or BAG_RUNS} runs', 'time per pose [ms]', med['passive'],
                     f'{med["active"]}; {med["environment"]}'))
    return rows


def report(rows, record) -> str:
    lines = ['# Process settings: what each default buys', ''] + markdown_lines(record) + [
        'Each default of the executables\' process settings against its alternative, in '
        'alternating runs (each a fresh process); medians over the runs. What the settings do: '
        '[docs/node.md](../node.md#process-settings).', '',
        '| option | case | figure | default | alternative |', '|---|---|---|---:|---:|']
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines) + '\n'


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--md', metavar='PATH', required=True, help='the report to write')
    ap.add_argument('--runs', type=int, help='runs of every setting of every case (default: '
                                             'those of the module doc)')
    args = ap.parse_args(argv)
    record = provenance(command_line('python scripts/bench_process_settings.py',
                                     sys.argv[1:] if argv is None else argv))
    text = report(measure(args.runs), record)
    with open(args.md, 'w', encoding='utf-8') as f:
        f.write(text)
    print(text, end='')
    return 0


if __name__ == '__main__':
    sys.exit(main())
