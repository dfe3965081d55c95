"""The stolen-CPU figures the benchmarks report (scripts/cpu_steal.py)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'scripts'))
from cpu_steal import cpu_times, format_share, steal_share, StealMeter  # noqa: E402


def write_stat(path, steal, other=(100, 5, 50, 800, 10, 1, 2), guest=(7, 3)):
    user, nice, system, idle, iowait, irq, softirq = other
    with open(path, 'w') as f:
        f.write(f'cpu  {user} {nice} {system} {idle} {iowait} {irq} {softirq} {steal} '
                f'{guest[0]} {guest[1]}\ncpu0 1 2 3 4 5 6 7 8 9 10\nintr 1\n')


def test_reads_steal_and_the_total_without_counting_guest_time_twice(tmp_path):
    stat = tmp_path / 'stat'
    write_stat(stat, steal=40)
    assert cpu_times(str(stat)) == (40, 100 + 5 + 50 + 800 + 10 + 1 + 2 + 40)


def test_share_between_two_readings(tmp_path):
    stat = tmp_path / 'stat'
    write_stat(stat, steal=40)
    meter = StealMeter(str(stat))
    # 100 more jiffies of which 25 stolen
    write_stat(stat, steal=65, other=(150, 5, 60, 815, 10, 1, 2))
    assert meter.share() == pytest.approx(25 / 100)
    assert meter.share() is None                     # no time passed since
    assert steal_share((0, 100), (30, 200)) == pytest.approx(0.3)
    assert steal_share(None, (30, 200)) is None and steal_share((0, 100), (0, 100)) is None


def test_unreadable_or_foreign_files_give_none(tmp_path):
    assert cpu_times(str(tmp_path / 'missing')) is None
    bad = tmp_path / 'bad'
    bad.write_text('intr 1 2 3\n')
    assert cpu_times(str(bad)) is None
    bad.write_text('cpu  1 2 x\n')
    assert cpu_times(str(bad)) is None
    assert StealMeter(str(tmp_path / 'missing')).share() is None
    assert format_share(None) == 'n/a' and format_share(0.1234) == '12.3 %'


@pytest.mark.skipif(not os.path.exists('/proc/stat'), reason='Linux only')
def test_this_machine_reports_its_counters():
    steal, total = cpu_times()
    assert 0 <= steal <= total and total > 0
