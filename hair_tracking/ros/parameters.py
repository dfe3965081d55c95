"""The ``hair_sim`` node's ROS parameters: one per row of the parameter table
(:mod:`hair_tracking.core.param_table`), declared, described, validated and turned into the
:class:`~hair_tracking.output.settings.Settings` snapshot the next step applies.

Each parameter's descriptor carries its description, its allowed values as text
(``additional_constraints``), read-only, and for an integer or a double its range
(``integer_range`` / ``floating_point_range``, so rqt's parameter editor shows a slider).  rclpy
checks a descriptor's range before the node's own validation and would answer in its own words
("Parameter groom.guides out of range. Min: 1, ..."), so every refusal is made the node's
(``groom.guides: 0 is outside the allowed range [1, 100000]``) with rclpy's public hooks only:

* a change (``ros2 param set``, rqt, the ``set_parameters`` services, ``Node.set_parameters``)
  goes through the pre-set callback first; a value outside the row's range is noted with its
  message and handed on inside the descriptor's range, and the on-set callback then refuses the
  change with the noted message (nothing is stored);
* a start value (``-p``, a params file, overrides) that rclpy refuses at declaration is read
  back through a dynamically typed declaration and refused with the row's message.

A descriptor range holds its bounds; an open bound (``lo_open``) and a scene field whose bounds
only keep it finite (``magnitude_only``) are refused at the bound by the node's validation.
Changes are validated against the pending snapshot in the on-set callback (a refusal changes
nothing) and stored by the post-set callback.
"""
from typing import Callable, Dict, List, Optional

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.parameter import Parameter

from hair_tracking.core.param_table import NODE_ROWS, table
from hair_tracking.core.params import did_you_mean, Param, ParamError
from hair_tracking.core.scene import Scene, SceneError
from hair_tracking.output.params_check import unknown_parameters
from hair_tracking.output.settings import apply_changes, make_settings, Settings
from hair_tracking.resources import config_path

_PARAM_TYPES = {
    'bool': Parameter.Type.BOOL,
    'int': Parameter.Type.INTEGER,
    'double': Parameter.Type.DOUBLE,
    'string': Parameter.Type.STRING,
    'double_array': Parameter.Type.DOUBLE_ARRAY,
}


def descriptor(p: Param) -> ParameterDescriptor:
    """The ROS ParameterDescriptor of a table row: description, the allowed values as text
    (``additional_constraints``, e.g. ``[1, 100000]``), read-only, and an integer's or a
    double's range (``integer_range``, step 1 / ``floating_point_range``, continuous)."""
    d = ParameterDescriptor(name=p.name, type=_PARAM_TYPES[p.kind].value,
                            description=p.full_description(),
                            additional_constraints=p.range_text(), read_only=p.read_only)
    if p.lo is not None and p.hi is not None:
        if p.kind == 'int':
            d.integer_range = [IntegerRange(from_value=int(p.lo), to_value=int(p.hi), step=1)]
        elif p.kind == 'double':
            d.floating_point_range = [FloatingPointRange(from_value=float(p.lo),
                                                         to_value=float(p.hi), step=0.0)]
    return d


def load_base_scene(scene_file: str) -> Scene:
    """The scene named by ``scene_file`` (a path or a preset name); ``Scene()`` if empty."""
    if not scene_file:
        return Scene()
    try:
        path = config_path(scene_file)
    except FileNotFoundError as e:
        raise SceneError('scene_file', str(e)) from None
    return Scene.from_yaml(path)


def plain(value):
    """A parameter value as plain Python (arrays as lists)."""
    if isinstance(value, (list, tuple)) or hasattr(value, 'tolist'):
        return list(value)
    return value


def _coerce_parameter(p: Optional[Param], prm: Parameter) -> Optional[Parameter]:
    """``prm`` with integers turned into doubles where ``p`` is a double (else None)."""
    if p is None:
        return None
    if p.kind == 'double' and prm.type_ == Parameter.Type.INTEGER:
        return Parameter(prm.name, Parameter.Type.DOUBLE, float(prm.value))
    if p.kind == 'double_array' and prm.type_ == Parameter.Type.INTEGER_ARRAY:
        return Parameter(prm.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in prm.value])
    return None


def _inside(p: Param, prm: Parameter) -> Parameter:
    """``prm`` moved inside ``p``'s descriptor range (its lower bound): what rclpy lets through
    to the on-set callback, which refuses it in the node's words."""
    return Parameter(prm.name, prm.type_, int(p.lo) if p.kind == 'int' else float(p.lo))


class NodeParameters:
    """The parameters of ``node`` (see the module docstring).

    :attr:`pending` is the newest accepted snapshot; ``on_change(old, new)`` is called after
    each accepted change (the node moves its timers, threads ...).  Invalid start values raise
    :class:`~hair_tracking.core.params.ParamError` naming the parameter.
    """

    def __init__(self, node, on_change: Callable[[Settings, Settings], None]):
        self._node = node
        self._on_change = on_change
        sf = NODE_ROWS['scene_file']
        node.declare_parameter(sf.name, sf.default, descriptor(sf))
        self.base = load_base_scene(node.get_parameter('scene_file').value)
        rows = table(self.base)
        self.table: Dict[str, Param] = {p.name: p for p in rows}
        for p in rows:
            if p.name != 'scene_file':
                self._declare(p)
        values = {p.name: plain(node.get_parameter(p.name).value) for p in rows}
        self.pending: Settings = make_settings(values, self.base)    # ParamError if invalid
        self._refused: Dict[str, str] = {}       # the pre-set callback's refusals, by name
        node.add_pre_set_parameters_callback(self._pre_set)
        node.add_on_set_parameters_callback(self._on_set)
        node.add_post_set_parameters_callback(self._post_set)

    def _declare(self, p: Param) -> None:
        """Declare ``p``.  A start value rclpy refuses is read through a dynamically typed
        declaration (then undeclared): an integer given for a double (``-p damping:=2``) is
        declared as the double it means; a value outside the row's range is refused with the
        row's message (public rclpy API only)."""
        node = self._node
        try:
            node.declare_parameter(p.name, p.default, descriptor(p))
        except (InvalidParameterTypeException, InvalidParameterValueException) as refused:
            given = node.declare_parameter(p.name, None,
                                           ParameterDescriptor(dynamic_typing=True))
            node.undeclare_parameter(p.name)
            fixed = _coerce_parameter(p, given) or given
            if fixed.type_ != _PARAM_TYPES[p.kind]:
                raise refused
            p.coerce(plain(fixed.value))     # ParamError in the node's words
            node.declare_parameter(p.name, fixed.value, descriptor(p), ignore_override=True)

    def _pre_set(self, parameters: List[Parameter]) -> List[Parameter]:
        """Integers given for doubles become doubles (``ros2 param set ... damping 2``); a
        number outside its row's range is noted and handed on inside the descriptor's range,
        for :meth:`_on_set` to refuse in the node's words."""
        self._refused = {}
        out = []
        for prm in parameters:
            p = self.table.get(prm.name)
            fixed = _coerce_parameter(p, prm) if p is not None else None
            prm = fixed if fixed is not None else prm
            if p is not None and p.kind in ('int', 'double') and \
                    prm.type_ == _PARAM_TYPES[p.kind]:
                problem = p.problem(prm.value)
                if problem:
                    self._refused[prm.name] = str(ParamError(prm.name, problem))
                    prm = _inside(p, prm)
            out.append(prm)
        return out

    def _changes(self, parameters: List[Parameter]) -> Dict[str, object]:
        return {prm.name: plain(prm.value) for prm in parameters if prm.name in self.table}

    def _on_set(self, parameters: List[Parameter]) -> SetParametersResult:
        """Validate a candidate change against the pending snapshot; change nothing."""
        refused = [self._refused[prm.name] for prm in parameters if prm.name in self._refused]
        self._refused = {}
        if refused:
            return SetParametersResult(successful=False, reason=refused[0])
        changes = self._changes(parameters)
        if not changes:
            return SetParametersResult(successful=True)
        try:
            apply_changes(self.pending, changes, self.base)
        except ParamError as e:
            return SetParametersResult(successful=False, reason=str(e))
        return SetParametersResult(successful=True)

    def _post_set(self, parameters: List[Parameter]) -> None:
        """Store the accepted change as the snapshot the next step applies."""
        changes = self._changes(parameters)
        if not changes:
            return
        old = self.pending
        self.pending = apply_changes(old, changes, self.base)[0]
        self._on_change(old, self.pending)

    def keep(self, settings: Settings) -> None:
        """Make ``settings`` the pending snapshot again (a change that failed to apply)."""
        self.pending = settings

    def warn_unknown(self, argv: List[str]) -> Dict[str, List[str]]:
        """Warn about every parameter that the params files or ``-p`` of ``argv`` (the
        process's ``--ros-args``) set for this node but that the node does not have (ROS 2
        itself ignores them silently); returns ``{source: [names]}``."""
        node = self._node
        fqn = node.get_fully_qualified_name()
        found = unknown_parameters(argv, fqn, self.table, node.get_name())
        for source, names in found.items():
            hints = [did_you_mean(n, self.table) for n in names]      # '; did you mean ...'
            said = ', '.join(f'{n} ({h[2:]})' if h else n for n, h in zip(names, hints))
            node.get_logger().warn(
                f'{source}: unknown parameter{"s" if len(names) > 1 else ""} for {fqn}, '
                f'ignored: {said} (the node\'s parameters: config/hair_sim.yaml, '
                f'docs/node.md)')
        return found
