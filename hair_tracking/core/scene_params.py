"""The scene's rows of the parameter table: every field of the scene, declared once.

Each row (:class:`~hair_tracking.core.params.Param`) gives a scene field's dotted path, type,
default, description, unit, allowed values and whether a change rebuilds the hair (every groom
field and the tracker mode: they change strand counts, node counts or the rest shape; every other
field applies live to the running hair).  The scene dataclasses of :mod:`hair_tracking.core.scene`
take their field defaults from these rows and validate every field with them; the node declares
one ROS parameter per row (under the same dotted name), and ``config/hair_sim.yaml``,
``config/scene_default.yaml`` and the table in ``docs/node.md`` are generated from them
(:mod:`hair_tracking.output.param_files`).  Rules that join two fields (``groom.guides *
groom.ghosts_per_guide``, ``groom.scalp.front_max_polar_deg <= groom.scalp.max_polar_deg``) are
code in :meth:`hair_tracking.core.scene.Scene.validate`.

The rows are in the order of the scene's fields (a section's rows together), the order of the
generated files.  Units are SI (metres, seconds, radians unless a name says ``_deg``); the groom
and the collider are given in the head frame (REP-103: x forward, y left, z up, origin at the
head centre).
"""
from typing import Any, Dict, Tuple

from hair_tracking.core.params import Param

SOLVERS = ('ftl', 'pbd', 'xpbd')
#: Shapes of a collider slot (``colliders.extra_<i>.shape``; none: the slot is unused).
SLOT_SHAPES = ('none', 'sphere', 'capsule', 'ellipsoid', 'plane')
#: The collider slots: ``colliders.<slot>.*`` (docs/colliders.md).
COLLIDER_SLOTS = ('extra_1', 'extra_2', 'extra_3', 'extra_4')
COLLIDERS = ('none', 'sphere', 'ellipsoid')
ELASTIC_MODES = ('kept', 'changed')
CURVES = ('none', 'bezier', 'catmull_rom')
TRACKING_MODES = ('paper', 'blend', 'turn')
#: Where the heads come from: one head-pose stream, or every face REP-155 perception tracks.
PEOPLE_SOURCES = ('pose', 'hri')
#: Length units of a groom file: metres per unit (``tenth_in``: tenths of an inch, Cem Yuksel's
#: models); ``auto`` guesses from the span of the roots (docs/grooms.md).
GROOM_UNITS = {'m': 1.0, 'cm': 0.01, 'mm': 0.001, 'in': 0.0254, 'tenth_in': 0.00254}
#: Up axis of a groom file: one of its axes either way (``y``: y up, the face toward +z; ``z``:
#: z up, the face toward +x, the head frame's axes; ``x``: x up, the face toward +y); ``auto``
#: guesses it (docs/grooms.md).
GROOM_UP_AXES = ('auto', 'x', '-x', 'y', '-y', 'z', '-z')
#: How an imported groom is put on the head: ``translate`` (roots fitted onto the scalp
#: ellipsoid by a translation), ``scale`` (a translation and a uniform scale), ``none`` (the
#: file's coordinates, in metres and REP-103 axes, are the head frame).
GROOM_FITS = ('translate', 'scale', 'none')


def _row(name: str, kind: str, default: Any, description: str, **kw: Any) -> Param:
    return Param(name, kind, default, description, scene=True, **kw)


def _slot_rows(slot: str) -> Tuple[Param, ...]:
    """The rows of one collider slot ``colliders.<slot>.*``."""
    p = f'colliders.{slot}.'
    return (
        _row(p + 'shape', 'string', 'none',
             'a further collider the hair is kept out of (sphere, capsule, ellipsoid, plane: the '
             'half-space below it); none: unused', choices=SLOT_SHAPES),
        _row(p + 'frame', 'string', 'head',
             'the frame it rides on: head (moves with the head pose), fixed (the fixed frame of '
             'the pose), or a TF frame name (e.g. l_shoulder_<id>; its last pose is kept while '
             'none arrives, and the collider is off until one has)'),
        _row(p + 'center', 'double_array', (0.0, 0.0, 0.0),
             'its centre (a capsule: the middle of its axis; a plane: a point of it) in that '
             'frame', unit='m', lo=-100.0, hi=100.0, length=3),
        _row(p + 'rotation', 'double_array', (0.0, 0.0, 0.0, 1.0),
             'its axes in that frame, a unit quaternion (x, y, z, w); the capsule\'s axis and '
             'the plane\'s normal are its local z', lo=-1.0, hi=1.0, length=4),
        _row(p + 'radius', 'double', 0.05,
             'sphere, capsule radius', unit='m', lo=0.0, hi=10.0, lo_open=True),
        _row(p + 'half_length', 'double', 0.1,
             'capsule: half the length of its axis segment', unit='m', lo=0.0, hi=10.0),
        _row(p + 'radii', 'double_array', (0.05, 0.05, 0.05),
             'ellipsoid semi-axes along its local x, y, z', unit='m', lo=0.0, hi=10.0,
             lo_open=True, length=3),
        _row(p + 'margin', 'double', 0.004,
             'hair is kept this far outside it (at most half the shortest segment)', unit='m',
             lo=0.0, hi=0.1),
        _row(p + 'friction', 'double', 0.3,
             'tangential damping on contact, 0 none .. 1 sticks', lo=0.0, hi=1.0),
    )


SCENE_PARAMS: Tuple[Param, ...] = (
    _row('groom.guides', 'int', 64,
         'number of guide strands simulated with PBD/FTL (an imported groom: chosen among its '
         'strands, at most all of them)', lo=1, hi=100_000, rebuild=True),
    _row('groom.ghosts_per_guide', 'int', 8,
         'ghost strands created per guide (total = guides * this); 0 shows the guides themselves '
         '(an imported groom: every strand of the file is a ghost, 0 shows the guides alone)',
         lo=0, hi=10_000, rebuild=True),
    _row('groom.guide_nodes', 'int', 16,
         'nodes per guide strand, root included', lo=3, hi=256, rebuild=True),
    _row('groom.ghost_nodes', 'int', 16,
         'nodes per ghost strand, root included', lo=3, hi=256, rebuild=True),
    _row('groom.detail_nodes', 'int', 0,
         'points per strand of the groom\'s own shape in the output: every strand kept at this '
         'many points (an imported one resampled from the file) and carried by its ghost '
         'between the ghost\'s nodes, so curls finer than ghost_nodes are kept (output.curve '
         'then does not apply); 0: the ghosts\' nodes are the output; see docs/grooms.md',
         lo=0, hi=1024, rebuild=True),
    _row('groom.length', 'double', 0.25,
         'mean strand length', unit='m', lo=0.001, hi=5.0, rebuild=True),
    _row('groom.length_variation', 'double', 0.1,
         'relative spread of strand lengths: uniform in length * (1 +- this)',
         lo=0.0, hi=0.9, rebuild=True),
    _row('groom.droop', 'double', 0.6,
         'rest shape: 0 straight along the scalp normal, 1 hanging down',
         lo=0.0, hi=1.0, rebuild=True),
    _row('groom.seed', 'int', 1,
         'random seed of the groom', lo=0, hi=2**31 - 1, rebuild=True),
    _row('groom.file', 'string', '',
         'a groom file to import instead of the procedural groom: .hair (Cem Yuksel), .data '
         '(USC-HairSalon), .bin (CT2Hair), .ply (polylines), .npz, .usd/.usda/.usdc/.usdz '
         '(BasisCurves; needs usd-core); a path, relative to the working directory; empty: the '
         'procedural groom. Its strands are the hair (groom.length, length_variation, droop '
         'and seed then do not apply); see docs/grooms.md', rebuild=True),
    _row('groom.max_strands', 'int', 0,
         'imported groom: keep at most this many strands, evenly spread over the scalp; 0 keeps '
         'them all', lo=0, hi=2_000_000, rebuild=True),
    _row('groom.units', 'string', 'auto',
         'imported groom: length unit of the file (tenth_in: tenths of an inch); auto: the one '
         'the file states, else guessed from the span of the roots',
         choices=('auto',) + tuple(GROOM_UNITS), rebuild=True),
    _row('groom.up_axis', 'string', 'auto',
         'imported groom: the file axis pointing up, either way (the face: groom.face_axis); '
         'auto: the one the file states, else the axis along which the tips hang below the '
         'roots',
         choices=GROOM_UP_AXES, rebuild=True),
    _row('groom.face_axis', 'string', 'auto',
         'imported groom: the file axis the face looks toward, either way, across the up axis; '
         'auto: the side of the head the roots leave bare, when they tell it, else the up '
         'axis\'s convention (y up: +z; z up: +x; x up: +y)',
         choices=GROOM_UP_AXES, rebuild=True),
    _row('groom.fit', 'string', 'translate',
         'imported groom: translate (roots fitted onto the scalp ellipsoid), scale (and a '
         'uniform scale) or none (the file, in metres, is already in the head frame); the roots '
         'are then put on the scalp', choices=GROOM_FITS, rebuild=True),
    _row('groom.file_rotation_deg', 'double_array', (0.0, 0.0, 0.0),
         'imported groom: rotation about the head frame\'s x, y, z axes (in that order) before '
         'fitting', unit='deg', lo=-360.0, hi=360.0, length=3, rebuild=True),
    _row('groom.file_offset', 'double_array', (0.0, 0.0, 0.0),
         'imported groom: shift after fitting, head frame (the roots then slide onto the '
         'scalp)', unit='m', lo=-1.0, hi=1.0, length=3, rebuild=True),
    _row('groom.scalp.center', 'double_array', (0.0, 0.0, 0.0),
         'centre of the scalp ellipsoid, head frame',
         unit='m', lo=-1.0, hi=1.0, length=3, rebuild=True),
    _row('groom.scalp.radii', 'double_array', (0.095, 0.08, 0.105),
         'semi-axes of the scalp ellipsoid, head frame',
         unit='m', lo=0.01, hi=1.0, length=3, rebuild=True),
    _row('groom.scalp.max_polar_deg', 'double', 105.0,
         'roots grow up to this polar angle from +z', unit='deg', lo=1.0, hi=180.0, rebuild=True),
    _row('groom.scalp.front_max_polar_deg', 'double', 45.0,
         '... but only up to this on the face side (x > 0); at most groom.scalp.max_polar_deg',
         unit='deg', lo=0.0, hi=180.0, rebuild=True),
    _row('collider.shape', 'string', 'ellipsoid',
         'head collider shape', choices=COLLIDERS),
    _row('collider.center', 'double_array', (0.0, 0.0, 0.0),
         'collider centre, head frame', unit='m', lo=-1.0, hi=1.0, length=3),
    _row('collider.radius', 'double', 0.1,
         'sphere radius', unit='m', lo=0.01, hi=1.0),
    _row('collider.radii', 'double_array', (0.095, 0.08, 0.105),
         'ellipsoid semi-axes, head frame', unit='m', lo=0.01, hi=1.0, length=3),
    _row('collider.margin', 'double', 0.004,
         'hair is kept this far outside the collider surface', unit='m', lo=0.0, hi=0.1),
    _row('collider.friction', 'double', 0.3,
         'tangential damping on contact, 0 none .. 1 sticks', lo=0.0, hi=1.0),
    _row('body.bust', 'bool', False,
         'a bust below the head (neck, shoulders, chest and trunk: five capsules sized from '
         'body.height as ROS4HRI human_description sizes a person) that the guides and the blend '
         'and turn trackers\' ghosts are kept out of; see docs/colliders.md'),
    _row('body.height', 'double', 1.7,
         'height of the person the bust is sized from (human_description: unit = height / 7.5)',
         unit='m', lo=0.5, hi=2.5),
    _row('body.frame', 'string', '',
         'TF frame the bust rides on (the torso frame, e.g. torso_<id> of a REP-155 skeleton); '
         'empty: the neck frame computed from the head pose (the head\'s pivot below its '
         'centre, the torso upright below it and turned with the head\'s heading)'),
    _row('body.margin', 'double', 0.004,
         'hair is kept this far outside the bust (at most half the shortest segment)',
         unit='m', lo=0.0, hi=0.1),
    _row('body.friction', 'double', 0.3,
         'tangential damping on contact with the bust, 0 none .. 1 sticks', lo=0.0, hi=1.0),
    _row('body.max_push_speed', 'double', 0.5,
         'the speed a push out of the bust may add to a guide node (a body that jumps or appears '
         'inside the hair pushes it out without launching it)', unit='m/s', lo=0.0, hi=100.0),
    *(row for slot in COLLIDER_SLOTS for row in _slot_rows(slot)),
    _row('solver.type', 'string', 'ftl',
         'guide solver: ftl (Follow-The-Leader), pbd, xpbd', choices=SOLVERS),
    _row('solver.dt', 'double', 1.0 / 240.0,
         'fixed simulation substep (ftl: a longer one runs inner steps of at most 1/240 s)',
         unit='s', lo=1e-5, hi=0.1),
    _row('solver.iterations', 'int', 4,
         'constraint iterations per substep (pbd, xpbd)', lo=1, hi=1000),
    _row('solver.stiffness', 'double', 1.0,
         'PBD stretch stiffness (iteration dependent)', lo=0.0, hi=1.0, lo_open=True),
    _row('solver.compliance', 'double', 0.0,
         'XPBD stretch compliance; 0 is rigid', unit='m/N', lo=0.0, hi=1.0),
    _row('solver.bend_stiffness', 'double', 0.3,
         'PBD/FTL bending stiffness', lo=0.0, hi=1.0),
    _row('solver.bend_compliance', 'double', 1e-4,
         'XPBD bending compliance', unit='m/N', lo=0.0, hi=1e3),
    _row('solver.ftl_damping', 'double', 0.9,
         'FTL velocity correction s_damp', lo=0.0, hi=1.0),
    _row('solver.max_substeps', 'int', 32,
         'cap of substeps per pose; further due substeps are dropped (counted in diagnostics)',
         lo=1, hi=10_000),
    _row('solver.shock_propagation', 'double', 0.0,
         'carry strands rigidly with fast head motion, 0 off .. 1', lo=0.0, hi=1.0),
    _row('solver.shape_stiffness', 'double', 0.0,
         'pull of every free node toward its groomed place carried by the head (an implicit '
         'spring, TressFX\'s global shape constraint): holds a style (curls, a fringe) against '
         'gravity, the settled sag about 9.81 / this [m]; it also stiffens the motion; 0 off',
         unit='1/s^2', lo=0.0, hi=1e6),
    _row('solver.max_displacement', 'double', 0.05,
         'per-substep displacement clamp (ftl: per inner step); 0 disables', unit='m',
         lo=0.0, hi=10.0),
    _row('solver.max_strain', 'double', 0.0,
         'PBD/XPBD: after every substep no guide segment is longer or shorter than its rest '
         'length by more than this fraction (strain limiting); 0 disables (FTL keeps lengths '
         'exact)', lo=0.0, hi=0.5),
    _row('solver.settle_time', 'double', 0.5,
         'time simulated with a still head after a (re)build or reset', unit='s', lo=0.0, hi=60.0),
    _row('solver.settle_speed', 'double', 0.0,
         'after solver.settle_time, keep settling (0.1 s at a time, at most 30 s in all) until '
         'no hair node moved faster than this over the last 0.1 s, so the hair starts near its '
         'settled shape; 0 settles exactly solver.settle_time', unit='m/s', lo=0.0, hi=10.0),
    _row('volume.enabled', 'bool', False,
         'hair-hair interaction through a grid on the head: the guides push apart where they '
         'are denser than the groom at rest, and move together (docs/volume.md); off: the '
         'stage is not built'),
    _row('volume.cell_size', 'double', 0.025,
         'edge of the grid\'s cells, about the spacing of the guides\' roots', unit='m',
         lo=0.002, hi=0.5),
    _row('volume.pressure', 'double', 30.0,
         'push out of cells denser than at rest: the acceleration per unit of excess density '
         '(over the mean rest density) per cell; 0 none', unit='m/s^2', lo=0.0, hi=10_000.0),
    _row('volume.friction', 'double', 20.0,
         'rate at which a node\'s velocity turns into the grid\'s there (hair-hair friction); '
         '0 none', unit='1/s', lo=0.0, hi=1000.0),
    _row('tracking.mode', 'string', 'blend',
         'ghost tracker: paper (Park & Kim: velocity transfer, weights (4)-(5), centre-of-mass '
         'tracking, every substep) or blend (each ghost the blended points of its '
         'tracking.blend_guides nearest guides, chosen among the strands, plus its rest offset '
         'carried by the head, once per frame; see docs/blend.md) or turn (each ghost segment '
         'turned as the matching segment of the guide with the nearest root, once per frame; '
         'exact lengths; see docs/turn.md)', choices=TRACKING_MODES, rebuild=True),
    _row('tracking.blend_guides', 'int', 3,
         'blend: guides blended per ghost (nearest roots)', lo=1, hi=8),
    _row('tracking.candidates', 'int', 8,
         'guides with the nearest roots examined per ghost', lo=1, hi=1024),
    _row('tracking.com_strength', 'double', 0.5,
         'centre-of-mass tracking strength per substep', lo=0.0, hi=1.0),
    _row('tracking.offset_strength', 'double', 0.05,
         'pull of each ghost node to its rest offset', lo=0.0, hi=1.0),
    _row('tracking.elastic_weight', 'bool', True,
         'use the elastic weight W* (equation 4 of Park & Kim)'),
    _row('tracking.elastic_mode', 'string', 'kept',
         'elastic weight mode: kept (W* = 0.5 v.v0 + 0.5) or changed (1 - W*)',
         choices=ELASTIC_MODES),
    _row('tracking.tip_weight', 'double', 0.3,
         'tip weight w_tip (grows linearly from 0 at the root)', lo=0.0, hi=5.0),
    _row('tracking.com_weight', 'double', 0.3,
         'centre-of-mass weight w_com per metre of distance / length', lo=0.0, hi=50.0),
    _row('tracking.max_weight', 'double', 1.5,
         'clamp of W* + w_tip + w_com (energy safety)', lo=0.0, hi=10.0),
    _row('tracking.length_restore', 'bool', True,
         'one Follow-The-Leader pass on the ghosts'),
    _row('tracking.collide', 'bool', True,
         'ghosts collide with the head collider'),
    _row('tracking.spread', 'double', 0.0,
         'HairControl spread control strength, 0 off', lo=0.0, hi=1.0),
    _row('tracking.spread_target', 'double', 1.0,
         'target spread as a multiple of the initial variance', lo=0.01, hi=100.0),
    _row('tracking.every_substep', 'bool', True,
         'paper: track the ghosts after every guide substep; false tracks them once per head '
         'pose over all its substeps (2-4x cheaper; passes the stability matrix too)'),
    _row('head_track.teleport_distance', 'double', 0.5,
         'a head jump farther than this resets the hair', unit='m', lo=0.0, hi=1e3, lo_open=True),
    _row('head_track.teleport_angle_deg', 'double', 90.0,
         '... or a turn larger than this between two poses',
         unit='deg', lo=0.0, hi=180.0, lo_open=True),
    _row('head_track.max_gap', 'double', 0.5,
         'poses farther apart than this count as a jump too',
         unit='s', lo=0.0, hi=3600.0, lo_open=True),
    _row('people.source', 'string', 'pose',
         'whose hair is simulated: pose (one head, from head_pose, head_transform or use_tf) '
         'or hri (every face of REP-155 perception: the ids on /humans/faces/tracked and the '
         'face_<id> frames on /tf, one hair each, published on /humans/faces/<id>/hair/points; '
         'docs/node.md#people)', choices=PEOPLE_SOURCES, read_only=True),
    _row('people.sellion_offset', 'double_array', (-0.085, 0.0, 0.01),
         'people.source hri: the head centre (the origin of the head frame) in a face_<id> '
         'frame, whose origin is the sellion (x out of the face, z toward the scalp); the '
         'default is half an adult head length (glabella to opisthocranion, about 19 cm) less '
         'the 1 cm the sellion lies behind the glabella, and 1 cm up, which puts the top of '
         'the default collider 11.5 cm above the sellion, the adult sellion-to-vertex height',
         unit='m', lo=-0.5, hi=0.5, length=3),
    _row('people.lost_timeout_s', 'double', 1.0,
         'people.source hri: a person neither listed on /humans/faces/tracked nor seen on /tf '
         'for this long is removed with their hair (one who comes back gets fresh hair)',
         unit='s', lo=0.0, hi=3600.0, lo_open=True),
    _row('people.max', 'int', 8,
         'people.source hri: most people followed at once (the first ids seen; others wait '
         'for a place)', lo=1, hi=64, read_only=True),
    _row('output.curve', 'string', 'none',
         'smoothing of the output strands', choices=CURVES),
    _row('output.points_per_strand', 'int', 16,
         'output points per strand when output.curve is not none', lo=2, hi=1024),
    _row('gravity', 'double_array', (0.0, 0.0, -9.81),
         'gravity, in the fixed frame of the head pose (or in gravity_frame)',
         unit='m/s^2', lo=-1e4, hi=1e4, magnitude_only=True, length=3),
    _row('damping', 'double', 1.0,
         'velocity damping rate', unit='1/s', lo=0.0, hi=1000.0),
)

#: The scene's rows by dotted path.
SCENE_ROWS: Dict[str, Param] = {p.name: p for p in SCENE_PARAMS}
