"""One row of the parameter table: a parameter's name, type, default, range, words and change
policy, and the checks and texts derived from it.

The table itself is rows of :class:`Param` (:mod:`hair_tracking.core.param_table`): the scene's
rows in :mod:`hair_tracking.core.scene_params` (from which the scene dataclasses take their
defaults and their validation), then the node's own.  Everything else
is derived from the rows: the node's ROS parameter descriptors, ``config/hair_sim.yaml``,
``config/scene_default.yaml`` and the table in ``docs/node.md``
(:mod:`hair_tracking.output.param_files`).  This module imports no ROS package.

Units are SI (metres, seconds, radians unless a name says ``_deg``); frames follow REP-103.
"""
from dataclasses import dataclass
import difflib
import math
from typing import Any, Iterable, Optional, Tuple

KINDS = ('bool', 'int', 'double', 'string', 'double_array')


class ParamError(ValueError):
    """A rejected parameter value; ``name`` is the parameter, the message says what is allowed."""

    def __init__(self, name: str, message: str):
        super().__init__(f'{name}: {message}')
        self.name = name


def did_you_mean(name: str, names: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` with the known name closest to the unknown ``name``
    (:func:`difflib.get_close_matches`), or '' when none is close: what every tool that
    refuses or ignores an unknown parameter adds to its words."""
    close = difflib.get_close_matches(name, list(names), n=1)
    return f"; did you mean '{close[0]}'?" if close else ''


@dataclass(frozen=True)
class Param:
    """One parameter: a row of the table.

    ``kind`` is one of :data:`KINDS`.  ``lo``/``hi`` bound a number (each element of an array);
    ``lo_open`` excludes ``lo`` itself; ``magnitude_only`` says the bounds are no physical range
    and only keep the numbers finite and sane (the scene then refuses the bounds themselves and
    says "finite numbers of magnitude below ``hi``").  ``choices`` lists the allowed strings.
    ``length`` is the fixed length of an array.  ``read_only`` parameters are set at start
    (launch file, params file, ``-p``) and never change; a change of a ``rebuild`` parameter
    rebuilds the hair in its rest shape at the current head pose (strand counts, nodes, groom
    shape).  ``scene`` marks a scene field (``name`` is its dotted path in the scene).
    """

    name: str
    kind: str
    default: Any
    description: str
    unit: str = ''
    lo: Optional[float] = None
    hi: Optional[float] = None
    lo_open: bool = False
    magnitude_only: bool = False
    choices: Tuple[str, ...] = ()
    length: Optional[int] = None
    read_only: bool = False
    rebuild: bool = False
    scene: bool = False

    # -------------------------------------------------------------- describing
    def interval_text(self) -> str:
        """The bounds as an interval, e.g. ``[1, 100000]``, ``(0.0, 1.0]``; '' without bounds."""
        if self.lo is None and self.hi is None:
            return ''
        lo = _num_text(self.lo, self.kind)
        hi = _num_text(self.hi, self.kind)
        return ('(' if self.lo_open else '[') + f'{lo}, {hi}]'

    def range_text(self) -> str:
        """The allowed values in words, e.g. ``[1, 100000]``, ``one of: ftl, pbd, xpbd``."""
        if self.choices:
            return 'one of: ' + ', '.join(self.choices)
        text = self.interval_text()
        if self.kind == 'double_array':
            return f'{self.length} numbers, each in {text}' if text else \
                f'{self.length} finite numbers'
        return text

    def full_description(self) -> str:
        """Description with unit and the consequence of a change (for the ROS descriptor)."""
        text = self.description
        if self.unit:
            text += f' [{self.unit}]'
        if self.read_only:
            text += ' (read-only: set at start)'
        elif self.rebuild:
            text += ' (a change rebuilds the hair at the current head pose)'
        return text

    # -------------------------------------------------------------- checking
    def coerce(self, value: Any) -> Any:
        """``value`` as this parameter's Python type, or ParamError naming the allowed values.

        Integers are accepted for doubles (``-3`` becomes ``-3.0``); bools are never numbers.
        Arrays come back as tuples of floats.
        """
        kind = self.kind
        if kind == 'bool':
            if isinstance(value, bool):
                return value
            raise ParamError(self.name, f'must be true or false, got {value!r}')
        if kind == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ParamError(self.name, f'must be an integer in {self.range_text()}, '
                                            f'got {value!r}')
            value = int(value)
        elif kind == 'double':
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ParamError(self.name, f'must be a number in {self.range_text()}, '
                                            f'got {value!r}')
            value = float(value)
        elif kind == 'string':
            if not isinstance(value, str):
                raise ParamError(self.name, f'must be a string, got {value!r}')
        elif kind == 'double_array':
            if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
                raise ParamError(self.name, f'must be a list of {self.range_text()} '
                                            f'(write -3.0, not -3), got {value!r}')
            items = list(value)
            if len(items) != self.length or any(
                    isinstance(v, bool) or not isinstance(v, (int, float)) for v in items):
                raise ParamError(self.name, f'must be a list of {self.range_text()}, '
                                            f'got {value!r}')
            value = tuple(float(v) for v in items)
        self.check(value)
        return value

    def check(self, value: Any) -> None:
        """Range/choice check of an already typed value (ParamError on failure)."""
        problem = self.problem(value)
        if problem:
            raise ParamError(self.name, problem)

    def problem(self, value: Any, scene_words: bool = False) -> str:
        """Why an already typed ``value`` is not allowed, '' when it is.

        ``scene_words``: worded as a scene file's check says it (``is not one of a, b``; the
        interval without the array's length; "finite numbers of magnitude below" for
        ``magnitude_only``) rather than as the node says it (:meth:`range_text`).
        """
        if self.choices:
            if value in self.choices:
                return ''
            if scene_words:
                return f'{value!r} is not one of {", ".join(self.choices)}'
            return f'{value!r} is not {self.range_text()}'
        if self.kind not in ('int', 'double', 'double_array') or \
                (self.lo is None and self.hi is None):
            return ''
        vals = value if isinstance(value, tuple) else (value,)
        if scene_words and self.magnitude_only:
            if all(math.isfinite(v) and abs(v) < self.hi for v in vals):
                return ''
            return f'{value!r} must be finite numbers of magnitude below {_e_text(self.hi)}'
        for v in vals:
            bad = not math.isfinite(v)
            if self.lo is not None:
                bad = bad or v < self.lo or (self.lo_open and v == self.lo)
            if self.hi is not None:
                bad = bad or v > self.hi
            if bad:
                allowed = self.interval_text() if scene_words else self.range_text()
                return f'{value!r} is outside the allowed range {allowed}'
        return ''


def _num_text(v, kind):
    if v is None:
        return 'inf'
    if kind == 'int':
        return str(int(v))
    return repr(float(v))


def _e_text(v: float) -> str:
    """``v`` in short scientific notation: ``1e4``."""
    mantissa, exponent = f'{v:.0e}'.split('e')
    return f'{mantissa}e{int(exponent)}'
