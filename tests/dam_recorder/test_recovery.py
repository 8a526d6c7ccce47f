"""Recovery of bags whose recorder died: the file as the crash left it (a snapshot of the bag
directory taken while the writer is open), cut at every kind of place."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from bag_readers import read_with_mcap, read_with_rosbags
from mcap.records import Chunk
from mcap.stream_reader import StreamReader, breakup_chunk
from rosbag2_format import metadata_problems
from test_bag_writer import T0, add_topics, joint_state

from dam_recorder.bag_writer import BagWriter
from dam_recorder.errors import RecoveryError
from dam_recorder.recover_cli import main as recover_main
from dam_recorder.recovery import RECOVERED_KEY, mcap_is_complete, recover_bag


def crashed_bag(tmp_path: Path, prefixes, typestore, flushes: int = 3, per_flush: int = 50,
                unflushed: int = 20, name: str = 'bag') -> Path:
    """A bag directory as a SIGKILL leaves it: ``flushes`` chunks written out, ``unflushed``
    messages still in memory."""
    writer = BagWriter(tmp_path / 'live', custom_data=lambda: {'dam_recorder.lost_messages':
                                                               '{"/joint_states": 2}'})
    ids = add_topics(writer, prefixes)
    i = 0
    for _ in range(flushes):
        for _ in range(per_flush):
            writer.write(ids[0], T0 + i, joint_state(typestore, i))
            i += 1
        writer.flush()
    for _ in range(unflushed):
        writer.write(ids[0], T0 + i, joint_state(typestore, i))
        i += 1
    snapshot = tmp_path / name
    shutil.copytree(tmp_path / 'live', snapshot)
    writer.close()
    for path in snapshot.iterdir():  # the snapshot keeps the live bag's names
        if path.name.startswith('live_'):
            path.rename(snapshot / path.name.replace('live_', f'{name}_'))
    meta = (snapshot / 'metadata.yaml').read_text().replace('live_', f'{name}_')
    (snapshot / 'metadata.yaml').write_text(meta)
    return snapshot


def stamps(topics: dict, topic: str = '/joint_states') -> list[int]:
    return [r.values['header']['stamp']['sec'] for r in topics.get(topic, [])]


def chunk_ends(path: Path) -> list[tuple[int, int]]:
    """(file offset where each chunk record ends, messages up to it), by the mcap reader."""
    out = []
    count = 0
    with open(path, 'rb') as stream:
        reader = StreamReader(stream, emit_chunks=True).records
        try:
            for record in reader:
                if isinstance(record, Chunk):
                    count += sum(type(r).__name__ == 'Message' for r in breakup_chunk(record))
                    out.append((stream.tell(), count))
        except Exception:  # noqa: BLE001 - the crashed file has no footer
            pass
    return out


def test_crashed_bag_is_not_readable_and_recover_makes_it_whole(tmp_path: Path, prefixes,
                                                                typestore) -> None:
    bag = crashed_bag(tmp_path, prefixes, typestore)
    assert not mcap_is_complete(bag / 'bag_0.mcap')
    with pytest.raises(Exception):  # noqa: B017 - an index reader refuses the file
        read_with_mcap(bag)
    report = recover_bag(bag)
    assert [(f.path, f.rebuilt, f.message_count) for f in report.files] == \
        [('bag_0.mcap', True, 150)]
    assert mcap_is_complete(bag / 'bag_0.mcap')
    assert metadata_problems(bag) == []
    for read in (read_with_rosbags, read_with_mcap):
        assert stamps(read(bag)) == list(range(150))  # the 20 unflushed ones are lost
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == 150
    assert info['duration']['nanoseconds'] == 149
    assert info['custom_data'] == {'dam_recorder.lost_messages': '{"/joint_states": 2}',
                                   RECOVERED_KEY: 'bag_0.mcap'}
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    assert topics['/joint_states']['message_count'] == 150
    assert topics['/joint_states']['topic_metadata']['type_description_hash'] == \
        typestore.hash_rihs01('sensor_msgs/msg/JointState')
    assert topics['/dam/status']['message_count'] == 0  # subscribed, nothing arrived
    assert topics['/dam/status']['topic_metadata']['offered_qos_profiles'][0][
        'durability'] == 'transient_local'


def test_every_complete_chunk_survives_a_cut_anywhere(tmp_path: Path, prefixes,
                                                      typestore) -> None:
    bag = crashed_bag(tmp_path, prefixes, typestore, flushes=4, per_flush=30, unflushed=0)
    file = bag / 'bag_0.mcap'
    original = file.read_bytes()
    ends = chunk_ends(file)
    assert [count for _, count in ends] == [30, 60, 90, 120]
    first_chunk_start = 8 + 1 + 8 + len(b'ros2') + 4 + 4 + 20  # magic, header record (approx)
    cuts = sorted({first_chunk_start, *range(ends[0][0] - 3, len(original), 97),
                   *(end for end, _ in ends), *(end - 1 for end, _ in ends), len(original)})
    for cut in cuts:
        file.write_bytes(original[:cut])
        expected = max([count for end, count in ends if end <= cut], default=0)
        report = recover_bag(bag)
        assert report.message_count == expected, cut
        assert stamps(read_with_rosbags(bag)) == list(range(expected)), cut
        assert metadata_problems(bag) == [], cut


def test_intact_files_are_left_as_they_are(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag')
    ids = add_topics(writer, prefixes)
    for i in range(30):
        writer.write(ids[0], T0 + i, joint_state(typestore, i))
        if i == 9:
            writer.split()
    writer.close()
    before = {p.name: p.read_bytes() for p in (tmp_path / 'bag').glob('*.mcap')}
    meta_before = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())
    report = recover_bag(tmp_path / 'bag')
    assert [(f.path, f.rebuilt) for f in report.files] == [('bag_0.mcap', False),
                                                           ('bag_1.mcap', False)]
    assert {p.name: p.read_bytes() for p in (tmp_path / 'bag').glob('*.mcap')} == before
    assert yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text()) == meta_before


def test_split_bag_with_a_damaged_last_file(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'live')
    ids = add_topics(writer, prefixes)
    for i in range(60):
        writer.write(ids[0], T0 + i, joint_state(typestore, i))
        if i == 29:
            writer.split()
    writer.flush()
    shutil.copytree(tmp_path / 'live', tmp_path / 'crash')
    writer.close()
    bag = tmp_path / 'crash'
    (bag / 'metadata.yaml').unlink()  # even without the old metadata
    report = recover_bag(bag)
    assert [(f.path, f.rebuilt, f.message_count) for f in report.files] == \
        [('live_0.mcap', False, 30), ('live_1.mcap', True, 30)]
    assert metadata_problems(bag) == []
    for read in (read_with_rosbags, read_with_mcap):
        assert stamps(read(bag)) == list(range(60))


def test_file_killed_before_its_first_flush(tmp_path: Path, prefixes, typestore) -> None:
    bag = crashed_bag(tmp_path, prefixes, typestore, flushes=0, unflushed=5)
    (bag / 'bag_0.mcap').write_bytes(b'')  # nothing reached the file
    report = recover_bag(bag)
    assert report.message_count == 0
    assert metadata_problems(bag) == []
    assert read_with_mcap(bag) == {}
    assert {t.name for t in report.topics} == {'/joint_states', '/dam/status'}


def test_sqlite3_bag_keeps_what_was_committed(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'live', storage='sqlite3', compression='none')
    ids = add_topics(writer, prefixes)
    for i in range(40):
        writer.write(ids[0], T0 + i, joint_state(typestore, i))
        if i == 24:
            writer.flush()
    shutil.copytree(tmp_path / 'live', tmp_path / 'crash')
    writer.close()
    report = recover_bag(tmp_path / 'crash')
    assert report.message_count == 25
    assert metadata_problems(tmp_path / 'crash') == []
    assert stamps(read_with_rosbags(tmp_path / 'crash')) == list(range(25))


def test_no_bag_is_an_error_naming_the_directory(tmp_path: Path, capsys) -> None:
    with pytest.raises(RecoveryError, match='nothing_here'):
        recover_bag(tmp_path / 'nothing_here')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(RecoveryError, match='no .mcap or .db3'):
        recover_bag(tmp_path / 'empty')
    assert recover_main([str(tmp_path / 'empty')]) == 1
    assert 'no .mcap or .db3' in capsys.readouterr().err


def test_recover_command_reports_what_it_did(tmp_path: Path, prefixes, typestore,
                                             capsys) -> None:
    bag = crashed_bag(tmp_path, prefixes, typestore, flushes=2, per_flush=10)
    assert recover_main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert 'bag_0.mcap: 20 messages (rebuilt' in out
    assert '/joint_states: 20 (sensor_msgs/msg/JointState)' in out
