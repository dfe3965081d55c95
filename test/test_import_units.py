"""hair_sim_bag import reads the units of a recording as users bring them: the time unit of a
pose table (100 ns ticks of .NET / Unity / Windows among them) and the length unit of a BVH,
and it refuses or warns, naming the option, where the timing is no head-pose stream's."""
import decimal
import math

import numpy as np
import pytest

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import DEFAULT_START_TIME_S, main
from hair_tracking.motion import bvh as mocap, head_motion as hm, pose_table as tables

T0 = int(DEFAULT_START_TIME_S * 1e9)
NET_EPOCH_TICKS = 621_355_968_000_000_000        # 1970-01-01 in .NET ticks since 0001-01-01


def _table(path, stamps, header='timestamp,x,y,z,qx,qy,qz,qw'):
    rows = [header]
    for k, t in enumerate(stamps):
        a = 0.01 * k
        rows.append(f'{t},{0.001 * k},0,1.6,0,0,{math.sin(a / 2):.9f},{math.cos(a / 2):.9f}')
    path.write_text('\n'.join(rows) + '\n')
    return path


def test_a_100ns_tick_table_imports_at_its_true_duration_without_flags(tmp_path, capsys):
    """.NET / Unity DateTime ticks (100 ns since 0001-01-01) at 90 Hz for 74.8 s: recognised
    as a date, imported at 74.8 s, with --keep-times on the Unix clock."""
    t0 = 638_680_000_000_000_000                     # 2024-11-23 23:06:40 UTC
    n = 6736
    table = _table(tmp_path / 'ticks.csv', [t0 + k * 111_111 for k in range(n)])
    out = tmp_path / 'ticks.mcap'
    assert main(['import', str(table), '-o', str(out)]) == 0
    text, err = capsys.readouterr()
    assert '100 ns ticks since 0001-01-01' in text and '2024-11-23 23:06:40 UTC' in text
    assert f'{n} poses, 74.833 s, median rate 90.0 Hz' in text and err == ''
    hp = bag_io.read_head_poses(out)
    assert hp.t_ns[0] == T0 and hp.t_ns[-1] - hp.t_ns[0] == (n - 1) * 11_111_100
    kept = tmp_path / 'kept.mcap'
    assert main(['import', str(table), '-o', str(kept), '--keep-times']) == 0
    assert bag_io.read_head_poses(kept).t_ns[0] == (t0 - NET_EPOCH_TICKS) * 100
    # the same table with flags: --time-scale as before; a wrong unit imports with a warning
    # that names the options
    assert main(['import', str(table), '-o', str(tmp_path / 'scaled.mcap'),
                 '--time-scale', '1e-7']) == 0
    assert '74.833 s' in capsys.readouterr().out
    assert main(['import', str(table), '-o', str(tmp_path / 's.mcap'), '--time-unit', 's']) == 0
    text, err = capsys.readouterr()
    assert '748332585.000 s' in text
    assert err.count('\n') == 1 and 'warning' in err and '--time-unit' in err \
        and '--time-scale' in err and 'median rate' in err


@pytest.mark.parametrize('name, stamps, unit, rate', [
    ('relative 100 ns ticks at 60 Hz', [k * 166_667 for k in range(120)], '100ns', 60.0),
    ('microseconds at 30 Hz', [5_000_000 + k * 33_333 for k in range(60)], 'us', 30.0),
    ('milliseconds at 100 Hz', [k * 10 for k in range(100)], 'ms', 100.0),
    ('seconds at 120 Hz', [f'{k / 120:.6f}' for k in range(120)], 's', 120.0),
    ('seconds at 5 Hz', [f'{k / 5:.1f}' for k in range(20)], 's', 5.0),
    ('nanoseconds at 200 Hz', [k * 5_000_000 for k in range(100)], 'ns', 200.0),
    ('Unix seconds', [f'{1_700_000_000 + k / 50:.3f}' for k in range(50)], 's', 50.0),
    ('Unix milliseconds', [1_700_000_000_000 + k * 8 for k in range(50)], 'ms', 125.0),
    ('FILETIME ticks', [133_500_000_000_000_000 + k * 111_111 for k in range(90)], '100ns', 90.0),
])
def test_time_units_are_recognised(tmp_path, name, stamps, unit, rate):
    m = tables.read_pose_table(str(_table(tmp_path / 't.csv', stamps)), time_column='timestamp',
                               time_unit='auto', quat_columns=('qx', 'qy', 'qz', 'qw'),
                               position_columns=('x', 'y', 'z'))
    assert m.units.split(' (auto')[0].split(' since')[0] == tables.TIME_UNIT_WORDS[unit], \
        (name, m.units)
    assert m.rate_hz == pytest.approx(rate, rel=1e-3), name


def test_the_column_name_says_the_unit():
    for column, unit in (('time_ms', 'ms'), ('stamp_us', 'us'), ('t_s', 's'), ('ticks', '100ns'),
                         ('timestamp_ns', 'ns')):
        step = decimal.Decimal(10 ** 7) / tables.TIME_FACTOR_NS[unit]       # 100 Hz
        stamps = [k * step for k in range(10)]
        got, _, words = tables.recognise_time_unit(column, stamps)
        assert got == unit and f'from the name {column!r}' in words, column


def test_implausible_timing_is_refused_naming_the_options(tmp_path, capsys):
    cases = {
        'slow.csv': ['0', '100', '200', '300'],                   # t_s: 0.01 Hz
        'gap.csv': ['0', '0.01', '0.02', '200000'],               # 100 Hz, but over two days
    }
    for name, stamps in cases.items():
        table = _table(tmp_path / name, stamps, header='t_s,x,y,z,qx,qy,qz,qw')
        assert main(['import', str(table), '-o', str(tmp_path / 'x.mcap')]) == 2, name
        err = capsys.readouterr().err
        assert err.count('\n') == 1 and str(table) in err and "'t_s'" in err
        assert '--time-unit' in err and '--time-scale' in err and 'Traceback' not in err
    with pytest.raises(hm.UnitsError, match='no head-pose rate in any unit'):
        tables.recognise_time_unit('t', [decimal.Decimal(0), decimal.Decimal(10 ** 20)])
    assert not (tmp_path / 'x.mcap').exists()


def write_bvh(path, scale: float, frames: int = 60, rate: float = 120.0):
    """A small skeleton standing 1.7 m tall in units of ``scale`` metres (hips, spine, neck,
    head, one leg; CMU axes) walking forward at 1.2 m/s and nodding."""
    u = 1.0 / scale

    def off(x, y, z):
        return f'{x * u:.6f} {y * u:.6f} {z * u:.6f}'
    text = ['HIERARCHY', 'ROOT Hips', '{', f'  OFFSET {off(0, 0, 0)}',
            '  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation',
            '  JOINT Spine', '  {', f'    OFFSET {off(0, 0.3, 0)}',
            '    CHANNELS 3 Zrotation Yrotation Xrotation',
            '    JOINT Neck', '    {', f'      OFFSET {off(0, 0.25, 0)}',
            '      CHANNELS 3 Zrotation Yrotation Xrotation',
            '      JOINT Head', '      {', f'        OFFSET {off(0, 0.1, 0)}',
            '        CHANNELS 3 Zrotation Yrotation Xrotation',
            '        End Site', '        {', f'          OFFSET {off(0, 0.15, 0)}', '        }',
            '      }', '    }', '  }',
            '  JOINT LeftUpLeg', '  {', f'    OFFSET {off(0.1, -0.45, 0)}',
            '    CHANNELS 3 Zrotation Yrotation Xrotation',
            '    End Site', '    {', f'      OFFSET {off(0, -0.45, 0)}', '    }', '  }', '}',
            'MOTION', f'Frames: {frames}', f'Frame Time: {1 / rate:.7f}']
    for k in range(frames):
        t = k / rate
        hips = off(0, 0.9, 1.2 * t)
        nod = 20 * math.sin(2 * math.pi * 2 * t)
        text.append(f'{hips} 0 0 0 0 0 0 0 0 0 0 0 {nod:.5f} 0 0 0')
    path.write_text('\n'.join(text) + '\n')
    return path


@pytest.mark.parametrize('unit', ['cm', 'mm', 'm'])
def test_bvh_units_are_recognised_from_the_skeleton(tmp_path, capsys, unit):
    bvh = write_bvh(tmp_path / f'walk_{unit}.bvh', mocap.BVH_UNITS[unit])
    out = tmp_path / 'walk.mcap'
    assert main(['import', str(bvh), '-o', str(out)]) == 0
    assert f'units {unit} (auto: rest pose' in capsys.readouterr().out
    hp = bag_io.read_head_poses(out)
    speed = np.linalg.norm(hp.position[-1] - hp.position[0]) / (hp.duration_s)
    assert speed == pytest.approx(1.2, rel=0.05)
    assert 1.2 < np.median(hp.position[:, 2]) < 1.8


def test_a_unit_that_makes_no_person_is_refused_naming_the_unit_the_skeleton_suggests(
        tmp_path, capsys):
    bvh = write_bvh(tmp_path / 'walk_cm.bvh', mocap.BVH_UNITS['cm'])
    out = tmp_path / 'walk.mcap'
    assert main(['import', str(bvh), '--units', 'm', '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'Traceback' not in err
    assert 'with units m the rest pose stands 170 m tall' in err
    assert 'the skeleton suggests cm (auto' in err and not out.exists()
    # a scale is the user's word: imported, with the warnings of height and head speed
    assert main(['import', str(bvh), '--scale', '1', '-o', str(out)]) == 0
    err = capsys.readouterr().err
    assert 'the rest pose stands 170 m tall' in err and 'm/s' in err and out.exists()
    assert main(['import', str(bvh), '--units', 'cm', '-o', str(tmp_path / 'ok.mcap')]) == 0
    assert 'warning' not in capsys.readouterr().err


def test_a_table_whose_head_outruns_a_person_is_warned_about(tmp_path, capsys):
    stamps = [str(k / 60) for k in range(60)]
    rows = ['t_s,x,y,z,qx,qy,qz,qw']
    rows += [f'{s},{100.0 * k},0,160,0,0,0,1' for k, s in enumerate(stamps)]
    table = tmp_path / 'mm.csv'
    table.write_text('\n'.join(rows) + '\n')
    assert main(['import', str(table), '-o', str(tmp_path / 'x.mcap')]) == 0
    err = capsys.readouterr().err
    assert 'the head moves at a median 6000 m/s' in err and 'another unit than metres' in err
