"""Package-level set-up: numba's cache directory keyed by the sources."""
import os
import subprocess
import sys

import hair_tracking

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _cache_dir_in_fresh_python(code, **env):
    clean = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
    clean.update(env)
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, env=clean, check=True,
                         capture_output=True, text=True, timeout=120)
    return out.stdout.strip()


def test_numba_cache_is_keyed_by_the_source_hash():
    key = hair_tracking.source_hash()
    assert len(key) == 12 and int(key, 16) >= 0
    got = _cache_dir_in_fresh_python(
        'import hair_tracking, numba; print(numba.config.CACHE_DIR)')
    assert got.endswith(f'numba-{key}') and got == hair_tracking.numba_cache_dir()
    # numba imported first: its configuration is updated all the same
    got = _cache_dir_in_fresh_python(
        'import numba, hair_tracking; print(numba.config.CACHE_DIR)')
    assert got.endswith(f'numba-{key}')
    # a cache directory chosen by the user is kept
    got = _cache_dir_in_fresh_python(
        'import hair_tracking, numba; print(numba.config.CACHE_DIR)',
        NUMBA_CACHE_DIR='/tmp/hair_tracking_user_cache')
    assert got == '/tmp/hair_tracking_user_cache'


def _console_scripts():
    """(name, module) of every executable setup.py installs."""
    import re
    with open(os.path.join(ROOT, 'setup.py'), encoding='utf-8') as f:
        text = f.read()
    return re.findall(r"'(hair_sim_\w+) = ([\w.]+):main'", text)


def test_every_executable_prints_help_and_exits_0():
    scripts = _console_scripts()
    assert {name for name, _ in scripts} >= {'hair_sim_node', 'hair_sim_bag', 'hair_sim_eval',
                                             'hair_sim_demo', 'hair_sim_warmup'}
    for name, module in scripts + [('live demo', 'hair_tracking.ros.live_demo')]:
        out = subprocess.run([sys.executable, '-m', module, '--help'], cwd=ROOT,
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, (name, out.stderr)
        assert out.stdout.startswith('usage:'), (name, out.stdout)
        assert 'ready' not in out.stdout + out.stderr, name        # nothing was started


def test_the_license_named_in_package_xml_is_there():
    with open(os.path.join(ROOT, 'package.xml'), encoding='utf-8') as f:
        assert '<license>MIT</license>' in f.read()
    with open(os.path.join(ROOT, 'LICENSE'), encoding='utf-8') as f:
        assert f.readline().strip() == 'MIT License'
