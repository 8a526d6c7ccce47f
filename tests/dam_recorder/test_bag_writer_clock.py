"""BagWriter and a clock that jumps back (a simulation started again while recording)."""

from __future__ import annotations

from pathlib import Path

import yaml
from bag_readers import read_with_rosbags
from rosbag2_format import metadata_problems

from dam_recorder.bag_writer import CLOCK_JUMP_BACK_NS, BagWriter
from dam_recorder.type_description import load_message_type

T0 = 1_000_000_000_000  # [ns]: simulated time, 1000 s


def _int64(store, i: int) -> bytes:
    message = store.types['std_msgs/msg/Int64'](data=i)
    return bytes(store.serialize_cdr(message, 'std_msgs/msg/Int64'))


def test_a_clock_that_jumps_back_starts_a_new_file_under_a_duration_limit(
        tmp_path: Path, prefixes, typestore) -> None:
    """-d 1: 0.5 s of messages, then the clock goes back 500 s (the stand-in started again)
    and runs 2.5 s: the jump starts a new file at once (it does not stay open for 500 s), and
    every file spans less than the limit of one clock run."""
    limit = 1_000_000_000
    writer = BagWriter(tmp_path / 'bag', max_file_duration_ns=limit)
    msg = load_message_type('std_msgs/msg/Int64', prefixes)
    topic = writer.add_topic('/counter', msg.name, msg.definition(), msg.type_hash, [])
    stamps = [T0 + i * 10_000_000 for i in range(50)]  # 0.5 s
    back = T0 - 500 * 10**9
    stamps += [back + i * 10_000_000 for i in range(250)]  # 2.5 s after the jump
    for i, stamp in enumerate(stamps):
        writer.write(topic, stamp, _int64(typestore, i))
    writer.close()
    assert writer.clock_jumps_back == 1
    assert metadata_problems(tmp_path / 'bag') == []
    files = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['files']
    assert [f['message_count'] for f in files] == [50, 100, 100, 50]
    assert files[1]['starting_time']['nanoseconds_since_epoch'] == back
    assert all(f['duration']['nanoseconds'] < limit for f in files)
    values = [r.values['data'] for r in read_with_rosbags(tmp_path / 'bag')['/counter']]
    assert sorted(values) == list(range(300))


def test_small_disorder_of_receive_stamps_is_no_jump(tmp_path: Path, prefixes,
                                                     typestore) -> None:
    writer = BagWriter(tmp_path / 'bag', max_file_duration_ns=10**9)
    msg = load_message_type('std_msgs/msg/Int64', prefixes)
    topic = writer.add_topic('/counter', msg.name, msg.definition(), msg.type_hash, [])
    for i, stamp in enumerate([T0, T0 + 500_000_000, T0 + 500_000_000 - CLOCK_JUMP_BACK_NS // 2]):
        writer.write(topic, stamp, _int64(typestore, i))
    writer.close()
    assert writer.clock_jumps_back == 0 and len(writer.files) == 1
