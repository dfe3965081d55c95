"""Every measured report says where, when and how it was made: the provenance record the
evaluation and the benchmarks write (hair_tracking/evaluation/provenance.py), and the reports
committed under docs/results."""
import glob
import json
import os
import re

from hair_tracking.evaluation.provenance import (command_line, machine_text, markdown_lines,
                                                 provenance)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RESULTS = os.path.join(ROOT, 'docs', 'results')
DATE = re.compile(r'^\d{4}-\d{2}-\d{2}$')


def _check(record, where):
    assert DATE.match(record['date']), where
    assert record['machine']['cpu'] and record['machine']['logical_cpus'] >= 1, where
    assert record['command'].startswith(('hair_sim_', 'python scripts/', 'make ')), where


def test_the_record_of_this_run():
    cmd = command_line('python scripts/bench_frame.py', ['--ghosts', '10', '--json', 'a b.json'])
    assert cmd == "python scripts/bench_frame.py --ghosts 10 --json 'a b.json'"
    record = provenance(cmd, threads=2)
    _check(record, 'provenance()')
    assert record['machine']['threads'] == 2
    assert record['machine']['logical_cpus'] == os.cpu_count()
    assert set(record['software']) == {'python', 'numpy', 'numba'}
    text = machine_text(record)
    assert f"{os.cpu_count()} logical CPUs, 2 thread(s) used; Python " in text
    lines = markdown_lines(record)
    assert lines == [f"- Date: {record['date']}", f'- Machine: {text}', f'- Command: `{cmd}`', '']
    assert 'threads' not in provenance(cmd)['machine']


def test_every_committed_report_has_its_provenance():
    reports = sorted(p for p in glob.glob(os.path.join(RESULTS, '**'), recursive=True)
                     if os.path.isfile(p))
    assert reports
    for path in reports:
        name = os.path.relpath(path, RESULTS)
        stem, ext = os.path.splitext(name)
        if ext == '.json':
            with open(path, encoding='utf-8') as f:
                data = json.load(f)
            assert next(iter(data)) == 'provenance', name
            _check(data['provenance'], name)
        elif ext == '.md':
            with open(path, encoding='utf-8') as f:
                head = f.read().split('\n')[:8]
            date, machine, command = (next((ln for ln in head if ln.startswith(f'- {key}: ')),
                                           None) for key in ('Date', 'Machine', 'Command'))
            assert date and machine and command, f'{name}: no provenance under its title'
            assert DATE.match(date[len('- Date: '):]), name
            _check({'date': date[len('- Date: '):], 'command': command[len('- Command: `'):-1],
                    'machine': {'cpu': machine, 'logical_cpus': 1}}, name)
        else:                           # a table (CSV) whose report says how it was made
            assert os.path.isfile(os.path.join(RESULTS, stem + '.md')), name


def test_the_documents_link_reports_that_exist():
    """README.md and docs/*.md quote a report's headline with a link to it."""
    docs = [os.path.join(ROOT, 'README.md')] + glob.glob(os.path.join(ROOT, 'docs', '*.md'))
    linked = set()
    for path in docs:
        with open(path, encoding='utf-8') as f:
            for target in re.findall(r'\]\(((?:docs/)?results/[^)#]+)', f.read()):
                full = os.path.normpath(os.path.join(os.path.dirname(path), target))
                assert os.path.isfile(full), f'{os.path.basename(path)} links {target}'
                linked.add(os.path.basename(full))
    assert {'dominance.md', 'stability.md', 'bench_blend.json', 'bench_latency.json'} <= linked
