"""The typed settings snapshot of the ``hair_sim`` node, generated from the parameter table.

:class:`Settings` has one attribute per node row of the table
(:mod:`hair_tracking.core.param_table`: same name, default and type) plus the validated scene.
The ROS shell (:mod:`hair_tracking.ros.node`) declares one ROS parameter per row, validates a
candidate change with :func:`apply_changes` (which builds and validates the whole scene, so
cross-field rules hold too) and hands the resulting snapshot to the next simulation step;
``hair_sim_bag run`` reads a params file of the node into the same snapshot.  A change of the
groom that imports a file reads it while validating (:func:`check_groom_file`), so a bad file is
refused with the change.  This module imports no ROS package: it is plain data and checks,
testable without DDS.

Units are SI (metres, seconds, radians unless a name says ``_deg``); frames follow REP-103.
"""
from dataclasses import field, make_dataclass
from typing import Any, Dict, Mapping, Optional, Tuple

from hair_tracking.core.param_table import by_name, NODE_PARAMS
from hair_tracking.core.params import did_you_mean, ParamError
from hair_tracking.core.scene import Scene, scene_fields, SceneError
from hair_tracking.grooms.build import build_groom
from hair_tracking.grooms.polylines import GroomFileError

RGBA = Tuple[float, float, float, float]
#: The Python type of each kind of row.
_TYPES = {'bool': bool, 'int': int, 'double': float, 'string': str, 'double_array': RGBA}


class _Derived:
    """What :class:`Settings` derives from its rows."""

    __slots__ = ()

    def values(self) -> Dict[str, Any]:
        """Every parameter as ``{name: value}`` (arrays as tuples), in the table's order."""
        out = {p.name: getattr(self, p.name) for p in NODE_PARAMS}
        out.update(scene_fields(self.scene))
        return out

    @property
    def publish_period(self) -> float:
        """Seconds between two publications."""
        return 1.0 / self.publish_rate_hz

    @property
    def guide_state(self) -> bool:
        """Whether the node publishes the guides' state for ghost shards."""
        return self.publish_guide_state or self.shards > 0

    @property
    def cloud_rgb(self) -> bool:
        """Whether the clouds carry the rgb field (``cloud_fields``)."""
        return 'rgb' in self.cloud_fields

    @property
    def cloud_strand(self) -> bool:
        """Whether the clouds carry the strand field (``cloud_fields``)."""
        return 'strand' in self.cloud_fields

    @property
    def marker_lifetime(self) -> float:
        """Marker lifetime [s]; 0 = forever."""
        return self.marker_lifetime_periods * self.publish_period


Settings = make_dataclass(
    'Settings',
    [('scene', Scene, field(default_factory=Scene))] +
    [(p.name, _TYPES[p.kind], field(default=p.default)) for p in NODE_PARAMS],
    bases=(_Derived,), frozen=True, namespace={'__module__': __name__, '__doc__': """Frozen
    snapshot of every parameter: the validated scene plus one attribute per node row of the
    table (same name, default and type), in the table's order.  The node builds a new one for
    each accepted change (:func:`apply_changes`); a simulation step reads the one current at
    its start, so a change never shows up half-applied."""})


def _nest(flat: Mapping[str, Any]) -> Dict[str, Any]:
    out: Dict[str, Any] = {}
    for path, value in flat.items():
        node = out
        parts = path.split('.')
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = list(value) if isinstance(value, tuple) else value
    return out


def make_settings(values: Mapping[str, Any], base: Optional[Scene] = None) -> Settings:
    """A validated :class:`Settings` from ``{name: value}``; missing names take their default.

    ``base`` supplies the defaults of the scene fields (a ``scene_file``).  Unknown names, bad
    types and out-of-range values raise :class:`ParamError` naming the parameter and what is
    allowed; cross-field scene rules are checked by ``Scene.validate``.
    """
    params = by_name(base)
    unknown = sorted(set(values) - set(params))
    if unknown:
        raise ParamError(unknown[0], 'unknown parameter' + (
            did_you_mean(unknown[0], params) or ' (see config/hair_sim.yaml for the list)'))
    node, scene_flat = {}, {}
    for name, p in params.items():
        value = p.coerce(values[name]) if name in values else p.default
        (scene_flat if p.scene else node)[name] = value
    try:
        scene = Scene.from_dict(_nest(scene_flat))
    except SceneError as e:
        raise ParamError(e.field, str(e).split(': ', 1)[-1]) from None
    return Settings(scene=scene, **node)


def check_groom_file(scene: Scene) -> None:
    """ParamError naming ``groom.file`` when the scene imports a groom file that cannot be read
    or put on the head (the file is read and imported here, so a bad one is refused before
    anything is rebuilt); nothing for the procedural groom."""
    if scene.groom.file:
        try:
            build_groom(scene.groom)        # kept (grooms/cache.py): the hair's build loads it
        except GroomFileError as e:
            raise ParamError('groom.file', str(e)) from None


def apply_changes(settings: Settings, changes: Mapping[str, Any],
                  base: Optional[Scene] = None, allow_read_only: bool = False
                  ) -> Tuple[Settings, bool]:
    """Validate ``changes`` against ``settings``; returns ``(new settings, rebuild needed)``.

    Raises :class:`ParamError` (name + allowed values) for an unknown or read-only parameter,
    a wrong type, a value out of range, a scene that fails validation or a changed groom whose
    file cannot be imported (:func:`check_groom_file`); ``settings`` itself is never modified
    (it is frozen).
    """
    params = by_name(base)
    for name in changes:
        if name not in params:
            raise ParamError(name, 'unknown parameter' + did_you_mean(name, params))
        if params[name].read_only and not allow_read_only:
            raise ParamError(name, 'is read-only (set it at start: params file, launch file '
                                   'or -p name:=value)')
    old = settings.values()
    values = dict(old)
    values.update(changes)
    new = make_settings(values, base)
    new_values = new.values()
    rebuild = any(params[n].rebuild and new_values[n] != old[n] for n in changes)
    if new.scene.groom != settings.scene.groom:
        check_groom_file(new.scene)
    return new, rebuild
