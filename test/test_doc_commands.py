"""The documents' fast command blocks run as written.

A ```bash block of README.md or docs/*.md that follows the line ``<!-- test: fast -->`` is
run here (docs/architecture.md, "Documented commands"): the marked blocks of one document in
order, by ``bash -e -o pipefail``, in one empty temporary folder (so a block may use what an
earlier one of the same document wrote) that holds links to the repository's ``config/``,
``hair_tracking/`` and ``scripts/``, so the repository-relative inputs a document names
resolve; with the venv's executables and ``scripts/`` on PATH, this checkout first on
PYTHONPATH, and the tests' ROS environment (``ROS_PYTHON_CHECK_FIELDS=1``, discovery on this
machine, domain 95).  A block that fails fails the test with its file, line and output.
"""
import glob
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARKER = '<!-- test: fast -->'
DOMAIN = 95
#: Repository folders linked into the temporary folder (read as inputs by the blocks).
LINKED = ('config', 'hair_tracking', 'scripts')
TIMEOUT_S = 600


def documents():
    return ['README.md'] + sorted(os.path.relpath(p, ROOT)
                                  for p in glob.glob(os.path.join(ROOT, 'docs', '*.md')))


def marked_blocks(rel):
    """``(line, text)`` of every marked block of the document ``rel``: the line of its first
    command, and the commands.  A marker not followed by a ```bash block is an error."""
    with open(os.path.join(ROOT, rel), encoding='utf-8') as f:
        lines = f.read().splitlines()
    blocks = []
    for i, line in enumerate(lines):
        if line.strip() != MARKER:
            continue
        if i + 1 >= len(lines) or lines[i + 1].strip() != '```bash':
            raise AssertionError(f'{rel}:{i + 1}: {MARKER} must be followed by a ```bash block')
        end = next((j for j in range(i + 2, len(lines)) if lines[j].startswith('```')), None)
        if end is None:
            raise AssertionError(f'{rel}:{i + 2}: the marked block is not closed')
        blocks.append((i + 3, '\n'.join(lines[i + 2:end])))
    return blocks


MARKED = [rel for rel in documents() if marked_blocks(rel)]


def _env():
    env = dict(os.environ, ROS_PYTHON_CHECK_FIELDS='1', ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED='1')
    env['PATH'] = os.pathsep.join([os.path.dirname(sys.executable),
                                   os.path.join(ROOT, 'scripts'), env.get('PATH', '')])
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [ROOT, env.get('PYTHONPATH')]))
    return env


def test_readme_and_docs_have_marked_blocks():
    assert 'README.md' in MARKED
    assert any(rel.startswith('docs') for rel in MARKED)


@pytest.mark.parametrize('rel', MARKED)
def test_marked_blocks_run(rel, tmp_path):
    for name in LINKED:
        os.symlink(os.path.join(ROOT, name), tmp_path / name)
    for line, text in marked_blocks(rel):
        try:
            out = subprocess.run(['bash', '-e', '-o', 'pipefail', '-c', text], cwd=tmp_path,
                                 env=_env(), stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True, timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired as e:
            seen = (e.output or b'').decode(errors='replace')      # bytes, whatever text= says
            pytest.fail(f'{rel}:{line}: still running after {TIMEOUT_S} s\n{text}\n'
                        f'--- output ---\n{seen[-4000:]}')
        if out.returncode != 0:
            pytest.fail(f'{rel}:{line}: exit status {out.returncode}\n{text}\n'
                        f'--- output ---\n{out.stdout[-4000:]}')
