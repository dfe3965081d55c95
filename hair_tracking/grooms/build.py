"""The groom a scene asks for: the procedural one (:func:`hair_tracking.core.groom.make_groom`)
or the strands of ``groom.file`` put on the head.

Import (:func:`import_groom`): read the file (:func:`~hair_tracking.grooms.formats.
read_strands`); skip empty and degenerate strands (counted); units and up axis as given or
guessed, the head frame's axes, ``groom.file_rotation_deg``; keep ``groom.max_strands`` strands
evenly spread over the scalp; fit the roots onto the scalp, add ``groom.file_offset``, put the
roots on the scalp and the rest outside it (:mod:`~hair_tracking.grooms.fit`); resample every
strand by arc length to ``groom.ghost_nodes`` (:mod:`~hair_tracking.grooms.resample`); order
the strands along the scalp (:func:`~hair_tracking.core.groom.scalp_order`), as the procedural
ghosts are; with ``groom.detail_nodes`` every strand resampled to that many points as well
(``Groom.detail_rest``, :mod:`hair_tracking.ghosts.detail`).

Groom (:func:`build_groom`): the imported strands are the ghosts; ``groom.guides`` of them
(at most all) are chosen for coverage of the scalp and the shapes
(:func:`~hair_tracking.grooms.guides.choose_guides_by_shape`): the blend and turn trackers'
guides (``Groom.guide_index``), and, resampled to ``groom.guide_nodes``, the paper tracker's
(``Groom.guide_rest``).  With ``groom.ghosts_per_guide`` 0 there are no ghosts: the chosen
strands alone are simulated and shown.
"""
from dataclasses import dataclass
from typing import Tuple

import numpy as np

from hair_tracking.core.groom import Groom, make_groom, scalp_order
from hair_tracking.core.scene import GroomSpec
from hair_tracking.core.scene_params import GROOM_UNITS
from hair_tracking.grooms import fit, resample
from hair_tracking.grooms.formats import read_strands
from hair_tracking.grooms.guides import choose_guides_by_shape
from hair_tracking.grooms.polylines import bounding_box, GroomFileError, Polylines


@dataclass
class Survey:
    """What a groom file holds, in its own units and axes, and the guess of both."""

    format: str
    strands: int                       # in the file
    vertices: int
    empty: int                         # strands of fewer than two vertices
    degenerate: int                    # strands of zero length
    lengths: Tuple[float, float, float]    # min, median, max arc length [file units]
    box: Tuple[np.ndarray, np.ndarray]     # bounding box [file units]
    unit: float                        # metres per file unit, given, stated or guessed
    units_words: str
    up: str
    up_words: str
    face: str                          # the file axis the face looks toward
    face_words: str


@dataclass
class Imported:
    """An imported groom: ``strands`` (S, N, 3) resampled, in the head frame [m], along the
    scalp; ``placed`` the same strands at the file's resolution, in the file's order
    (``strands[i]`` is ``placed``'s strand ``order[i]``); ``survey`` the file; ``note`` one
    line saying what was done, ``placing`` its part that says how the strands were put on the
    scalp."""

    strands: np.ndarray
    placed: Polylines
    order: np.ndarray
    survey: Survey
    note: str
    placing: str = ''


def survey(path: str, units: str = 'auto', up_axis: str = 'auto',
           face_axis: str = 'auto') -> Tuple[Survey, Polylines]:
    """Read ``path`` and describe it; returns the survey and its usable strands (GroomFileError
    when it cannot be read or has none, or when a face axis given lies along the up axis).
    ``face_axis`` '' takes the up axis's convention without a guess (a groom turned by
    ``groom.file_rotation_deg``)."""
    poly = read_strands(path)
    keep, lengths, empty, degenerate = resample.usable(poly)
    if keep.size == 0:
        raise GroomFileError(path, '', 'a strand of two or more distinct vertices',
                             f'{empty} empty and {degenerate} degenerate strands')
    raw_count, raw_vertices = poly.count, int(poly.counts.sum())
    if keep.size < poly.count:
        poly = poly.select(keep)
        lengths = lengths[keep]
    starts = poly.starts
    roots = poly.points[starts]
    tips = poly.points[starts + poly.counts - 1]
    if units != 'auto':
        unit, unit_words = GROOM_UNITS[units], units
        problem = fit.units_problem(roots, poly.points, unit, units)
        if problem:
            raise GroomFileError(path, '', '', problem)
    elif poly.meters_per_unit is not None:
        unit = poly.meters_per_unit
        unit_words = f'{unit:g} m (stated by the file)'
    else:
        units, unit_words = fit.guess_units(roots, poly.points)
        unit = GROOM_UNITS[units]
    if up_axis != 'auto':
        up_words = up_axis
    elif poly.up_axis is not None:
        up_axis, up_words = poly.up_axis, f'{poly.up_axis} (stated by the file)'
    else:
        up_axis, up_words = fit.guess_up(roots, tips, lengths)
    if face_axis not in ('', 'auto'):
        if face_axis[-1] == up_axis[-1]:
            raise GroomFileError(path, '', '', f'the face axis {face_axis} lies along the up '
                                 f'axis {up_axis}; give one across it (groom.face_axis)')
        face_words = face_axis
    else:
        face_axis, why, _ = fit.guess_face(roots, up_axis) if face_axis else \
            ('', 'groom.file_rotation_deg turns the groom', 0.0)
        face_words = why
        if not face_axis:
            face_axis = fit.convention_face(up_axis)
            face_words = f'{face_axis} (the convention of a file with {up_axis[-1]} up: {why})'
    return Survey(format=poly.format, strands=raw_count, vertices=raw_vertices, empty=empty,
                  degenerate=degenerate,
                  lengths=(float(lengths.min()), float(np.median(lengths)),
                           float(lengths.max())),
                  box=bounding_box(poly.points), unit=unit,
                  units_words=unit_words, up=up_axis, up_words=up_words, face=face_axis,
                  face_words=face_words), poly


def import_groom(spec: GroomSpec) -> Imported:
    """The strands of ``spec.file`` put on the head (see the module docstring)."""
    turned = spec.face_axis == 'auto' and any(spec.file_rotation_deg)
    info, poly = survey(spec.file, spec.units, spec.up_axis, '' if turned else spec.face_axis)
    axes = fit.head_axes(info.unit, info.up, spec.file_rotation_deg, info.face)
    roots = fit.affine(poly.points[poly.starts], axes, np.zeros(3))
    subset = resample.spread_subset(roots, spec.max_strands)
    if subset.size < poly.count:
        poly = poly.select(subset)
        roots = roots[subset]
    center, radii = spec.scalp.center, spec.scalp.radii
    if spec.fit == 'none':
        s, t = 1.0, np.zeros(3)
        fit_words = 'not fitted'
    else:
        s, t, rms = fit.fit_to_scalp(roots, center, radii, scale=spec.fit == 'scale')
        fit_words = (f'fitted onto the scalp: translated by [{t[0]:.3f}, {t[1]:.3f}, '
                     f'{t[2]:.3f}] m' + (f', scaled by {s:.3f}' if spec.fit == 'scale' else '')
                     + f', roots {100 * rms:.1f} % of the radii off the scalp')
    points = fit.affine(poly.points, s * axes, t + np.asarray(spec.file_offset),
                        in_place=True)                     # the file's points are not kept
    placed, off_cap = _onto_scalp(Polylines(points, poly.counts, poly.format), spec.scalp)
    strands = resample.resample(placed, spec.ghost_nodes)
    fit.push_out(strands[:, 1:], center, radii)
    order = scalp_order(strands[:, 0])
    dropped = info.strands - poly.count
    placing = fit_words + (f'; {off_cap} roots ({100 * off_cap / poly.count:.0f} %) off the '
                           'scalp cap (groom.scalp: the face, an ear or the neck) moved to its '
                           'edge' if off_cap else '')
    note = (f'groom {spec.file} ({info.format}): {poly.count} strands'
            + (f' of {info.strands}' if dropped else '')
            + (f' ({info.empty} empty, {info.degenerate} degenerate skipped)'
               if info.empty or info.degenerate else '')
            + f'; units {info.units_words}; up {info.up_words}; face {info.face_words}; '
            + placing)
    return Imported(strands=np.ascontiguousarray(strands[order]), placed=placed, order=order,
                    survey=info, note=note, placing=placing)


def _onto_scalp(poly: Polylines, scalp) -> Tuple[Polylines, int]:
    """Every root moved onto the scalp ellipsoid along its ray from the centre, and into the
    scalp cap (:func:`~hair_tracking.grooms.fit.into_cap`), its strand carried with it, and
    every other vertex pushed out of the ellipsoid scaled by REST_CLEARANCE
    (:func:`~hair_tracking.grooms.fit.push_out`); in place.  Returns the strands and how many
    roots were moved into the cap."""
    center, radii = scalp.center, scalp.radii
    starts = poly.starts
    roots = poly.points[starts]
    on = fit.onto_ellipsoid(roots, center, radii)
    moved = int(np.count_nonzero(fit.into_cap(on, center, radii, scalp)))
    points = poly.points
    fit.shift_strands(points, poly.counts, on - roots)
    roots = points[starts]
    fit.push_out(points, center, radii)
    points[starts] = roots
    return poly, moved


def build_groom(spec: GroomSpec, cache: bool = True) -> Groom:
    """The groom of ``spec``: procedural, or imported from ``spec.file`` (see the module
    docstring), with ``cache`` through :mod:`hair_tracking.grooms.cache` (an unchanged file
    with the same options is read and placed once)."""
    if not spec.file:
        return make_groom(spec)
    if not cache:
        return _imported_groom(spec)
    from hair_tracking.grooms import cache as groom_cache
    name = groom_cache.key(spec)                 # reads the file's ends: once
    groom = groom_cache.load(name)
    if groom is None:
        groom = _imported_groom(spec)
        groom_cache.store(name, groom)
    return groom


def _imported_groom(spec: GroomSpec) -> Groom:
    """The groom of ``spec.file``: imported, its guides chosen."""
    imported = import_groom(spec)
    strands = imported.strands
    count = min(spec.guides, strands.shape[0])
    index = choose_guides_by_shape(strands, count)
    guide_rest = resample.resample(imported.placed.select(imported.order[index]),
                                   spec.guide_nodes)
    fit.push_out(guide_rest[:, 1:], spec.scalp.center, spec.scalp.radii)
    note = imported.note + f'; {count} guides'
    if count < spec.guides:
        note += f' (groom.guides {spec.guides} is more than the strands)'
    if spec.ghosts_per_guide == 0:
        empty = np.zeros((0, spec.ghost_nodes, 3))
        return Groom(guide_rest=guide_rest, ghost_rest=empty, note=note)
    detail = None
    if spec.detail_nodes:
        detail = resample.resample(imported.placed.select(imported.order), spec.detail_nodes)
        fit.push_out(detail[:, 1:], spec.scalp.center, spec.scalp.radii)
    return Groom(guide_rest=guide_rest, ghost_rest=strands, guide_index=index, note=note,
                 detail_rest=detail)
