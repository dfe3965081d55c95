"""Params files read or refused in one line, and unknown parameters in params files and -p
arguments, matched to the node as rcl does."""
import pytest

from hair_tracking.core import param_table as params
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


def test_params_files_are_read_or_refused_in_one_line(tmp_path):
    from hair_tracking.output.params_check import load_params_file, node_parameters, \
        params_files_problem, ParamsFileError
    good = tmp_path / 'good.yaml'
    good.write_text('/**:\n  ros__parameters: {damping: 2.0, groom: {guides: 8}}\n'
                    'hair_sim:\n  ros__parameters: {damping: 3.0}\n'
                    'ns:\n  other:\n    ros__parameters: {x: [1, 2]}\n')
    data = load_params_file(str(good))
    assert node_parameters(data, '/hair_sim') == {'damping': 3.0, 'groom.guides': 8}
    assert node_parameters(data, '/nobody/else') == {'damping': 2.0, 'groom.guides': 8}
    assert node_parameters({'hair_sim': data['hair_sim']}, '/nobody') is None
    assert params_files_problem(['x', '--ros-args', '--params-file', str(good)]) is None
    empty = tmp_path / 'empty.yaml'
    empty.write_text('')
    assert load_params_file(str(empty)) == {}
    for text, reason in [
            (None, 'params file not found'),
            ('a: [1,\n', 'not valid YAML: line 2, column 1: '),
            ('- 1\n', 'a params file holds a mapping of node names'),
            ('hair_sim: 3\n', 'hair_sim: a value where "ros__parameters:" should be'),
            ('hair_sim: {ros__parameters: 3}\n', 'hair_sim.ros__parameters: must be a mapping'),
            ('hair_sim: {ros__parameters: {a: }}\n', 'hair_sim.ros__parameters.a has no value'),
            ('hair_sim: {ros__parameters: {a: [true, 1]}}\n', 'mixes bool and integer')]:
        bad = tmp_path / 'bad.yaml'
        bad.unlink(missing_ok=True)
        if text is not None:
            bad.write_text(text)
        with pytest.raises(ParamsFileError) as err:
            load_params_file(str(bad))
        assert str(err.value).startswith(f'{bad}: ') and reason in str(err.value), err.value
        assert '\n' not in str(err.value)
        assert params_files_problem(['x', '--ros-args', '--params-file', str(bad)]) == \
            str(err.value)


def test_rcl_argument_errors_become_one_line():
    from hair_tracking.output.params_check import rcl_arguments_problem

    class UnknownROSArgsError(RuntimeError):
        pass
    rcl = RuntimeError("failed to initialize rcl: Couldn't parse params file: '--params-file "
                       "a b.yaml'. Error: node name must not start with a number, at "
                       "/project/src/parse.c:490, at /project/src/rcl/arguments.c:415")
    assert rcl_arguments_problem(rcl) == \
        'a b.yaml: not a valid params file: node name must not start with a number'
    assert rcl_arguments_problem(UnknownROSArgsError("['--bogus']")) == \
        "unknown ROS arguments after --ros-args: ['--bogus']"
    assert rcl_arguments_problem(RuntimeError('something else')) is None
