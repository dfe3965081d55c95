"""The installed package: every console script answers --help, and the licence is named."""
import os
import subprocess
import sys

from console_scripts import console_scripts

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_every_executable_prints_help_and_exits_0():
    scripts = [(name, target.partition(':')[2]) for name, target in console_scripts().items()]
    assert {name for name, _ in scripts} >= {'hair_sim_node', 'hair_sim_bag', 'hair_sim_eval',
                                             'hair_sim_demo', 'hair_sim_warmup'}
    commands = [[sys.executable, '-c', f'import sys; from hair_tracking.executable import {fn}; '
                 f'sys.argv[0] = {name!r}; sys.exit({fn}())', '--help']
                for name, fn in scripts]
    commands.append([sys.executable, '-m', 'hair_tracking.ros.live_demo', '--help'])
    for cmd in commands:
        out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, (cmd, out.stderr)
        assert out.stdout.startswith('usage:'), (cmd, out.stdout)
        assert 'ready' not in out.stdout + out.stderr, cmd        # nothing was started


def test_the_license_named_in_package_xml_is_there():
    with open(os.path.join(ROOT, 'package.xml'), encoding='utf-8') as f:
        assert '<license>MIT</license>' in f.read()
    with open(os.path.join(ROOT, 'LICENSE'), encoding='utf-8') as f:
        assert f.readline().strip() == 'MIT License'
