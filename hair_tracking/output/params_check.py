"""Which parameters given on the command line or in params files the node does not know.

ROS 2 silently ignores a params-file entry, or a ``-p name:=value``, for a parameter a node never
declares: a misspelt ``grom.guides`` changes nothing and says nothing.  The node calls
:func:`unknown_parameters` on the ``--ros-args`` of its process and warns, naming each unknown
key and where it came from.

The entries that apply to a node follow rcl's rules: a params file's top-level keys are node
names, absolute (``/ns/hair_sim``) or relative (``hair_sim``, taken as ``/hair_sim``), with the
wildcards ``/**`` (any number of namespace levels) and ``*`` (one name); ``-p node:name:=v``
applies to that node only.

The same module reads params files for everyone (:func:`load_params_file`): ``hair_sim_bag run
--params`` through it, and ``hair_sim_node`` checks every ``--params-file`` of its command line
with it before rcl parses them (:func:`params_files_problem`), so a file that is missing, not
YAML, or not shaped as rcl wants is one line naming the file and what is wrong, not rcl's
traceback.  This module imports no ROS package.
"""
import os
import re
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import yaml

#: The key under which a node's section holds its parameters.
ROS_PARAMETERS = 'ros__parameters'


class ParamsFileError(ValueError):
    """A params file that cannot be used; the message is one line naming the file."""


PARAMS_FILE_FLAGS = ('--params-file',)
PARAM_FLAGS = ('-p', '--param')


def _ros_arg_spans(argv: Sequence[str]) -> List[str]:
    """The arguments inside ``--ros-args ... [--]`` sections (in order)."""
    out: List[str] = []
    inside = False
    for a in argv:
        if a == '--ros-args':
            inside = True
        elif a == '--' and inside:
            inside = False
        elif inside:
            out.append(a)
    return out


def params_files(argv: Sequence[str]) -> List[str]:
    """The ``--params-file`` paths of the ROS arguments in ``argv``."""
    args = _ros_arg_spans(argv)
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a in PARAMS_FILE_FLAGS]


def param_assignments(argv: Sequence[str]) -> List[Tuple[str, str]]:
    """``(node or '', name)`` of every ``-p [node:]name:=value`` of the ROS arguments."""
    args = _ros_arg_spans(argv)
    out = []
    for i, a in enumerate(args[:-1]):
        if a in PARAM_FLAGS and ':=' in args[i + 1]:
            lhs = args[i + 1].split(':=', 1)[0]
            node, _, name = lhs.rpartition(':')
            out.append((node, name))
    return out


def node_key_matches(key: str, fqn: str) -> bool:
    """Does the params-file node key ``key`` apply to the node named ``fqn`` (``/ns/name``)?"""
    pattern = ('/' + key.lstrip('/')).split('/')[1:]
    name = fqn.split('/')[1:]

    def match(i: int, j: int) -> bool:
        if i == len(pattern):
            return j == len(name)
        if pattern[i] == '**':
            return any(match(i + 1, k) for k in range(j, len(name) + 1))
        if j == len(name):
            return False
        return (pattern[i] == '*' or pattern[i] == name[j]) and match(i + 1, j + 1)
    return match(0, 0)


def flat_parameters(d: dict, prefix: str = '') -> Dict[str, object]:
    """``{dotted name: value}`` of a nested ``ros__parameters`` mapping."""
    out: Dict[str, object] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(flat_parameters(v, f'{prefix}{k}.'))
        else:
            out[f'{prefix}{k}'] = v
    return out


def _yaml_problem(exc: yaml.YAMLError) -> str:
    """One line out of PyYAML's several: where, then what."""
    mark = getattr(exc, 'problem_mark', None)
    problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
    where = f'line {mark.line + 1}, column {mark.column + 1}: ' if mark is not None else ''
    return f'{where}{problem}'


_KINDS = ((bool, 'bool'), (int, 'integer'), (float, 'double'), (str, 'string'))


def _kind(value) -> Optional[str]:
    return next((name for t, name in _KINDS if isinstance(value, t)), None)


def _check_parameters(params: dict, where: str) -> None:
    """What rcl refuses among parameter values: a name without a value, a list that mixes
    types (a ROS array holds one type: ``[1, 2.0]`` is neither integers nor doubles)."""
    for name, value in flat_parameters(params).items():
        if value is None:
            raise ParamsFileError(f'{where}.{name} has no value')
        if isinstance(value, list):
            kinds = sorted({_kind(v) or '' for v in value})
            if len(kinds) > 1 and '' not in kinds:
                raise ParamsFileError(
                    f'{where}.{name}: the list mixes {" and ".join(kinds)} values; a ROS '
                    f'array holds one type (write 1.0, not 1, in a list of doubles)')


def _check_section(section, where: str) -> None:
    """A node's section: namespaces (mappings) down to ``ros__parameters``, a mapping."""
    if not isinstance(section, dict):
        raise ParamsFileError(f'{where}: a value where "{ROS_PARAMETERS}:" should be (a node\'s '
                              f'parameters go under "NODE: {ROS_PARAMETERS}:")')
    for key, value in section.items():
        if key == ROS_PARAMETERS:
            if not isinstance(value, dict):
                raise ParamsFileError(f'{where}.{ROS_PARAMETERS}: must be a mapping of '
                                      'parameter names to values')
            _check_parameters(value, f'{where}.{ROS_PARAMETERS}')
        else:
            _check_section(value, f'{where}.{key}')


def load_params_file(path: str) -> dict:
    """The contents of the ROS 2 params file ``path``: ``{node key: section}``.

    Raises :class:`ParamsFileError` (one line naming the file) when the file is missing or
    unreadable, is not YAML, is not a mapping of node names, or holds what rcl's parser refuses:
    a value outside ``NODE: ros__parameters:``, a parameter without a value, a list of mixed
    types.  An empty file is an empty mapping."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ParamsFileError(f'{path}: params file not found')
    try:
        with open(path, encoding='utf-8') as fh:
            data = yaml.safe_load(fh)
    except OSError as exc:
        raise ParamsFileError(f'{path}: cannot read the params file: {exc.strerror}') from None
    except UnicodeDecodeError:
        raise ParamsFileError(f'{path}: not a params file (not UTF-8 text)') from None
    except yaml.YAMLError as exc:
        raise ParamsFileError(f'{path}: not valid YAML: {_yaml_problem(exc)}') from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ParamsFileError(f'{path}: a params file holds a mapping of node names, each '
                              f'with "{ROS_PARAMETERS}:", not a {type(data).__name__}')
    for key, section in data.items():
        _check_section(section, f'{path}: {key}')
    return data


def node_parameters(data: dict, fqn: str) -> Optional[Dict[str, object]]:
    """``{dotted name: value}`` that the contents of a params file (:func:`load_params_file`)
    set for the node ``fqn``: the sections whose key matches it (:func:`node_key_matches`),
    wildcard keys first so a section naming the node wins; ``None`` when no section does."""
    sections = [(key, section) for key, section in data.items()
                if isinstance(key, str) and node_key_matches(key, fqn)]
    if not sections:
        return None
    out: Dict[str, object] = {}
    for key, section in sorted(sections, key=lambda ks: '*' not in ks[0]):
        out.update(flat_parameters(section.get(ROS_PARAMETERS) or {}))
    return out


def params_file_names(path: str, fqn: str) -> List[str]:
    """Dotted names of the parameters ``path`` sets for the node ``fqn`` (an unusable file and
    other nodes' sections give none: :func:`params_files_problem` reports the file)."""
    try:
        return list(node_parameters(load_params_file(path), fqn) or {})
    except ParamsFileError:
        return []


def params_files_problem(argv: Sequence[str]) -> Optional[str]:
    """One line naming the first ``--params-file`` of the ROS arguments in ``argv`` that
    :func:`load_params_file` refuses, and why; ``None`` when every one is usable."""
    for path in params_files(argv):
        try:
            load_params_file(path)
        except ParamsFileError as exc:
            return str(exc)
    return None


def rcl_arguments_problem(exc: BaseException) -> Optional[str]:
    """One line out of the error rclpy raises when rcl refuses the command line's ROS
    arguments (``failed to initialize rcl: ...``, a params file or ``-p`` value rcl cannot
    parse, or an argument rcl does not know), without rcl's source locations; ``None`` for any
    other error."""
    text = str(exc)
    if type(exc).__name__ == 'UnknownROSArgsError':     # rclpy's, not exported by name
        return f'unknown ROS arguments after --ros-args: {text}'
    prefix = 'failed to initialize rcl: '
    if not text.startswith(prefix):
        return None
    text = re.sub(r'(, at [^,]+:\d+)+$', '', text[len(prefix):].strip())
    found = re.match(r"Couldn't parse params file: '--params-file (.+?)'\. Error: (.*)", text)
    if found:
        return f'{found.group(1)}: not a valid params file: {found.group(2)}'
    return f'invalid ROS arguments: {text}'


def unknown_parameters(argv: Sequence[str], fqn: str, known: Iterable[str],
                       node_name: str = '') -> Dict[str, List[str]]:
    """``{source: [unknown names]}`` for the node ``fqn``: each params file of ``argv`` and
    ``'-p'`` for command-line assignments (``node_name`` is the node's own name, which
    ``-p node_name:param:=v`` may name).  ``use_sim_time`` and the other parameters rclpy
    declares itself count as known."""
    known = set(known) | {'use_sim_time', 'qos_overrides', 'start_type_description_service'}

    def is_known(name: str) -> bool:
        return name in known or name.split('.')[0] in ('qos_overrides',)
    out: Dict[str, List[str]] = {}
    for path in params_files(argv):
        bad = [n for n in params_file_names(path, fqn) if not is_known(n)]
        if bad:
            out[os.fspath(path)] = bad
    node_name = node_name or fqn.rsplit('/', 1)[-1]
    bad = [name for node, name in param_assignments(argv)
           if node in ('', node_name, fqn) and not is_known(name)]
    if bad:
        out['-p'] = bad
    return out
