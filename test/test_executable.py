"""What every executable's main() does (hair_tracking.executable): numba's cache folder, the
process settings and their options, the console entry points, and a warm-up that leaves the node
nothing to compile.

Each process setting is tried in a fresh interpreter: it changes the whole process, as an
executable's main() does.
"""
import argparse
import os
import subprocess
import sys

import pytest

from console_scripts import console_scripts
from node_process import until_ready_then_ctrl_c
from hair_tracking import executable

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_python(code: str, *args, **env) -> str:
    out = subprocess.run([sys.executable, '-c', code, *args], capture_output=True, text=True,
                         timeout=300, cwd=ROOT, env={**os.environ, **env})
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


# ==================================================================== numba's cache folder
def test_importing_the_package_changes_nothing_and_main_sets_the_cache_folder():
    """``import hair_tracking.executable`` (what a console script imports first) loads neither
    numba nor rclpy nor numpy and sets no variable; :func:`use_numba_cache` points numba at the
    folder of the source hash, before numba loads; a folder chosen by the user is kept."""
    code = '''
import os, sys
import hair_tracking, hair_tracking.executable as ex
loaded = sorted(m for m in ('numba', 'rclpy', 'numpy') if m in sys.modules)
print(loaded, os.environ.get('NUMBA_CACHE_DIR'))
ex.use_numba_cache()
import numba
print(numba.config.CACHE_DIR == ex.numba_cache_dir(), numba.config.CACHE_DIR)
'''
    clean = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, env=clean)
    assert out.returncode == 0, out.stderr
    first, second = out.stdout.strip().split('\n')
    assert first == '[] None'
    assert second.startswith('True ') and second.endswith(f'numba-{executable.source_hash()}')
    assert out.stderr == ''
    user = run_python('from hair_tracking import executable as ex; ex.use_numba_cache(); '
                      'import numba; print(numba.config.CACHE_DIR)',
                      NUMBA_CACHE_DIR='/tmp/hair_tracking_user_cache')
    assert user == '/tmp/hair_tracking_user_cache'


def test_numba_loaded_before_the_cache_folder_is_set_is_said():
    clean = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
    out = subprocess.run([sys.executable, '-c', 'import numba; from hair_tracking import '
                          'executable; executable.use_numba_cache()'], capture_output=True,
                         text=True, timeout=120, cwd=ROOT, env=clean)
    assert out.returncode == 0, out.stderr
    assert 'numba was loaded before its cache folder was set' in out.stderr


def test_make_demo_sets_the_cache_folder_before_numba_loads():
    """``make demo`` runs ``python -m hair_tracking.ros.live_demo``: its module imports no
    numba, so its ``main()`` sets the cache folder first and nothing warns."""
    clean = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
    code = ('import sys; import hair_tracking.ros.live_demo as d; loaded = "numba" in '
            'sys.modules; d.executable.use_numba_cache(); print(loaded)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=120, cwd=ROOT, env=clean)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'False' and out.stderr == ''


def test_every_console_script_is_an_entry_point_of_this_module():
    """Each sets the cache folder and the stop request up before its executable's imports."""
    entries = console_scripts()
    assert set(entries) == {'hair_sim_node', 'hair_sim_ghosts', 'hair_sim_bag', 'hair_sim_groom',
                            'hair_sim_eval', 'hair_sim_demo', 'hair_sim_warmup', 'hair_sim_ctl',
                            'hair_sim_view'}
    for name, target in entries.items():
        assert target == f'hair_tracking.executable:{name}'
        assert callable(getattr(executable, name))


# ==================================================================== process settings
def test_freeze_heap_collects_then_freezes_the_start_up_objects():
    """In a fresh interpreter: garbage made before the call is collected, every live object is
    frozen (so later full collections no longer walk them), and new garbage is still collected."""
    code = '''
import gc, weakref
from hair_tracking.executable import freeze_heap
class Cycle:
    pass
def make():
    a, b = Cycle(), Cycle()
    a.b, b.a = b, a
    return weakref.ref(a)
assert gc.get_freeze_count() == 0
before = make()
freeze_heap()
assert before() is None, 'garbage from before the freeze was not collected'
assert gc.get_freeze_count() > 1000, gc.get_freeze_count()
after = make()
gc.collect()
assert after() is None, 'garbage made after the freeze is not collected'
print('ok')
'''
    assert run_python(code) == 'ok'


HEAP = '''
import ctypes, sys
from hair_tracking.executable import retain_freed_memory


class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        'arena', 'ordblks', 'smblks', 'hblks', 'hblkhd', 'usmblks', 'fsmblks', 'uordblks',
        'fordblks', 'keepcost')]


libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] != '0':
    print(retain_freed_memory(int(sys.argv[1])), file=sys.stderr)
buf = bytearray(3 << 20)              # a cloud-sized message buffer
mapped = libc.mallinfo2().hblkhd      # bytes in mmap-ed chunks while it is alive
del buf
print(mapped >= 3 << 20, libc.mallinfo2().fordblks >= 3 << 20)
'''


def heap_use(megabytes: int):
    """(the 3 MB buffer was a separate mapping, its bytes stayed in the heap once freed)"""
    out = run_python(HEAP, str(megabytes), GLIBC_TUNABLES='')
    return tuple(v == 'True' for v in out.split())


@pytest.mark.skipif(executable._glibc() is None, reason='needs glibc')
def test_retained_memory_keeps_large_buffers_in_the_heap_for_reuse():
    """glibc's rule, read from its own counters (mallinfo2): by default a 3 MB buffer is a
    mapping of its own, unmapped when freed (the next one is faulted in again page by page);
    with freed memory retained it comes from the heap, which keeps its pages once it is freed."""
    assert heap_use(0) == (True, False)
    assert heap_use(256) == (False, True)


def test_retain_freed_memory_leaves_user_choices_alone(monkeypatch):
    assert 'defaults kept' in executable.retain_freed_memory(0)
    monkeypatch.setenv('GLIBC_TUNABLES', 'glibc.malloc.trim_threshold=1000')
    assert 'left as they are' in executable.retain_freed_memory(64)


WAIT_POLICY = '''
import os, sys
from hair_tracking.executable import set_omp_wait_policy
print(set_omp_wait_policy(sys.argv[1]))
print(os.environ.get('OMP_WAIT_POLICY'))
import numba
import numpy as np
from numba import njit, prange
@njit(parallel=True)
def bump(a):
    for i in prange(a.size):
        a[i] += 1.0
bump(np.zeros(10000))
print(numba.threading_layer())
os.environ.pop('OMP_WAIT_POLICY', None)
print(set_omp_wait_policy('passive'))
'''


def test_a_wait_policy_pins_numbas_threading_layer_to_openmp_before_its_threads_start():
    """In fresh interpreters: the policy reaches the environment and numba's threading layer is
    OpenMP's, the only one that reads it; once the threads run, nothing changes and the message
    says so."""
    env = {k: v for k, v in os.environ.items()
           if k not in ('OMP_WAIT_POLICY', 'NUMBA_THREADING_LAYER')}
    for policy in ('active', 'passive'):
        out = subprocess.run([sys.executable, '-c', WAIT_POLICY, policy], capture_output=True,
                             text=True, timeout=300, env=env, cwd=ROOT)
        assert out.returncode == 0, out.stderr
        first, value, layer, late = out.stdout.strip().split('\n')
        assert first == (f'OpenMP worker threads wait {policy} (numba threading layer omp, '
                         f'OMP_WAIT_POLICY={policy.upper()})')
        assert (value, layer) == (policy.upper(), 'omp')
        assert late == 'OpenMP threads already started: wait policy passive not applied'


def test_a_wait_policy_leaves_the_users_choices_alone(monkeypatch):
    """OMP_WAIT_POLICY or another threading layer in the environment win; nothing is set."""
    env = {k: v for k, v in os.environ.items() if k != 'OMP_WAIT_POLICY'}
    out = subprocess.run([sys.executable, '-c', WAIT_POLICY, 'active'], capture_output=True,
                         text=True, timeout=300, cwd=ROOT,
                         env={**env, 'NUMBA_THREADING_LAYER': 'workqueue'})
    assert out.returncode == 0, out.stderr
    first, value, layer, _ = out.stdout.strip().split('\n')
    assert first == ('NUMBA_THREADING_LAYER=workqueue from the environment kept: wait policy '
                     'active not applied')
    assert (value, layer) == ('None', 'workqueue')
    assert executable.set_omp_wait_policy('environment').startswith('OpenMP wait policy')
    monkeypatch.setenv('OMP_WAIT_POLICY', 'ACTIVE')
    assert executable.set_omp_wait_policy('passive') == \
        'OMP_WAIT_POLICY=ACTIVE from the environment kept'
    with pytest.raises(ValueError, match='omp_wait_policy must be one of'):
        executable.set_omp_wait_policy('spin')


def test_process_options_parse_and_apply():
    parser = argparse.ArgumentParser()
    executable.add_arguments(parser)
    args = parser.parse_args([])
    assert (args.malloc_retain_mb, args.omp_wait_policy, args.gc_freeze) == (256, 'passive', True)
    args = parser.parse_args(['--malloc-retain-mb', '0', '--omp-wait-policy', 'environment',
                              '--no-gc-freeze'])
    assert not args.gc_freeze
    assert executable.apply(args) == ['OpenMP wait policy: as the environment says',
                                      'malloc retention 0: glibc malloc defaults kept']
    args.malloc_retain_mb = -1
    with pytest.raises(ValueError, match=r'--malloc-retain-mb must be in \[0, 2047\], got -1'):
        executable.apply(args)
    bare = argparse.ArgumentParser()
    executable.add_arguments(bare, omp_wait_policy=None, gc_freeze=False)
    args = bare.parse_args(['--malloc-retain-mb', '0'])      # (not this process's malloc)
    assert not hasattr(args, 'omp_wait_policy') and not hasattr(args, 'gc_freeze')
    assert executable.apply(args) == ['malloc retention 0: glibc malloc defaults kept']
    with pytest.raises(ValueError, match='omp_wait_policy must be one of'):
        executable.add_arguments(argparse.ArgumentParser(), omp_wait_policy='spin')


def test_each_executable_has_the_settings_that_act_in_it():
    """The offline run has a wait policy and a heap freeze (its numba kernels and its loop);
    play and record run no kernel and freeze nothing: only the memory option.  Every default
    is the one the benchmarks found better on a shared machine (docs/node.md)."""
    from hair_tracking.ros.bag_cli import build_parser
    parser = build_parser()
    run = parser.parse_args(['run', '-o', 'x.mcap'])
    assert (run.omp_wait_policy, run.gc_freeze, run.malloc_retain_mb) == ('passive', True, 256)
    assert parser.parse_args(['run', '-o', 'x.mcap', '--omp-wait-policy', 'active']) \
        .omp_wait_policy == 'active'
    for argv in (['play'], ['record', '-a', '-o', 'x.mcap']):
        args = parser.parse_args(argv)
        assert not hasattr(args, 'omp_wait_policy') and not hasattr(args, 'gc_freeze')
        assert args.malloc_retain_mb == executable.DEFAULT_RETAIN_MB


# ==================================================================== warm-up
def _cache_files(folder):
    found = {}
    for base, _, files in os.walk(folder):
        for f in files:
            path = os.path.join(base, f)
            st = os.stat(path)
            found[os.path.relpath(path, folder)] = (st.st_size, st.st_mtime_ns)
    return found


def test_warmup_needs_no_rclpy_and_leaves_the_node_nothing_to_compile():
    """``hair_sim_warmup`` (what make install runs) fills the cache the node uses without
    loading rclpy; the node then starts without writing anything into that cache, so it
    compiled nothing."""
    cache = os.environ['NUMBA_CACHE_DIR']
    code = ('import sys; from hair_tracking.executable import hair_sim_warmup; '
            'sys.argv[0] = "hair_sim_warmup"; rc = hair_sim_warmup(); '
            'print("rclpy loaded:", "rclpy" in sys.modules); sys.exit(rc)')
    out = run_python(code)
    assert f'numba cache: {cache}' in out and 'rclpy loaded: False' in out, out
    before = _cache_files(cache)
    env = dict(os.environ, ROS_DOMAIN_ID='58', PYTHONUNBUFFERED='1',
               PYTHONPATH=os.pathsep.join(filter(None, [ROOT, os.environ.get('PYTHONPATH')])))
    node = subprocess.Popen(
        [sys.executable, '-c', 'import sys; from hair_tracking.executable import hair_sim_node; '
         'sys.argv[0] = "hair_sim_node"; sys.exit(hair_sim_node())', '--ros-args'],
        env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    text = until_ready_then_ctrl_c(node, timeout=240.0)
    assert node.returncode == 0 and 'ready:' in text, text
    assert _cache_files(cache) == before
    # nor does the import of a groom file, or its detail (groom.detail_nodes)
    code = ('import os, sys, tempfile; import numpy as np; '
            'from hair_tracking.core.scene import Scene; '
            'from hair_tracking.ghosts.detail import Detail; '
            'from hair_tracking.grooms.build import build_groom; '
            'from hair_tracking.grooms.writers import write_data; '
            'd = tempfile.mkdtemp(); path = os.path.join(d, "g.data"); '
            's = np.linspace(0.0, 0.3, 25)[:, None] * np.array([0.2, 0.1, -1.0]); '
            'roots = np.array([[0.0, 0.0, 0.1], [0.03, 0.0, 0.099], [-0.03, 0.02, 0.098]]); '
            'pts = (roots[:, None] + s[None]).reshape(-1, 3); '
            'write_data(path, pts, np.full(3, 25)); '
            'spec = Scene().with_changes(groom__file=path, groom__guides=2, '
            'groom__detail_nodes=40).groom; g = build_groom(spec, cache=False); '
            'Detail(g.ghost_rest, g.detail_rest).carry(g.ghost_rest, np.eye(3)); print("built")')
    assert run_python(code) == 'built'
    assert _cache_files(cache) == before
