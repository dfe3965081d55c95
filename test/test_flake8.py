"""The code base is flake8-clean (max line length 99, see setup.cfg)."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_flake8_clean():
    targets = [p for p in ('hair_tracking', 'msg_adapters', 'test', 'scripts', 'launch',
                           'setup.py')
               if os.path.exists(os.path.join(ROOT, p))]
    proc = subprocess.run([sys.executable, '-m', 'flake8', *targets], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, 'flake8 found problems:\n' + proc.stdout + proc.stderr
