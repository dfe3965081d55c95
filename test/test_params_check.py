"""Unknown parameters in params files and -p arguments, matched to the node as rcl does."""
from hair_tracking.output import settings as params
from hair_tracking.output.params_check import node_key_matches, param_assignments, params_files, \
    unknown_parameters


def test_node_keys_match_like_rcl():
    assert node_key_matches('/**', '/hair_sim')
    assert node_key_matches('/**', '/a/b/hair_sim')
    assert node_key_matches('hair_sim', '/hair_sim')
    assert node_key_matches('/hair_sim', '/hair_sim')
    assert not node_key_matches('hair_sim', '/left/hair_sim')
    assert node_key_matches('/**/hair_sim', '/left/hair_sim')
    assert node_key_matches('/*/hair_sim', '/left/hair_sim')
    assert not node_key_matches('/*/hair_sim', '/a/b/hair_sim')
    assert node_key_matches('/left/*', '/left/hair_sim')
    assert not node_key_matches('other', '/hair_sim')


def test_ros_args_sections_are_read():
    argv = ['prog', '--params-file', 'not_ros.yaml', '--ros-args', '--params-file', 'a.yaml',
            '-p', 'x:=1', '--', '-p', 'ignored:=2', '--ros-args', '--param', 'n:y:=3']
    assert params_files(argv) == ['a.yaml']
    assert param_assignments(argv) == [('', 'x'), ('n', 'y')]


def test_shipped_config_has_no_unknown_key(tmp_path):
    import os
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    shipped = os.path.join(root, 'config', 'hair_sim.yaml')
    names = params.by_name()
    assert unknown_parameters(['x', '--ros-args', '--params-file', shipped], '/ns/any_name',
                              names) == {}
    f = tmp_path / 'p.yaml'
    f.write_text('hair_sim:\n  ros__parameters:\n    solver: {tipe: pbd}\n'
                 '/other:\n  ros__parameters:\n    whatever: 1\n')
    assert unknown_parameters(['x', '--ros-args', '--params-file', str(f),
                               '-p', 'other:zzz:=1', '-p', 'hair_sim:qqq:=1'],
                              '/hair_sim', names) == {str(f): ['solver.tipe'], '-p': ['qqq']}
    # a namespaced node is not addressed by a relative key
    assert unknown_parameters(['x', '--ros-args', '--params-file', str(f)], '/left/hair_sim',
                              names) == {}
