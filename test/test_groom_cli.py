"""``hair_sim_groom`` (info, convert, preview) and ``hair_sim_bag run`` on an imported groom of
every format; bad files give one line naming the byte and exit 3."""
import os
import subprocess
import sys

import numpy as np
import pytest

import groom_files as gf
from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import main as bag_main
from hair_tracking.bags.groom_cli import main
from hair_tracking.core.scene import Scene
from hair_tracking.grooms.build import import_groom
from hair_tracking.grooms.formats import read_strands

from recordings import write_walk_bag

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    """The synthetic groom (cm, y up, head 1.6 m up) in every format the tests write."""
    d = tmp_path_factory.mktemp('grooms')
    strands = gf.to_file_frame(gf.synthetic_groom(80, 14, seed=11))
    out = {}
    for ext, write in gf.WRITERS.items():
        out[ext] = d / ('groom' + ext)
        write(out[ext], strands)
    return out


def test_info_tells_counts_lengths_box_units_and_up_axis(files, capsys):
    assert main(['info', str(files['.hair'])]) == 0
    text = capsys.readouterr().out
    for needle in ("Cem Yuksel's .hair", 'strands:   80 of 80', 'vertices:', 'lengths:   min',
                   'box:', 'units:     cm (guessed', 'up axis:   y (guessed', 'on the head: '
                   'fitted onto the scalp'):
        assert needle in text, needle


def test_convert_writes_the_strands_as_read_or_as_on_the_head(files, tmp_path, capsys):
    out = tmp_path / 'raw.npz'
    assert main(['convert', str(files['.data']), '-o', str(out)]) == 0
    raw, src = read_strands(str(out)), read_strands(str(files['.data']))
    assert np.array_equal(raw.counts, src.counts) and np.array_equal(raw.points, src.points)
    assert raw.meters_per_unit is None and raw.up_axis is None     # guesses stay guesses
    stated = tmp_path / 'stated.npz'
    assert main(['convert', str(files['.data']), '-o', str(stated), '--units', 'cm',
                 '--up-axis', 'y']) == 0
    said = read_strands(str(stated))
    assert said.meters_per_unit == pytest.approx(0.01) and said.up_axis == 'y'
    capsys.readouterr()
    for extra in (['--rotation', '0,0,90'], ['--max-strands', '10']):
        assert main(['convert', str(files['.data']), '-o', str(tmp_path / 'no.npz')]
                    + extra) == 2
        assert 'add --imported' in capsys.readouterr().err
    assert not (tmp_path / 'no.npz').exists()
    head = tmp_path / 'head.npz'
    assert main(['convert', str(files['.data']), '-o', str(head), '--imported',
                 '--nodes', '12']) == 0
    with np.load(head) as z:
        assert z['counts'].tolist() == [12] * 80
        spec = Scene().with_changes(groom__file=str(files['.data']), groom__ghost_nodes=12).groom
        np.testing.assert_allclose(z['points'].reshape(80, 12, 3), import_groom(spec).strands,
                                   atol=1e-6)
    # the converted file imports as the original does
    a = import_groom(Scene().with_changes(groom__file=str(out)).groom)
    b = import_groom(Scene().with_changes(groom__file=str(files['.data'])).groom)
    np.testing.assert_allclose(a.strands, b.strands, atol=1e-6)
    assert main(['convert', str(files['.data']), '-o', str(out)]) == 5       # exists
    assert main(['convert', str(files['.data']), '-o', str(tmp_path / 'x.txt')]) == 2
    capsys.readouterr()


def test_preview_draws_front_and_side(files, tmp_path, capsys):
    from PIL import Image
    out = tmp_path / 'groom.png'
    assert main(['preview', str(files['.ply']), '-o', str(out), '--max-strands', '40']) == 0
    assert 'wrote' in capsys.readouterr().out
    with Image.open(out) as im:
        w, h = im.size
        pixels = np.asarray(im.convert('RGB'), dtype=np.int32)
    assert w > 1.5 * h                                   # two views side by side
    hair = np.abs(pixels - [0x6b, 0x44, 0x23]).sum(axis=2) < 120      # the hair's colour
    assert hair[:, : w // 2].sum() > 50 and hair[:, w // 2:].sum() > 50


@pytest.mark.parametrize('command', ['info', 'convert', 'preview'])
def test_a_bad_file_is_one_line_with_exit_3(files, tmp_path, capsys, command):
    data = files['.hair'].read_bytes()
    bad = tmp_path / 'cut.hair'
    bad.write_bytes(data[:200])
    extra = [] if command == 'info' else ['-o', str(tmp_path / ('o.npz' if command ==
                                                                'convert' else 'o.png'))]
    assert main([command, str(bad)] + extra) == 3
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and f'{bad}: byte 128: expected' in err
    assert main([command, str(tmp_path / 'none.data')] + extra) == 3
    assert 'file not found' in capsys.readouterr().err
    assert not (tmp_path / 'o.npz').exists() and not (tmp_path / 'o.png').exists()


def test_usage_errors_exit_2_without_a_traceback(files, tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT)
    for args, code in ((['preview', str(files['.bin'])], 2),
                       (['info', str(files['.bin']), '--units', 'furlong'], 2),
                       (['info', str(files['.bin']), '--rotation', '1,2'], 2),
                       (['info', str(tmp_path / 'x.abc')], 3)):
        proc = subprocess.run([sys.executable, '-m', 'hair_tracking.bags.groom_cli'] + args,
                              capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
        assert proc.returncode == code, proc.stderr
        assert 'Traceback' not in proc.stderr and 'error' in proc.stderr


@pytest.fixture(scope='module')
def walk(tmp_path_factory):
    return write_walk_bag(tmp_path_factory.mktemp('walk') / 'walk.mcap', 0.4)


@pytest.mark.parametrize('ext', list(gf.WRITERS))
def test_hair_sim_bag_runs_each_format(files, walk, tmp_path, capsys, ext, one_numba_thread):
    out = tmp_path / 'out.mcap'
    args = ['run', str(walk), '-o', str(out), '-q', '--set', f'groom.file={files[ext]}',
            '--set', 'groom.guides=8', '--set', 'solver.settle_time=0.05']
    assert bag_main(args) == 0
    text = capsys.readouterr().out
    assert f'groom {files[ext]}' in text and 'hair: 80 strands x 16 points' in text
    counts = {t.topic: t.count for t in bag_io.bag_info(out)['topics']}
    assert counts['/hair/points'] > 5


def test_hair_sim_bag_refuses_a_bad_groom_file_with_exit_3(files, walk, tmp_path, capsys):
    bad = tmp_path / 'bad.data'
    bad.write_bytes(np.int32(3).tobytes())
    assert bag_main(['run', str(walk), '-o', str(tmp_path / 'o.mcap'), '-q',
                     '--set', f'groom.file={bad}']) == 3
    err = capsys.readouterr().err
    assert 'groom.file:' in err and 'bad.data: byte 0: expected a strand count' in err
    assert not (tmp_path / 'o.mcap').exists()


def test_units_that_make_no_head_of_hair_are_refused_naming_the_guess(tmp_path, capsys):
    mm = tmp_path / 'mm.data'
    gf.write_data(mm, gf.to_file_frame(gf.synthetic_groom(40, 10, seed=3), unit=0.001))
    assert main(['info', str(mm), '--units', 'cm']) == 3
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and 'with units cm the roots span' in err
    assert 'the strands suggest mm (guessed' in err
    assert main(['info', str(mm)]) == 0 and 'mm (guessed' in capsys.readouterr().out
    # right units, fitted with a scale: near 1
    spec = Scene().with_changes(groom__file=str(mm), groom__fit='scale').groom
    assert 'scaled by 1.0' in import_groom(spec).note


@pytest.mark.parametrize('ext', ['.hair', '.data', '.ply', '.npz', '.usda', '.usdc'])
def test_convert_writes_every_format_and_it_reads_back(files, tmp_path, ext):
    out = tmp_path / ('out' + ext)
    assert main(['convert', str(files['.data']), '-o', str(out), '--units', 'cm',
                 '--up-axis', 'y']) == 0
    src, back = read_strands(str(files['.data'])), read_strands(str(out))
    assert np.array_equal(back.counts, src.counts)
    np.testing.assert_array_equal(back.points.astype(np.float32), src.points.astype(np.float32))
    if ext in ('.npz', '.usda', '.usdc'):                  # the layouts that carry them
        assert back.meters_per_unit == pytest.approx(0.01) and back.up_axis == 'y'
    head = tmp_path / ('head' + ext)
    assert main(['convert', str(files['.data']), '-o', str(head), '--imported',
                 '--nodes', '10']) == 0
    on_head = import_groom(Scene().with_changes(groom__file=str(files['.data']),
                                                groom__ghost_nodes=10).groom).strands
    np.testing.assert_allclose(read_strands(str(head)).points.reshape(on_head.shape), on_head,
                               atol=1e-6)


def test_export_writes_a_run_as_an_animated_usd_file(walk, tmp_path, capsys):
    from pxr import Usd, UsdGeom
    from msg_adapters.pointcloud import pointcloud2_to_strands
    run = tmp_path / 'run.mcap'
    assert bag_main(['run', str(walk), '-o', str(run), '-q', '--set', 'groom.guides=6',
                     '--set', 'groom.ghosts_per_guide=3', '--set', 'groom.ghost_nodes=8',
                     '--set', 'solver.settle_time=0.1']) == 0
    usd = tmp_path / 'hair.usda'
    assert bag_main(['export', str(run), '-o', str(usd)]) == 0
    assert 'frames of 18 strands x 8 points' in capsys.readouterr().out
    with bag_io.open_bag(run) as r:
        conns = [c for c in r.connections if c.topic == '/hair/points']
        clouds = [pointcloud2_to_strands(bag_io.deserialize(r, raw, c.msgtype))[0]
                  for c, _, raw in bag_io.messages(r, conns)]
    stage = Usd.Stage.Open(str(usd))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath('/groom/hair'))
    times = curves.GetPointsAttr().GetTimeSamples()
    assert times == list(range(len(clouds))) and len(clouds) > 5
    assert stage.GetEndTimeCode() == len(clouds) - 1 and 25 < stage.GetTimeCodesPerSecond() < 35
    for k in (0, len(clouds) - 1):
        got = np.asarray(curves.GetPointsAttr().Get(k))
        np.testing.assert_array_equal(got, clouds[k].reshape(-1, 3).astype(np.float32))
    assert list(curves.GetCurveVertexCountsAttr().Get(0)) == [8] * 18
    assert UsdGeom.GetStageUpAxis(stage) == 'Z' and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert read_strands(str(usd)).count == 18            # a still groom: the first frame
