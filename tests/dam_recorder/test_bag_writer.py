"""Bags written by BagWriter: read back by two readers, metadata.yaml as Jazzy requires it,
files split by time and on request (by size: test_size_limit.py), sqlite3, and what a flush
makes durable."""

from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest
import yaml
from bag_readers import read_with_mcap, read_with_rosbags
from mcap.stream_reader import StreamReader
from rosbag2_format import metadata_problems

from dam_recorder.bag_writer import BagWriter
from dam_recorder.errors import BagError, ConfigurationError
from dam_recorder.qos import INFINITE_NS, OfferedQos, to_rosbags_qos
from dam_recorder.type_description import load_message_type

T0 = 1_700_000_000_000_000_000  # [ns]
LATCHED = OfferedQos('KEEP_LAST', 1, 'RELIABLE', 'TRANSIENT_LOCAL', INFINITE_NS, INFINITE_NS,
                     'AUTOMATIC', INFINITE_NS)


def joint_state(store, i: int) -> bytes:
    t = store.types
    message = t['sensor_msgs/msg/JointState'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=i, nanosec=1),
                                        frame_id=f'frame_{i}'),
        name=['a', 'b'], position=np.array([0.5 * i, -1.0]), velocity=np.array([]),
        effort=np.array([float(i)]))
    return bytes(store.serialize_cdr(message, 'sensor_msgs/msg/JointState'))


def dam_status(store, i: int) -> bytes:
    t = store.types
    message = t['dam_interfaces/msg/DamStatus'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=i, nanosec=0),
                                        frame_id=''),
        phase=f'PHASE_{i}', progress=i / 10, finger_names=['f1', 'f2'][: i % 3],
        compliant_torque=np.array([1.0, 2.0]), delta_theta_s=np.array([]), outcome=i % 6,
        outcome_name='SUCCESS' if i % 6 == 1 else '', message='m',
        compliant_torque_estimate=np.array([1.0, 2.0]),
        compliant_effort_measured=np.array([0.5, 0.0]))
    return bytes(store.serialize_cdr(message, 'dam_interfaces/msg/DamStatus'))


def add_topics(writer: BagWriter, prefixes) -> tuple[int, int]:
    js = load_message_type('sensor_msgs/msg/JointState', prefixes)
    st = load_message_type('dam_interfaces/msg/DamStatus', prefixes)
    return (writer.add_topic('/joint_states', js.name, js.definition(), js.type_hash, []),
            writer.add_topic('/dam/status', st.name, st.definition(), st.type_hash,
                             [to_rosbags_qos(LATCHED)]))


def write_messages(writer: BagWriter, ids: tuple[int, int], store, count: int,
                   step_ns: int = 1_000_000) -> None:
    for i in range(count):
        writer.write(ids[0], T0 + i * step_ns, joint_state(store, i))
        if i % 2 == 0:
            writer.write(ids[1], T0 + i * step_ns + 1, dam_status(store, i))


def test_mcap_bag_reads_back_with_both_readers(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag')
    ids = add_topics(writer, prefixes)
    write_messages(writer, ids, typestore, 300)
    writer.close()
    assert metadata_problems(tmp_path / 'bag') == []
    for read in (read_with_rosbags, read_with_mcap):
        topics = read(tmp_path / 'bag')
        joint_states = topics['/joint_states']
        assert [r.timestamp for r in joint_states] == [T0 + i * 1_000_000 for i in range(300)]
        assert [r.values['header']['frame_id'] for r in joint_states] == \
            [f'frame_{i}' for i in range(300)]
        assert joint_states[7].values['position'] == [3.5, -1.0]
        assert joint_states[7].values['effort'] == [7.0]
        status = topics['/dam/status']
        assert [r.values['phase'] for r in status] == [f'PHASE_{i}' for i in range(0, 300, 2)]
        assert status[2].values['finger_names'] == ['f1']  # i = 4


def test_metadata_is_version_9_with_offered_qos_and_hashes(tmp_path: Path, prefixes,
                                                            typestore) -> None:
    writer = BagWriter(tmp_path / 'bag', custom_data=lambda: {'dam_recorder.x': '{"a": 1}'})
    ids = add_topics(writer, prefixes)
    write_messages(writer, ids, typestore, 10)
    writer.close()
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == 15
    assert info['starting_time']['nanoseconds_since_epoch'] == T0
    assert info['duration']['nanoseconds'] == 9 * 1_000_000
    assert info['relative_file_paths'] == ['bag_0.mcap']
    assert info['custom_data'] == {'dam_recorder.x': '{"a": 1}'}
    assert info['ros_distro'] == 'jazzy'
    topics = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    status = topics['/dam/status']['topic_metadata']
    assert status['type'] == 'dam_interfaces/msg/DamStatus'
    assert status['serialization_format'] == 'cdr'
    assert status['type_description_hash'] == \
        typestore.hash_rihs01('dam_interfaces/msg/DamStatus')
    assert status['offered_qos_profiles'][0]['durability'] == 'transient_local'
    assert topics['/joint_states']['topic_metadata']['offered_qos_profiles'] == []
    assert (topics['/joint_states']['message_count'], topics['/dam/status']['message_count']) \
        == (10, 5)


def test_a_split_size_below_the_minimum_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match='below the smallest split size'):
        BagWriter(tmp_path / 'a', max_file_bytes=10)
    assert not (tmp_path / 'a').exists()


def test_split_by_duration_and_on_request(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag', max_file_duration_ns=100_000_000)
    ids = add_topics(writer, prefixes)
    write_messages(writer, ids, typestore, 250)  # 1 ms apart: 0.25 s, three files
    assert writer.split().name == 'bag_3.mcap'
    writer.write(ids[0], T0 + 10**9, joint_state(typestore, 999))
    writer.close()
    assert metadata_problems(tmp_path / 'bag') == []
    info = yaml.safe_load((tmp_path / 'bag' / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    assert [f['message_count'] for f in info['files']] == [150, 150, 75, 1]
    assert [f['starting_time']['nanoseconds_since_epoch'] - T0 for f in info['files']] == \
        [0, 100_000_000, 200_000_000, 10**9]
    assert all(f['duration']['nanoseconds'] < 100_000_000 for f in info['files'])
    read = read_with_mcap(tmp_path / 'bag')['/joint_states']
    assert [r.values['header']['stamp']['sec'] for r in read] == [*range(250), 999]


def test_sqlite3_bag_reads_back(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag', storage='sqlite3', compression='none')
    ids = add_topics(writer, prefixes)
    write_messages(writer, ids, typestore, 50)
    writer.close()
    assert metadata_problems(tmp_path / 'bag') == []
    assert (tmp_path / 'bag' / 'bag_0.db3').is_file()
    topics = read_with_rosbags(tmp_path / 'bag')
    assert [r.values['effort'] for r in topics['/joint_states']] == \
        [[float(i)] for i in range(50)]


def test_flush_puts_every_message_into_the_file_before_close(tmp_path: Path, prefixes,
                                                             typestore) -> None:
    writer = BagWriter(tmp_path / 'bag')
    ids = add_topics(writer, prefixes)
    write_messages(writer, ids, typestore, 40)
    writer.flush()
    with open(tmp_path / 'bag' / 'bag_0.mcap', 'rb') as stream:  # the file as a crash leaves it
        data = stream.read()
    assert not data.endswith(b'\x89MCAP0\r\n')  # no footer yet
    records = []
    reader = StreamReader(__import__('io').BytesIO(data)).records
    try:
        for record in reader:
            records.append(record)
    except Exception:  # noqa: BLE001 - the stream ends without a footer
        pass
    messages = [r for r in records if type(r).__name__ == 'Message']
    assert len(messages) == 60
    writer.close()


def test_random_chunk_boundaries_lose_nothing(tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag')
    ids = add_topics(writer, prefixes)
    rng = random.Random(3)
    for i in range(400):
        writer.write(ids[0], T0 + i, joint_state(typestore, i))
        if rng.random() < 0.05:
            writer.flush()
    writer.close()
    stamps = [r.values['header']['stamp']['sec']
              for r in read_with_mcap(tmp_path / 'bag')['/joint_states']]
    assert stamps == list(range(400))


def test_bad_options_and_existing_output_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigurationError, match="'lz4'"):
        BagWriter(tmp_path / 'a', compression='lz4')
    with pytest.raises(ConfigurationError, match="'rosbag'"):
        BagWriter(tmp_path / 'a', storage='rosbag')
    with pytest.raises(ConfigurationError, match="'zstd'"):
        BagWriter(tmp_path / 'a', storage='sqlite3', compression='zstd')
    with pytest.raises(ConfigurationError, match='-1'):
        BagWriter(tmp_path / 'a', max_file_bytes=-1)
    assert not (tmp_path / 'a').exists()
    (tmp_path / 'taken').mkdir()
    with pytest.raises(BagError, match='taken'):
        BagWriter(tmp_path / 'taken')
    writer = BagWriter(tmp_path / 'b')
    writer.add_topic('/x', 'std_msgs/msg/String', 'string data\n', '', [])
    with pytest.raises(BagError, match="'/x'"):
        writer.add_topic('/x', 'std_msgs/msg/String', 'string data\n', '', [])
    writer.close()
    writer.close()  # a second close does nothing
    with pytest.raises(BagError, match='closed'):
        writer.write(1, T0, b'\x00\x01\x00\x00\x01\x00\x00\x00\x00')
