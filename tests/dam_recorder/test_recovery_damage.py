"""Recovery of damaged bags (issue 20 B): ``recover`` trusts the data files over
``metadata.yaml``, names what it could not save and why, and afterwards every reader (``rosbags``,
``bag info``, ``bag export``) sees every message the files hold."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import grasp_bags as gb
import pytest
import yaml
from bag_readers import read_with_mcap, read_with_rosbags
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from rosbag2_format import metadata_problems
from test_bag_writer import T0, add_topics, joint_state

from dam_recorder.bag_cli import main as bag_main
from dam_recorder.bag_export import csv_name
from dam_recorder.bag_writer import BagWriter
from dam_recorder.recover_cli import main as recover_main
from dam_recorder.recovery import recover_bag

FEEDBACK_TYPE = 'dam_interfaces/action/DamGrasp_FeedbackMessage'


def grasp_bag(tmp_path: Path, typestore, prefixes, storage: str = 'mcap') -> tuple[Path, dict]:
    """A closed grasp bag and its message count per topic."""
    bag = gb.write_grasp_bag(tmp_path / 'bag', typestore, prefixes, storage=storage)
    return bag.path, {topic: len(times) for topic, times in bag.times.items()}


def edit_metadata(bag: Path, edit) -> None:
    path = bag / 'metadata.yaml'
    path.write_text(edit(path.read_text()))


def cut_inside_type_name(text: str) -> str:
    """The file cut in the middle of the feedback topic's type name."""
    return text[:text.index(FEEDBACK_TYPE) + 20]


def wrong_counts(text: str) -> str:
    data = yaml.safe_load(text)
    info = data['rosbag2_bagfile_information']
    info['message_count'] = 7
    for entry in info['topics_with_message_count']:
        entry['message_count'] = 1
    for entry in info['files']:
        entry['message_count'] = 2
    return yaml.safe_dump(data, sort_keys=False)


def missing_topics(text: str) -> str:
    data = yaml.safe_load(text)
    info = data['rosbag2_bagfile_information']
    info['topics_with_message_count'] = [
        e for e in info['topics_with_message_count']
        if e['topic_metadata']['name'] in ('/dam/status',)]
    return yaml.safe_dump(data, sort_keys=False)


def wrong_type(text: str) -> str:
    return text.replace('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/Pose')


def garbage(_text: str) -> str:
    return 'rosbag2_bagfile_information: [\x00 {{ not: yaml'


DAMAGE = {'cut inside a type name': cut_inside_type_name, 'wrong counts': wrong_counts,
          'missing topics': missing_topics, 'wrong type': wrong_type, 'garbage': garbage}


def every_reader_sees(bag: Path, counts: dict[str, int], tmp_path: Path, capsys) -> None:
    """rosbags, ``bag info`` and ``bag export`` see ``counts`` messages per topic."""
    assert metadata_problems(bag) == []
    read = read_with_rosbags(bag)
    assert {t: len(r) for t, r in read.items()} == counts
    assert bag_main(['info', '--json', str(bag)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert {t['name']: t['count'] for t in info['topics']} == counts
    out = tmp_path / 'csv'
    assert bag_main(['export', str(bag), '-o', str(out)]) == 0
    capsys.readouterr()
    for topic, count in counts.items():
        if count:
            with open(out / csv_name(topic), newline='') as stream:
                assert len(list(csv.reader(stream))) == count + 1, topic


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
@pytest.mark.parametrize('damage', sorted(DAMAGE))
def test_damaged_metadata_is_rebuilt_from_the_data_files(tmp_path: Path, typestore, prefixes,
                                                        capsys, damage, storage) -> None:
    bag, counts = grasp_bag(tmp_path, typestore, prefixes, storage)
    before = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    edit_metadata(bag, DAMAGE[damage])
    report = recover_bag(bag)
    assert report.metadata_problems, damage  # what was wrong is said
    assert all(not f.problems for f in report.files)  # the data files were whole
    after = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    topics = {e['topic_metadata']['name']: e for e in after['topics_with_message_count']}
    for entry in before['topics_with_message_count']:
        meta = entry['topic_metadata']
        assert topics[meta['name']]['topic_metadata']['type'] == meta['type']
        assert topics[meta['name']]['topic_metadata']['type_description_hash'] == \
            meta['type_description_hash']
    every_reader_sees(bag, counts, tmp_path, capsys)


def test_the_report_names_the_broken_type_and_the_command_does_not_say_intact_only(
        tmp_path: Path, typestore, prefixes, capsys) -> None:
    bag, counts = grasp_bag(tmp_path, typestore, prefixes)
    edit_metadata(bag, cut_inside_type_name)
    assert recover_main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"topic /dam_grasp/_action/feedback had type '{FEEDBACK_TYPE[:20]}'" in out
    assert f"the data files say '{FEEDBACK_TYPE}'" in out
    assert f'/dam_grasp/_action/feedback: {counts["/dam_grasp/_action/feedback"]} (' in out


# -- damaged data files -------------------------------------------------------------------------

def chunked_bag(tmp_path: Path, prefixes, typestore, chunks: int = 4, per_chunk: int = 40
                ) -> Path:
    """A closed bag of ``chunks`` zstd chunks of ``per_chunk`` joint states each."""
    writer = BagWriter(tmp_path / 'bag')
    ids = add_topics(writer, prefixes)
    i = 0
    for _ in range(chunks):
        for _ in range(per_chunk):
            writer.write(ids[0], T0 + i, joint_state(typestore, i))
            i += 1
        writer.flush()
    writer.close()
    return tmp_path / 'bag'


def chunk_spans(path: Path) -> list[tuple[int, int]]:
    """(start, end) of each chunk record in the file."""
    spans = []
    with open(path, 'rb') as stream:
        records = StreamReader(stream, emit_chunks=True).records
        start = stream.tell()
        for record in records:
            if isinstance(record, Chunk):
                spans.append((start, stream.tell()))
            start = stream.tell()
    return spans


def stamps(topics: dict) -> list[int]:
    return [r.values['header']['stamp']['sec'] for r in topics.get('/joint_states', [])]


def test_flipped_bytes_inside_a_compressed_chunk(tmp_path: Path, prefixes, typestore,
                                                 capsys) -> None:
    bag = chunked_bag(tmp_path, prefixes, typestore)
    file = bag / 'bag_0.mcap'
    data = bytearray(file.read_bytes())
    start, end = chunk_spans(file)[1]
    middle = (start + end) // 2
    data[middle] ^= 0xFF
    data[middle + 7] ^= 0x5A
    file.write_bytes(bytes(data))
    with pytest.raises(Exception):  # noqa: B017 - the bag is unreadable before
        read_with_rosbags(bag)
    assert recover_main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert '(intact)' not in out
    assert 'bag_0.mcap: 120 messages (rebuilt, with losses)' in out
    assert f'chunk at byte {start} cannot be read (' in out
    assert '40 messages lost (40 of /joint_states)' in out
    report = recover_bag(bag)  # a second run finds it whole
    assert [(f.rebuilt, f.problems) for f in report.files] == [(False, [])]
    expected = list(range(40)) + list(range(80, 160))
    for read in (read_with_rosbags, read_with_mcap):
        assert stamps(read(bag)) == expected
    every_reader_sees(bag, {'/joint_states': 120, '/dam/status': 0}, tmp_path, capsys)


def test_a_truncated_file_keeps_its_whole_chunks_and_says_what_was_cut(
        tmp_path: Path, prefixes, typestore, capsys) -> None:
    bag = chunked_bag(tmp_path, prefixes, typestore)
    file = bag / 'bag_0.mcap'
    start, end = chunk_spans(file)[2]
    size = file.stat().st_size
    file.write_bytes(file.read_bytes()[:(start + end) // 2])
    report = recover_bag(bag)
    (problem,) = report.files[0].problems
    assert f'runs past the end of the file ({(start + end) // 2} bytes)' in problem
    assert 'cannot be read' in problem and size > (start + end) // 2
    assert report.message_count == 80
    every_reader_sees(bag, {'/joint_states': 80, '/dam/status': 0}, tmp_path, capsys)


def test_a_file_without_its_summary_is_rebuilt_without_losses(tmp_path: Path, prefixes,
                                                              typestore, capsys) -> None:
    """Cut after the last chunk (a recorder that never closed the file): every message is
    there, and the command must not say 'with losses' (it read 'nothing lost' as a loss)."""
    bag = chunked_bag(tmp_path, prefixes, typestore)
    file = bag / 'bag_0.mcap'
    end = chunk_spans(file)[-1][1]
    file.write_bytes(file.read_bytes()[:end])
    assert recover_main([str(bag)]) == 0
    out = capsys.readouterr().out
    assert 'bag_0.mcap: 160 messages (rebuilt)' in out, out
    assert 'with losses' not in out, out


def test_a_damaged_sqlite3_page_is_not_called_intact(tmp_path: Path, typestore, prefixes,
                                                     capsys) -> None:
    """Bytes changed in a page the counting queries do not read (a table of their own: the
    message definitions) made every reader fail while recover said 'intact'."""
    import sqlite3

    bag, _counts = grasp_bag(tmp_path, typestore, prefixes, storage='sqlite3')
    [file] = bag.glob('*.db3')
    with sqlite3.connect(file) as conn:
        pages = dict(conn.execute("SELECT name, rootpage FROM sqlite_master WHERE type='table'"))
        size = conn.execute('PRAGMA page_size').fetchone()[0]
    conn.close()
    unread = next(n for n in ('message_definitions', 'schema', 'metadata') if n in pages)
    start = (pages[unread] - 1) * size
    data = bytearray(file.read_bytes())
    for at in range(start, start + 24):  # the page header and its first cell pointers
        data[at] ^= 0xA5
    file.write_bytes(bytes(data))
    assert recover_main([str(bag)]) == 1
    captured = capsys.readouterr()
    assert '(intact)' not in captured.out
    assert f'recover: cannot read {file}: ' in captured.err, captured.err
