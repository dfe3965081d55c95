"""Where, when and how a measured report was made: the header of every report under
``docs/results``.

The evaluation (``hair_sim_eval``) and the benchmarks (``scripts/bench*.py``) start each report
they write with the same record: the machine (CPU model, logical CPUs, threads used, Python,
numpy and numba), the date (UTC) and the command that reproduces it.  JSON reports hold it as
their first key, ``provenance``; Markdown reports as the lines of :func:`markdown_lines` under
their title.  A figure the documents quote is read from such a report, so its machine, date and
command are always at hand.
"""
import datetime
import os
import platform
import shlex
from typing import List, Optional, Sequence


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what ``platform`` knows."""
    try:
        with open('/proc/cpuinfo', encoding='utf-8') as f:
            for line in f:
                if line.startswith('model name'):
                    return line.split(':', 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def command_line(program: str, argv: Sequence[str]) -> str:
    """``program`` and its arguments as a shell would take them back."""
    return ' '.join([program] + [shlex.quote(str(a)) for a in argv])


def provenance(command: str, threads: Optional[int] = None) -> dict:
    """The record of this run: date, machine and ``command``; ``threads`` the threads it used."""
    import numba
    import numpy
    machine = {'cpu': cpu_model(), 'logical_cpus': os.cpu_count()}
    if threads is not None:
        machine['threads'] = int(threads)
    return {'date': datetime.datetime.now(datetime.timezone.utc).date().isoformat(),
            'machine': machine,
            'software': {'python': platform.python_version(), 'numpy': numpy.__version__,
                         'numba': numba.__version__},
            'command': command}


def machine_text(record: dict) -> str:
    """One line of the machine: ``<cpu>, <n> logical CPUs, <t> thread(s) used; Python ...``."""
    m, s = record['machine'], record.get('software', {})
    text = f"{m['cpu']}, {m['logical_cpus']} logical CPUs"
    if 'threads' in m:
        text += f", {m['threads']} thread(s) used"
    if s:
        text += '; ' + ', '.join(f'{name.capitalize() if name == "python" else name} {v}'
                                 for name, v in s.items())
    return text


def markdown_lines(record: dict) -> List[str]:
    """The header lines of a Markdown report (a list, a blank line after it)."""
    return [f"- Date: {record['date']}", f'- Machine: {machine_text(record)}',
            f"- Command: `{record['command']}`", '']


def write_reports(record: dict, json_path: Optional[str] = None, figures: Optional[dict] = None,
                  md_path: Optional[str] = None, title: str = '',
                  body: Sequence[str] = ()) -> None:
    """A script's reports: ``figures`` as JSON beside its ``provenance`` record at
    ``json_path``, and a Markdown page at ``md_path``: ``# title``, the record's header lines
    (:func:`markdown_lines`), then ``body`` (lines); each only when its path is given."""
    import json
    if json_path:
        with open(json_path, 'w', encoding='utf-8') as f:
            json.dump({'provenance': record, **(figures or {})}, f, indent=1)
    if md_path:
        with open(md_path, 'w', encoding='utf-8') as f:
            f.write('\n'.join([f'# {title}', ''] + markdown_lines(record) + list(body)) + '\n')
