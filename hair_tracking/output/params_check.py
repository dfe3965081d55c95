"""Which parameters given on the command line or in params files the node does not know.

ROS 2 silently ignores a params-file entry, or a ``-p name:=value``, for a parameter a node never
declares: a misspelt ``grom.guides`` changes nothing and says nothing.  The node calls
:func:`unknown_parameters` on the ``--ros-args`` of its process and warns, naming each unknown
key and where it came from.

The entries that apply to a node follow rcl's rules: a params file's top-level keys are node
names, absolute (``/ns/hair_sim``) or relative (``hair_sim``, taken as ``/hair_sim``), with the
wildcards ``/**`` (any number of namespace levels) and ``*`` (one name); ``-p node:name:=v``
applies to that node only.  This module imports no ROS package.
"""
import os
from typing import Dict, Iterable, List, Sequence, Tuple

import yaml

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


def _flatten(d: dict, prefix: str = '') -> Iterable[str]:
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _flatten(v, f'{prefix}{k}.')
        else:
            yield f'{prefix}{k}'


def params_file_names(path: str, fqn: str) -> List[str]:
    """Dotted names of the parameters ``path`` sets for the node ``fqn`` (unreadable files and
    other nodes' sections give none: rcl itself reports a file it cannot parse)."""
    try:
        with open(path, encoding='utf-8') as f:
            data = yaml.safe_load(f)
    except (OSError, yaml.YAMLError):
        return []
    names: List[str] = []
    if not isinstance(data, dict):
        return names
    for key, section in data.items():
        if not (isinstance(key, str) and isinstance(section, dict)
                and node_key_matches(key, fqn)):
            continue
        params = section.get('ros__parameters')
        if isinstance(params, dict):
            names.extend(n for n in _flatten(params) if n not in names)
    return names


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
