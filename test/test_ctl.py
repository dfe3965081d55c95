"""hair_sim_ctl against a running hair_sim node over DDS: the ros2 param / reset habits for
users without ros2cli."""
import os
import signal
import subprocess
import sys
import time

import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOMAIN = 77


def _env():
    path = os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')]))
    return dict(os.environ, ROS_DOMAIN_ID=str(DOMAIN), PYTHONUNBUFFERED='1', PYTHONPATH=path)


@pytest.fixture(scope='module')
def node():
    proc = subprocess.Popen(
        [sys.executable, '-m', 'hair_tracking.ros.node', '--ros-args', '-p', 'groom.guides:=3',
         '-p', 'groom.ghosts_per_guide:=2', '-p', 'solver.settle_time:=0.0'],
        env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line or 'ready:' in line:
            break
    yield proc
    proc.send_signal(signal.SIGINT)
    try:
        proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()


def ctl(*args):
    out = subprocess.run([sys.executable, '-m', 'hair_tracking.ros.ctl', '--timeout', '30',
                          *args], env=_env(), capture_output=True, text=True, timeout=120)
    return out.returncode, out.stdout, out.stderr


def test_list_get_set_and_refusals(node):
    rc, out, err = ctl('param', 'list', '/hair_sim')
    assert rc == 0, err
    assert 'solver.type' in out.split() and 'groom.guides' in out.split()
    assert ctl('param', 'get', '/hair_sim', 'solver.type')[1].strip() == 'ftl'
    rc, out, err = ctl('param', 'set', '/hair_sim', 'damping', '2.5')
    assert rc == 0 and 'set damping = 2.5' in out, err
    assert ctl('param', 'get', '/hair_sim', 'damping')[1].strip() == '2.5'
    rc, out, err = ctl('param', 'set', '/hair_sim', 'damping', '2')       # an integer ...
    assert rc == 0, err
    assert ctl('param', 'get', '/hair_sim', 'damping')[1].strip() == '2.0'   # ... taken as 2.0
    rc, out, err = ctl('param', 'set', '/hair_sim', 'solver.type', 'rk4')
    assert rc == 1 and 'setting solver.type failed' in err and 'ftl' in err
    rc, out, err = ctl('param', 'set', '/hair_sim', 'groom.guides', '0')  # out of range
    assert rc == 1 and err == ('hair_sim_ctl: setting groom.guides failed: groom.guides: 0 is '
                               'outside the allowed range [1, 100000]\n')


def test_unknown_names_are_one_line_with_the_closest_ones(node):
    rc, out, err = ctl('param', 'set', '/hair_sim', 'groom.gost_nodes', '4')
    assert (rc, out) == (2, '')
    assert err == ("hair_sim_ctl: unknown parameter 'groom.gost_nodes' of /hair_sim; did you "
                   "mean 'groom.ghost_nodes'?\n")
    rc, out, err = ctl('param', 'get', '/hair_sim', 'no.such.thing')
    assert rc == 2
    assert err == ("hair_sim_ctl: unknown parameter 'no.such.thing' of /hair_sim "
                   "(hair_sim_ctl param list /hair_sim lists them)\n")
    assert ctl('param', 'get', '/hair_sim', 'groom.ghost_nodes')[1].strip() == '16'


def test_dump_is_a_params_file_and_reset_answers(node):
    rc, out, err = ctl('param', 'dump', '/hair_sim')
    assert rc == 0, err
    dumped = yaml.safe_load(out)['/hair_sim']['ros__parameters']
    assert dumped['solver.type'] == 'ftl' and dumped['groom.guides'] == 3
    rc, out, err = ctl('reset', '/hair_sim')
    assert rc == 0, err
    rc, out, err = ctl('--timeout', '1', 'param', 'list', '/nobody')
    assert rc == 1 and 'no parameter services' in err
