"""Bags a recorder left cut short: an output bag of ``hair_sim_bag run`` cut at several bytes is
read to its last whole message by every reader (info, run, import, play's bag side), ``recover``
writes a clean copy, and damaged files get a one-line error naming the file, the byte and what
was expected."""
import struct
from pathlib import Path

import numpy as np
import pytest

from hair_tracking.bags import io as bag_io
from hair_tracking.bags.cli import main
from hair_tracking.bags.mcap_salvage import is_cut, MAGIC
from hair_tracking.bags.play import Playback

SMALL = ['groom.guides=6', 'groom.ghosts_per_guide=3', 'groom.guide_nodes=8',
         'groom.ghost_nodes=8', 'solver.settle_time=0.1']


def _plain_messages(path):
    """{topic: [(log ns, raw bytes)]} of a whole bag, read with the plain rosbags reader."""
    from rosbags.highlevel import AnyReader
    out = {}
    with AnyReader([Path(path)], default_typestore=bag_io.typestore()) as r:
        for c, t, raw in r.messages():
            out.setdefault(c.topic, []).append((t, bytes(raw)))
    return out


def _records(data):
    """[(byte, opcode, length)] of the top-level MCAP records of ``data`` up to Data End."""
    pos, out = len(MAGIC), []
    while pos + 9 <= len(data):
        op, length = struct.unpack_from('<BQ', data, pos)
        out.append((pos, op, length))
        if op == 0x0F:
            break
        pos += 9 + length
    return out


@pytest.fixture(scope='module')
def hair_bag(tmp_path_factory):
    """The first second of the bundled walk run with the default scene (clouds, diagnostics and
    the head poses; several 1 MB chunks): a real output bag."""
    out = tmp_path_factory.mktemp('salvage') / 'hair.mcap'
    assert main(['run', '-o', str(out), '--duration', '1', '--no-markers', '-q']) == 0
    return out


def _cut(src: Path, dst: Path, size: int) -> Path:
    dst.write_bytes(src.read_bytes()[:size])
    return dst


def _cuts(data):
    """Byte counts to cut at: 150 kB, the end of the first chunk's record, 50 bytes into the
    records after it, mid-way through the third chunk, in the summary."""
    recs = _records(data)
    chunks = [(p, n) for p, op, n in recs if op == 0x06]
    assert len(chunks) >= 3
    first_end = chunks[0][0] + 9 + chunks[0][1]
    return [150_000, first_end, first_end + 50, chunks[2][0] + 9 + chunks[2][1] // 2,
            len(data) - 100]


def test_a_cut_output_bag_is_read_to_its_last_whole_message(hair_bag, tmp_path, capsys):
    data = hair_bag.read_bytes()
    whole = _plain_messages(hair_bag)
    assert not is_cut(hair_bag)
    previous = 0
    for size in _cuts(data):
        cut = _cut(hair_bag, tmp_path / f'cut_{size}.mcap', size)
        assert is_cut(cut)
        got = {}
        with bag_io.open_bag(cut) as reader:
            for c, t, raw in bag_io.messages(reader):
                got.setdefault(c.topic, []).append((t, bytes(raw)))
        err = capsys.readouterr().err
        n = sum(len(v) for v in got.values())
        assert err.count('\n') == 1 and f'{cut}: cut short at byte {size}' in err
        assert f'read to its last whole message: {n} messages' in err
        # every topic's messages are the first ones of the whole bag, and more of them the
        # later the cut
        for topic, msgs in got.items():
            assert msgs == whole[topic][:len(msgs)], (size, topic)
        assert n >= previous and n > 0
        previous = n
    assert previous == sum(len(v) for v in whole.values())     # cut in the summary: all of it
    with bag_io.open_bag(cut) as reader:                          # read again: no new warning
        assert reader.message_count == previous
    assert capsys.readouterr().err == ''


def test_every_reader_accepts_a_cut_bag_and_recover_writes_a_clean_copy(hair_bag, tmp_path,
                                                                        capsys):
    data = hair_bag.read_bytes()
    size = _cuts(data)[3]
    cut = _cut(hair_bag, tmp_path / 'cut.mcap', size)
    whole = _plain_messages(hair_bag)
    assert main(['info', str(cut)]) == 0
    out, err = capsys.readouterr()
    assert 'cut short' in err and 'hair_sim_bag recover writes a clean copy' in err
    with bag_io.open_bag(cut) as reader:     # (said once a process: play opens a bag twice)
        kept = {i.topic: i.count for i in bag_io.topics(reader)}
    n_pose = kept['/head_pose']
    assert 0 < n_pose < len(whole['/head_pose'])
    assert f'messages: {sum(kept.values())}' in out

    fixed = tmp_path / 'fixed.mcap'
    assert main(['recover', str(cut), str(fixed)]) == 0
    out, err = capsys.readouterr()
    assert f'wrote {fixed}: {sum(kept.values())} messages' in out
    assert not is_cut(fixed)
    copy = _plain_messages(fixed)                   # a whole bag: read by plain rosbags
    for topic, msgs in copy.items():
        assert msgs == whole[topic][:kept[topic]]
    assert main(['recover', str(cut), '-o', str(fixed)]) == 5          # exists
    assert main(['recover', str(cut)]) == 2                            # no output
    capsys.readouterr()

    poses = tmp_path / 'poses.mcap'
    assert main(['import', str(cut), '-o', str(poses)]) == 0
    assert f'{n_pose} poses' in capsys.readouterr().out
    hp = bag_io.read_head_poses(poses)
    ref = bag_io.read_head_poses(fixed)
    np.testing.assert_array_equal(hp.position, ref.position)

    hair = tmp_path / 'hair.mcap'
    assert main(['run', str(cut), '-o', str(hair), '-q'] + sum(
        (['--set', s] for s in SMALL), [])) == 0
    out = capsys.readouterr().out
    assert f'/head_pose [PoseStamped], {n_pose} poses' in out

    sent = []
    play = Playback(cut, rate=1000.0, log=lambda text: None)
    play.replay(lambda topic, t, raw: sent.append((topic, t, raw)), ['/head_pose'])
    assert [(t, raw) for _, t, raw in sent] == whole['/head_pose'][:n_pose]


def test_cut_compressed_chunks_keep_their_whole_messages(tmp_path, capsys):
    """zstd (what --compress writes) and lz4 chunks the file ends inside: their messages are
    decoded as far as the compressed data go."""
    import lz4.frame
    n = 30_000                                       # about 2.4 MB of poses: 3 chunks
    t = 10 ** 9 + np.arange(n) * 10 ** 7
    p = np.stack([np.arange(n) * 1e-3, np.zeros(n), np.ones(n)], axis=1)
    q = np.tile([0, 0, 0, 1.0], (n, 1))
    zst = bag_io.write_head_pose_bag(tmp_path / 'z.mcap', t, p, q, compress=True)
    plain = bag_io.write_head_pose_bag(tmp_path / 'p.mcap', t, p, q)
    # the same bag with lz4 chunks: each chunk record rewritten (spec layout, see mcap_salvage)
    data = plain.read_bytes()
    out = bytearray(data[:len(MAGIC)])
    recs = _records(data)
    for pos, op, length in recs:
        content = data[pos + 9:pos + 9 + length]
        if op == 0x06:
            (clen,) = struct.unpack_from('<I', content, 28)
            body = content[28 + 4 + clen + 8:]
            packed = lz4.frame.compress(body)
            content = content[:28] + struct.pack('<I', 3) + b'lz4' + \
                struct.pack('<Q', len(packed)) + packed
        out += struct.pack('<BQ', op, len(content)) + content
        if op == 0x0F:
            break
    lz4_bag = tmp_path / 'l.mcap'
    lz4_bag.write_bytes(bytes(out))                  # no summary, no end magic
    for bag in (zst, lz4_bag):
        raw = bag.read_bytes()
        chunks = [(pos, length) for pos, op, length in _records(raw) if op == 0x06]
        assert len(chunks) >= 2
        size = chunks[1][0] + 9 + int(chunks[1][1] * 0.6)           # 60 % of the second
        cut = _cut(bag, tmp_path / ('cut_' + bag.name), size)
        hp = bag_io.read_head_poses(cut)
        assert 'cut short' in capsys.readouterr().err
        first = len(bag_io.read_head_poses(_cut(bag, tmp_path / 'one.mcap',
                                                chunks[1][0])))
        (tmp_path / 'one.mcap').unlink()
        assert first < len(hp) < n                   # the second chunk gave some of its poses
        np.testing.assert_array_equal(hp.t_ns, t[:len(hp)])
        np.testing.assert_array_equal(hp.position, p[:len(hp)])


def _one_line_error(capsys, code, argv, *words):
    assert main(argv) == code
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'Traceback' not in err, err
    for w in words:
        assert w in err, (w, err)


def test_damaged_files_get_one_line_naming_the_file_the_byte_and_what_was_expected(
        tmp_path, capsys):
    good = bag_io.write_head_pose_bag(tmp_path / 'g.mcap', [10 ** 9, 2 * 10 ** 9],
                                      np.zeros((2, 3)), [[0, 0, 0, 1.0]] * 2)
    data = good.read_bytes()
    wrong = tmp_path / 'wrong.mcap'
    wrong.write_bytes(b'\x89MCAQ0\r\n' + data[8:])
    _one_line_error(capsys, 3, ['info', str(wrong)], str(wrong), 'not a bag', 'at byte 0',
                    "b'\\x89MCAP0\\r\\n' (MCAP)")
    header = tmp_path / 'header.mcap'
    header.write_bytes(data[:20])
    _one_line_error(capsys, 3, ['info', str(header)], str(header), 'at byte 8',
                    'expected a Header record')
    first = _records(data)[1][0]
    early = _cut(good, tmp_path / 'early.mcap', first + 30)
    _one_line_error(capsys, 3, ['run', str(early), '-o', str(tmp_path / 'o.mcap')],
                    str(early), 'before any whole message', f'at byte {first}')
    # a chunk whose compression the data do not match
    bad = bytearray(data[:first + 9 + 60])
    (clen,) = struct.unpack_from('<I', bad, first + 9 + 28)
    assert clen == 0
    body = bytes(bad[first + 9 + 28 + 4:])
    bad[first + 9 + 28:] = struct.pack('<I', 4) + b'zstd' + body
    garbled = tmp_path / 'garbled.mcap'
    garbled.write_bytes(bytes(bad))
    _one_line_error(capsys, 3, ['import', str(garbled), '-o', str(tmp_path / 'x.mcap')],
                    str(garbled), f'at byte {first + 9 + 28 + 8 + 8}', 'expected zstd data')
    # a whole file whose Footer puts the summary beyond itself
    beyond = bytearray(data)
    footer = len(data) - 37
    struct.pack_into('<Q', beyond, footer + 9, 2 * len(data))
    far = tmp_path / 'far.mcap'
    far.write_bytes(bytes(beyond))
    _one_line_error(capsys, 3, ['info', str(far)], str(far), f'at byte {footer + 9}',
                    f'summary at byte {2 * len(data)}, expected one between')
    # zeros where the next record should start end the data like a cut
    zeros = tmp_path / 'zeros.mcap'
    zeros.write_bytes(data[:_records(data)[2][0]] + bytes(4096))
    assert len(bag_io.read_head_poses(zeros)) == 2
    assert 'zeros from byte' in capsys.readouterr().err
    # a sqlite3 bag cut short cannot be read in part: the header says how long it should be
    n = 3000
    db = bag_io.write_head_pose_bag(tmp_path / 'p.db3', 10 ** 9 + np.arange(n) * 10 ** 7,
                                    np.zeros((n, 3)), np.tile([0, 0, 0, 1.0], (n, 1)))
    short = _cut(db, tmp_path / 'short.db3', db.stat().st_size // 2)
    _one_line_error(capsys, 3, ['info', str(short)], str(short), 'corrupt', 'byte 28',
                    f'the file ends at byte {short.stat().st_size}')
