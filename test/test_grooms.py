"""Groom files: every format read back from the tests' own writers (test/groom_files.py), bad
files refused in one line that names the byte, resampling, subsets, units and up-axis guesses,
the fit onto the scalp and the guides chosen among the imported strands."""
from dataclasses import replace

import numpy as np
import pytest

import groom_files as gf
from hair_tracking.core.groom import make_groom, REST_CLEARANCE
from hair_tracking.core.scene import Scene
from hair_tracking.grooms import fit, resample
from hair_tracking.grooms.build import build_groom, import_groom, survey
from hair_tracking.grooms.formats import read_strands
from hair_tracking.grooms.guides import choose_guides_by_shape, farthest_points
from hair_tracking.grooms.polylines import GroomFileError, Polylines

FORMATS = ['.hair', '.data', '.bin', '.ply', '.npz']


@pytest.fixture(scope='module')
def groom():
    """The synthetic groom [m, head frame] and as a DCC file holds it (cm, y up, head 1.6 m
    up)."""
    g = gf.synthetic_groom(200, 20, seed=3)
    return g, gf.to_file_frame(g)


def spec_for(path, **changes):
    return Scene().with_changes(groom__file=str(path), **changes).groom


# ------------------------------------------------------------------ reading
@pytest.mark.parametrize('ext', FORMATS + ['ascii.ply'])
def test_every_format_reads_back_what_was_written(tmp_path, groom, ext):
    _, strands = groom
    path = tmp_path / ('g' + ext if ext.startswith('.') else 'g_' + ext)
    if ext == 'ascii.ply':
        gf.write_ply(path, strands, binary=False)
    else:
        gf.WRITERS[ext](path, strands)
    poly = read_strands(str(path))
    points, counts = gf.flat(strands)
    assert np.array_equal(poly.counts, counts)
    assert np.array_equal(poly.points, points.astype(np.float64))


def test_hair_without_a_segments_array_uses_the_default_count(tmp_path, groom):
    g = gf.synthetic_groom(30, 12, ragged=False)
    gf.write_hair(tmp_path / 'g.hair', g, segments_array=False)
    poly = read_strands(str(tmp_path / 'g.hair'))
    assert np.array_equal(poly.counts, np.full(30, 12))
    assert np.allclose(poly.points, np.concatenate(g), atol=1e-6)


def test_usd_basis_curves_read_with_their_units_and_up_axis(tmp_path, groom):
    pytest.importorskip('pxr', reason='usd-core is not installed (optional extra [usd])')
    _, strands = groom
    gf.write_usd(tmp_path / 'g.usda', strands, meters_per_unit=0.01, up='Y')
    poly = read_strands(str(tmp_path / 'g.usda'))
    points, counts = gf.flat(strands)
    assert np.array_equal(poly.counts, counts)
    assert np.allclose(poly.points, points, rtol=0, atol=1e-4)
    assert poly.meters_per_unit == pytest.approx(0.01) and poly.up_axis == 'y'
    info, _ = survey(str(tmp_path / 'g.usda'))
    assert 'stated by the file' in info.units_words and info.up == 'y'


def test_usd_without_usd_core_says_how_to_get_it(tmp_path, monkeypatch):
    import builtins
    real = builtins.__import__

    def no_pxr(name, *a, **kw):
        if name == 'pxr' or name.startswith('pxr.'):
            raise ImportError(name)
        return real(name, *a, **kw)
    monkeypatch.setattr(builtins, '__import__', no_pxr)
    with pytest.raises(GroomFileError, match='usd-core'):
        read_strands(str(tmp_path / 'g.usd'))


# ------------------------------------------------------------------ bad files
def _bad(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(GroomFileError) as e:
        read_strands(str(path))
    text = str(e.value)
    assert '\n' not in text and text.startswith(str(path)) and 'expected' in text
    return text


def _written(tmp_path, ext, strands):
    path = tmp_path / ('src' + ext)
    gf.WRITERS[ext](path, strands)
    return path.read_bytes()


@pytest.mark.parametrize('ext', FORMATS)
def test_a_truncated_file_names_the_byte_where_it_ends(tmp_path, groom, ext):
    data = _written(tmp_path, ext, groom[1])
    text = _bad(tmp_path, 'cut' + ext, data[:len(data) * 2 // 3])
    assert 'byte' in text or ext == '.npz'


@pytest.mark.parametrize('ext', ['.hair', '.ply'])
def test_a_wrong_magic_is_named(tmp_path, groom, ext):
    data = _written(tmp_path, ext, groom[1])
    text = _bad(tmp_path, 'magic' + ext, b'XXXX' + data[4:])
    assert 'byte 0' in text and 'magic' in text


def test_counts_that_overrun_the_file_are_refused_at_their_byte(tmp_path, groom):
    data = bytearray(_written(tmp_path, '.data', groom[1]))
    first = int(np.frombuffer(bytes(data[4:8]), '<i4')[0])
    data[4:8] = np.int32(first + 1_000_000).tobytes()
    text = _bad(tmp_path, 'over.data', bytes(data))
    assert 'byte 8 (strand 0)' in text and f'{first + 1_000_000} vertices' in text
    data = bytearray(_written(tmp_path, '.data', groom[1]))
    data[0:4] = np.int32(10**9).tobytes()
    assert 'byte 0' in _bad(tmp_path, 'many.data', bytes(data))
    hair = bytearray(_written(tmp_path, '.hair', groom[1]))
    hair[8:12] = np.uint32(10**6).tobytes()              # the header's point count
    assert 'byte 128' in _bad(tmp_path, 'over.hair', bytes(hair))
    ct = bytearray(_written(tmp_path, '.bin', groom[1]))
    ct[4:8] = np.int32(-3).tobytes()
    assert 'byte 4 (strand 0)' in _bad(tmp_path, 'neg.bin', bytes(ct))


@pytest.mark.parametrize('ext', FORMATS)
def test_nan_vertices_are_refused_with_their_place(tmp_path, groom, ext):
    strands = [p.copy() for p in groom[1]]
    strands[2][3, 1] = np.nan
    vertex = sum(len(p) for p in strands[:2]) + 3
    text = _bad(tmp_path, 'nan' + ext, _written(tmp_path, ext, strands))
    assert f'vertex {vertex}' in text and 'finite' in text
    if ext == '.data':
        assert f'byte {4 * (2 + 2 + 3 * vertex)}' in text
    if ext == '.hair':
        assert f'byte {128 + 2 * len(strands) + 12 * vertex}' in text


def test_zero_strands_are_refused(tmp_path):
    assert 'at least 1' in _bad(tmp_path, 'zero.data', np.int32(0).tobytes())
    gf.write_hair(tmp_path / 'src.hair', [np.zeros((2, 3))])
    data = bytearray((tmp_path / 'src.hair').read_bytes())
    data[4:12] = np.zeros(2, np.uint32).tobytes()        # 0 hairs, 0 points
    assert 'byte 4' in _bad(tmp_path, 'zero.hair', bytes(data[:128]) + b'')


def test_an_unknown_extension_and_a_missing_file(tmp_path):
    with pytest.raises(GroomFileError, match='extensions'):
        read_strands(str(tmp_path / 'g.abc'))
    with pytest.raises(GroomFileError, match='file not found'):
        read_strands(str(tmp_path / 'none.data'))


def test_empty_and_degenerate_strands_are_skipped_and_counted(tmp_path, groom):
    strands = list(groom[1][:50]) + [np.zeros((1, 3)), np.ones((5, 3)), np.zeros((0, 3))]
    gf.write_data(tmp_path / 'g.data', strands)
    info, poly = survey(str(tmp_path / 'g.data'))
    assert (info.strands, info.empty, info.degenerate, poly.count) == (53, 2, 1, 50)
    imported = import_groom(spec_for(tmp_path / 'g.data'))
    assert imported.strands.shape[0] == 50 and '2 empty, 1 degenerate skipped' in imported.note
    gf.write_data(tmp_path / 'none.data', [np.zeros((1, 3)), np.ones((4, 3))])
    with pytest.raises(GroomFileError, match='1 empty and 1 degenerate'):
        import_groom(spec_for(tmp_path / 'none.data'))


# ------------------------------------------------------------------ resampling, subsets
def test_resampling_spaces_the_nodes_evenly_along_the_arc_and_keeps_root_and_tip():
    # an L: 3 m along x then 1 m along z, with a repeated vertex in the middle of the first leg
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [3, 0, 0], [3, 0, 1.0]])
    poly = Polylines(np.concatenate([p, p[:2] * 2.0]), np.array([5, 2]), 'test')
    out = resample.resample(poly, 5)
    assert np.allclose(out[0], [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [3, 0, 1]])
    assert np.allclose(out[1], np.linspace([0, 0, 0], [2, 0, 0], 5))
    assert np.allclose(resample.strand_lengths(poly), [4.0, 2.0])


def test_max_strands_keeps_an_even_deterministic_subset(tmp_path, groom):
    gf.write_data(tmp_path / 'g.data', groom[1])
    a = import_groom(spec_for(tmp_path / 'g.data', groom__max_strands=50))
    b = import_groom(spec_for(tmp_path / 'g.data', groom__max_strands=50))
    assert a.strands.shape[0] == 50 and np.array_equal(a.strands, b.strands)
    assert '50 strands of 200' in a.note
    # a scalp whose file lists the strands from front to back: the subset still covers it all,
    # closer on average than 100 strands drawn at random do
    rng = np.random.default_rng(0)
    u = rng.normal(size=(1000, 3))
    u[:, 2] = np.abs(u[:, 2])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    roots = 0.1 * u[np.argsort(u[:, 0])]
    pick = resample.spread_subset(roots, 100)
    assert len(set(pick.tolist())) == 100

    def cover(idx):          # how far a root is from the nearest kept one, on average
        return np.linalg.norm(roots[:, None] - roots[idx][None], axis=2).min(axis=1).mean()
    assert cover(pick) < 0.25 * cover(np.arange(100))
    assert cover(pick) < np.mean([cover(rng.choice(1000, 100, replace=False))
                                  for _ in range(10)])
    assert np.array_equal(resample.spread_subset(roots, 0), np.arange(1000))


# ------------------------------------------------------------------ units, axes, fit
@pytest.mark.parametrize('unit, name', [(1.0, 'm'), (0.01, 'cm'), (0.001, 'mm'),
                                        (0.0254, 'in'), (0.00254, 'tenth_in')])
@pytest.mark.parametrize('up', ['y', 'z'])
def test_units_and_up_axis_are_guessed(tmp_path, groom, unit, name, up):
    gf.write_data(tmp_path / 'g.data', gf.to_file_frame(groom[0], unit=unit, up=up))
    info, _ = survey(str(tmp_path / 'g.data'))
    assert (info.unit, info.up) == (fit.GROOM_UNITS[name], up)
    assert name in info.units_words and 'guessed' in info.up_words


def test_the_imported_groom_sits_on_the_scalp_with_the_file_s_shapes(tmp_path, groom):
    g, strands = groom
    gf.write_hair(tmp_path / 'g.hair', strands)
    spec = spec_for(tmp_path / 'g.hair')
    imported = import_groom(spec)
    s = imported.strands
    c, a = np.array(spec.scalp.center), np.array(spec.scalp.radii)
    assert s.shape == (200, spec.ghost_nodes, 3)
    assert np.allclose(np.linalg.norm((s[:, 0] - c) / a, axis=1), 1.0)         # on the scalp
    assert (np.linalg.norm((s[:, 1:] - c) / a, axis=2) >= REST_CLEARANCE - 1e-9).all()
    seg = np.linalg.norm(np.diff(s, axis=1), axis=2)
    assert np.median(seg.max(axis=1) / seg.min(axis=1)) < 1.25   # even, but for curls' chords
    # the synthetic groom's shapes, turned back into the head frame: each imported strand (from
    # its root) has its twin there, but where the scalp pushed a node out
    want = resample.resample(Polylines(np.concatenate(g), np.array([len(p) for p in g]), ''),
                             spec.ghost_nodes)
    rel, rel_want = s - s[:, :1], want - want[:, :1]
    gap = np.sqrt(np.mean(np.sum((rel[:, None] - rel_want[None]) ** 2, axis=3), axis=2))
    assert np.median(gap.min(axis=1)) < 1e-3
    assert np.mean(gap.min(axis=1) < 0.01) > 0.9


def test_rotation_offset_and_scale_options(tmp_path, groom):
    g, _ = groom
    # a z-up file in millimetres, already in the head frame, and the same groom turned -90 deg
    # about z: groom.file_rotation_deg turns it back
    gf.write_data(tmp_path / 'g.data', gf.to_file_frame(g, unit=0.001, up='z', origin=(0, 0, 0)))
    turned = [p @ fit.rotation([0, 0, -90]).T for p in g]
    gf.write_data(tmp_path / 't.data',
                  gf.to_file_frame(turned, unit=0.001, up='z', origin=(0, 0, 0)))
    direct = import_groom(spec_for(tmp_path / 'g.data', groom__fit='none'))
    back = import_groom(spec_for(tmp_path / 't.data', groom__fit='none',
                                 groom__file_rotation_deg=[0, 0, 90]))
    assert 'not fitted' in back.note
    gap = np.abs(back.strands[:, None] - direct.strands[None]).max(axis=(2, 3)).min(axis=1)
    assert gap.max() < 1e-5
    lifted = import_groom(spec_for(tmp_path / 'g.data', groom__fit='none',
                                   groom__file_offset=[0.0, 0.0, 0.02]))
    assert np.mean(lifted.strands[:, 0, 2]) > np.mean(direct.strands[:, 0, 2]) + 0.005
    scaled = import_groom(spec_for(tmp_path / 'g.data', groom__fit='scale'))
    assert 'scaled by' in scaled.note


def test_the_fit_finds_a_known_translation_and_scale():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(400, 3))
    u[:, 2] = np.abs(u[:, 2])                               # the upper half: a scalp
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    c, a = np.zeros(3), np.array([0.095, 0.08, 0.105])
    roots = (u * a) / 1.3 - [0.01, 0.02, 1.5]               # shrunk and moved away
    s, t, rms = fit.fit_to_scalp(roots, c, a, scale=True)
    assert s == pytest.approx(1.3, rel=1e-6) and rms < 1e-8
    assert np.allclose(s * roots + t, u * a, atol=1e-8)
    s, t, rms = fit.fit_to_scalp(u * a + [0.3, 0.0, 0.1], c, a, scale=False)
    assert s == 1.0 and np.allclose(t, [-0.3, 0.0, -0.1], atol=1e-8)


# ------------------------------------------------------------------ guides
def test_guides_by_shape_cover_the_shapes_that_roots_alone_miss():
    """Two families of strands on one scalp, interleaved: straight ones and ones bent far
    forward.  Farthest points over the roots alone may pick a family only by luck; over roots
    and shapes both families get guides in proportion."""
    rng = np.random.default_rng(2)
    u = rng.normal(size=(400, 3))
    u[:, 2] = np.abs(u[:, 2]) + 0.3
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    roots = u * 0.1
    bent = rng.random(400) < 0.1
    t = np.linspace(0, 0.25, 16)[None, :, None]
    rest = roots[:, None] + t * np.where(bent[:, None, None], [[[1.0, 0, -0.2]]],
                                         [[[0.0, 0, -1.0]]])
    pick = choose_guides_by_shape(rest, 20)
    assert np.array_equal(pick, choose_guides_by_shape(rest, 20))
    assert bent[pick].sum() >= 4                        # a tenth of the strands, a fifth of
    assert (~bent[pick]).sum() >= 8                     # the guides or more
    roots_only = farthest_points(roots, 20)
    assert bent[pick].sum() > bent[roots_only].sum()


def test_build_groom_gives_ghosts_guides_and_the_paper_tracker_s_rests(tmp_path, groom):
    gf.write_ply(tmp_path / 'g.ply', groom[1])
    spec = spec_for(tmp_path / 'g.ply', groom__guides=24, groom__guide_nodes=10)
    g = build_groom(spec)
    assert g.ghost_rest.shape == (200, spec.ghost_nodes, 3)
    assert g.guide_rest.shape == (24, 10, 3) and g.guide_index.shape == (24,)
    # the paper tracker's guides are the chosen strands, at their own node count
    assert np.allclose(g.guide_rest[:, 0], g.ghost_rest[g.guide_index, 0])
    assert np.allclose(g.guide_rest[:, -1], g.ghost_rest[g.guide_index, -1], atol=1e-9)
    alone = build_groom(spec_for(tmp_path / 'g.ply', groom__guides=500,
                                 groom__ghosts_per_guide=0))
    assert alone.ghost_rest.shape[0] == 0 and alone.guide_rest.shape[0] == 200
    assert 'more than the strands' in alone.note


def test_the_procedural_groom_is_untouched():
    spec = Scene().groom
    a, b = build_groom(spec), make_groom(spec)
    assert np.array_equal(a.ghost_rest, b.ghost_rest) and a.guide_index is None


@pytest.mark.parametrize('up', ['x', '-x', 'y', '-y', 'z', '-z'])
def test_a_groom_with_any_axis_up_lands_upright(tmp_path, up):
    """A groom written in cm with each file axis (either way) up, facing that axis's forward
    (:data:`fit.FORWARD`), the head 1.6 m up: the up axis is guessed and the strands land as
    the z-up file's do."""
    head = gf.synthetic_groom(60, 12, seed=5)
    for name, m in (('ref', fit.AXES['z']), (up, fit.AXES[up])):     # head = m @ file
        gf.write_data(tmp_path / f'{name}.data', [(h + [0.0, 0.0, 1.6]) @ m / 0.01
                                                  for h in head])
    info, _ = survey(str(tmp_path / f'{up}.data'))
    assert info.up == up and info.up_words.startswith(f'{up} (guessed: the tips hang')
    assert 'turn the rest' not in info.up_words
    got = import_groom(Scene().with_changes(groom__file=str(tmp_path / f'{up}.data')).groom)
    ref = import_groom(Scene().with_changes(groom__file=str(tmp_path / 'ref.data'),
                                            groom__up_axis='z').groom)
    np.testing.assert_allclose(got.strands, ref.strands, atol=1e-6)
    assert np.mean(got.strands[:, 0, 2]) > np.mean(got.strands[:, -1, 2])   # roots above tips


def test_hair_hanging_between_axes_is_reported_with_how_far_off():
    rng = np.random.default_rng(0)
    roots = rng.normal(size=(50, 3)) * 0.05
    a = np.radians(40.0)                               # hanging 40 deg from -z toward +x
    tips = roots + 0.3 * np.array([np.sin(a), 0.0, -np.cos(a)])
    up, words = fit.guess_up(roots, tips, np.full(50, 0.3))
    assert up == 'z' and '40 deg from it' in words and 'file_rotation_deg' in words


def test_an_imported_groom_is_built_once_and_again_when_its_file_or_options_change(
        tmp_path, monkeypatch):
    from hair_tracking.grooms import build, cache
    monkeypatch.setattr(cache, 'folder', lambda: str(tmp_path / 'cache'))
    built = []
    real = build._imported_groom
    monkeypatch.setattr(build, '_imported_groom', lambda spec: built.append(1) or real(spec))
    path = tmp_path / 'g.data'
    gf.write_data(path, gf.to_file_frame(gf.synthetic_groom(40, 10, seed=1)))
    spec = Scene().with_changes(groom__file=str(path), groom__guides=8).groom
    first, again = build_groom(spec), build_groom(spec)
    assert len(built) == 1
    for a, b in ((first.ghost_rest, again.ghost_rest), (first.guide_rest, again.guide_rest),
                 (first.guide_index, again.guide_index)):
        assert np.array_equal(a, b)
    assert first.note == again.note
    gf.write_data(path, gf.to_file_frame(gf.synthetic_groom(40, 10, seed=2)))   # same size
    other = build_groom(spec)
    assert len(built) == 2 and not np.array_equal(other.ghost_rest, first.ghost_rest)
    build_groom(replace(spec, guides=9))
    assert len(built) == 3
    lean = build_groom(replace(spec, ghosts_per_guide=0))
    assert lean.guide_index is None and build_groom(replace(spec, ghosts_per_guide=0)) \
        .guide_index is None and len(built) == 4
    for k in range(cache.ENTRIES + 3):
        build_groom(replace(spec, guides=10 + k))
    assert len(list((tmp_path / 'cache').iterdir())) == cache.ENTRIES
    monkeypatch.setattr(cache, 'folder', lambda: str(path / 'not a folder'))
    assert np.array_equal(build_groom(spec).ghost_rest, other.ghost_rest)    # no cache: built


FACES = [(up, face) for up in fit.UP_AXES for face in fit.UP_AXES if face[-1] != up[-1]]


@pytest.mark.parametrize('up, face', FACES)
def test_a_groom_lands_upright_facing_forward_whatever_its_axes(tmp_path, up, face):
    """All 24 right-angle orientations of a groom (each file axis up, either way, facing each
    axis across it), in mm, cm or m: the up axis is guessed from where the tips hang, the face
    from the side the roots leave open, and the strands land as the z-up, x-facing file's do:
    roots on the top of the scalp, the fringe in front of the face."""
    head = gf.synthetic_groom(80, 12, seed=7)
    unit = (0.001, 0.01, 1.0)[FACES.index((up, face)) % 3]
    for name, m in (('ref', fit.axes('z', 'x')), ('file', fit.axes(up, face))):
        gf.write_data(tmp_path / f'{name}.data', [(h + [0.0, 0.0, 1.6]) @ m / unit
                                                  for h in head])
    info, _ = survey(str(tmp_path / 'file.data'))
    assert (info.up, info.face) == (up, face)
    assert info.face_words.startswith(f'{face} (guessed: the roots leave the scalp open toward '
                                      f'{face}, clearly')
    got = import_groom(Scene().with_changes(groom__file=str(tmp_path / 'file.data')).groom)
    ref = import_groom(Scene().with_changes(groom__file=str(tmp_path / 'ref.data'),
                                            groom__up_axis='z', groom__face_axis='x').groom)
    np.testing.assert_allclose(got.strands, ref.strands, atol=1e-6)
    roots, tips = got.strands[:, 0], got.strands[:, -1]
    assert np.mean(roots[:, 2] < 0.0) < 0.1         # on the top of the head, but the nape
    fringe = roots[:, 0] > 0.03                                 # roots at the front ...
    assert fringe.any() and np.all(tips[fringe, 0] > 0.03)     # ... hang in front of the face


def test_the_face_is_the_convention_when_the_roots_cover_the_head_evenly(tmp_path):
    rng = np.random.default_rng(4)
    u = rng.normal(size=(500, 3))
    u[:, 1] = np.abs(u[:, 1])                           # the upper half of a y-up head [cm]
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    roots = u * 9.0 + [1.0, 160.0, 2.0]
    face, words, asym = fit.guess_face(roots, 'y')
    assert face == '' and asym < fit.MIN_FACE_ASYMMETRY and 'no side' in words
    gf.write_data(tmp_path / 'g.data', [np.linspace(r, r - [0.0, 30.0, 0.0], 8) for r in roots])
    info, _ = survey(str(tmp_path / 'g.data'))
    assert (info.up, info.face) == ('y', 'z')
    assert info.face_words.startswith('z (the convention of a file with y up: the roots leave '
                                      'no side')


def test_a_face_axis_along_the_up_axis_is_refused(tmp_path):
    from hair_tracking.core.scene import SceneError
    with pytest.raises(SceneError, match='groom.face_axis: must lie across groom.up_axis y'):
        Scene().with_changes(groom__up_axis='y', groom__face_axis='-y').validate()
    gf.write_data(tmp_path / 'g.data', gf.to_file_frame(gf.synthetic_groom(30, 8, seed=2)))
    with pytest.raises(GroomFileError, match='the face axis y lies along the up axis y'):
        survey(str(tmp_path / 'g.data'), face_axis='y')


def test_roots_off_the_scalp_cap_are_moved_to_its_edge_and_reported(tmp_path):
    """A groom whose roots run down over the face and under the chin: those roots go to the
    cap's edge at their azimuth (never on the face, chin or neck), their strands with them,
    and the note says how many."""
    head = gf.synthetic_groom(80, 10, seed=3)
    rng = np.random.default_rng(0)
    extra = []
    for _ in range(20):                                 # roots on the face and under the chin
        u = np.array([1.0, rng.uniform(-0.3, 0.3), rng.uniform(-0.9, 0.2)])
        u /= np.linalg.norm(u)
        root = u * gf.HEAD_RADII
        extra.append(root + np.linspace(0.0, 0.05, 6)[:, None] * [0.6, 0.0, -0.8])
    gf.write_data(tmp_path / 'g.data', [(h + [0.0, 0.0, 1.6]) / 0.01 for h in head + extra])
    spec = Scene().with_changes(groom__file=str(tmp_path / 'g.data'), groom__up_axis='z',
                                groom__face_axis='x').groom
    got = import_groom(spec)
    c, a = np.array(spec.scalp.center), np.array(spec.scalp.radii)
    u = (got.strands[:, 0] - c) / a
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    from hair_tracking.core.groom import in_scalp
    polar = np.degrees(np.arccos(np.clip(u[:, 2], -1, 1)))
    assert np.all(in_scalp(u, spec.scalp) | (polar < spec.scalp.max_polar_deg + 1e-6))
    assert np.all(polar[u[:, 0] > 0.9] <= spec.scalp.front_max_polar_deg + 1e-6)
    assert 'off the scalp cap' in got.placing and 'moved to its edge' in got.note
    moved = int(got.placing.split('; ')[-1].split()[0])
    assert 20 <= moved <= 40
