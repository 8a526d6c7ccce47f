"""The bag tools' reading module: what a path holds, ``metadata.yaml`` checks, types from the
bag's definitions (Jazzy's standard types where a bag has none), damaged storage files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import grasp_bags as gb
import numpy as np
import pytest

from dam_recorder.bag_reading import BagReader, locate, read_bag_metadata
from dam_recorder.bag_writer import BagWriter
from dam_recorder.errors import BagReadError


def test_locate_tells_a_bag_from_a_directory_of_bags(tmp_path: Path, typestore,
                                                     prefixes) -> None:
    one = gb.write_grasp_bag(tmp_path / 'eps' / 'b', typestore, prefixes,
                             topics=('/dam/status',)).path
    gb.write_grasp_bag(tmp_path / 'eps' / 'a', typestore, prefixes, topics=('/dam/status',))
    (tmp_path / 'eps' / 'c_not_a_bag').mkdir()
    assert locate(one) == ('bag', [one])
    assert locate(tmp_path / 'eps') == ('episodes', [tmp_path / 'eps' / 'a', one])
    (tmp_path / 'file').write_text('x')
    with pytest.raises(BagReadError, match=r'file: not a bag \(a bag is a directory'):
        locate(tmp_path / 'file')
    with pytest.raises(BagReadError, match='nothing: no such file or directory'):
        locate(tmp_path / 'nothing')


def test_metadata_is_read_with_custom_data(tmp_path: Path, typestore, prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'bag', typestore, prefixes, topics=('/dam/status',),
                             custom={'x': 'y'})
    meta = read_bag_metadata(bag.path)
    assert meta.storage == 'mcap' and meta.files == ['bag_0.mcap']
    assert meta.topics == {'/dam/status': 'dam_interfaces/msg/DamStatus'}
    assert meta.topic_counts == {'/dam/status': len(gb.PHASES)}
    assert meta.start_ns == bag.start_ns and meta.duration_ns == bag.end_ns - bag.start_ns
    assert meta.custom_data['x'] == 'y'
    assert meta.counts('dam_recorder.lost_messages') == gb.LOST
    assert meta.counts('dam_recorder.absent') == {}
    text = (bag.path / 'metadata.yaml').read_text()
    (bag.path / 'metadata.yaml').write_text(text.replace('message_count: 20\n',
                                                         'message_count: many\n', 1))
    with pytest.raises(BagReadError, match="message_count: expected an integer, got 'many'"):
        read_bag_metadata(bag.path)


def test_a_bag_without_definitions_is_read_with_the_standard_types(tmp_path: Path,
                                                                  typestore) -> None:
    writer = BagWriter(tmp_path / 'bare')
    topic = writer.add_topic('/joint_states', 'sensor_msgs/msg/JointState', '', '', [])
    t = typestore.types
    msg = t['sensor_msgs/msg/JointState'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=3,
                                                                               nanosec=4),
                                        frame_id='f'),
        name=['j'], position=np.array([0.25]), velocity=np.array([], np.float64),
        effort=np.array([-1.5]))
    writer.write(topic, gb.T0, bytes(typestore.serialize_cdr(msg, 'sensor_msgs/msg/JointState')))
    writer.close()
    with BagReader(tmp_path / 'bare') as bag:
        [read] = list(bag.messages())
        assert bag.field_names('sensor_msgs/msg/JointState') == \
            ('header', 'name', 'position', 'velocity', 'effort')
    assert (read.topic, read.time_ns, read.message.name) == ('/joint_states', gb.T0, ['j'])
    assert read.message.position.tolist() == [0.25] and read.message.effort.tolist() == [-1.5]
    assert read.message.header.stamp.nanosec == 4


def test_a_damaged_storage_file_is_an_error_naming_the_bag(tmp_path: Path, typestore,
                                                           prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'bag', typestore, prefixes, topics=('/dam/status',))
    (bag.path / 'bag_0.mcap').write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 40)
    with pytest.raises(BagReadError, match=f'{bag.path}: cannot'):
        with BagReader(bag.path) as reader:
            list(reader.messages())
    (bag.path / 'bag_0.mcap').unlink()
    with pytest.raises(BagReadError, match='cannot open the bag: .*missing'):
        with BagReader(bag.path):
            pass
    meta = json.dumps({'/a': -1})
    with pytest.raises(BagReadError, match='expected JSON'):
        read_bag_metadata(gb.write_grasp_bag(
            tmp_path / 'neg', typestore, prefixes, topics=('/dam/status',),
            custom={'dam_recorder.lost_messages': meta}).path).counts(
                'dam_recorder.lost_messages')


def test_the_bag_tools_do_not_import_rclpy() -> None:
    code = ('import sys\n'
            'import dam_recorder.bag_cli, dam_recorder.bag_export, dam_recorder.bag_info\n'
            'import dam_recorder.bag_plot, dam_recorder.bag_reading, dam_recorder.episode\n'
            'print(sorted(m for m in sys.modules if m.split(".")[0] == "rclpy"))\n')
    src = Path(__file__).resolve().parents[2] / 'src'
    env_path = f'{src / "dam_recorder"}:{src / "dam_common"}'
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          env={**os.environ, 'PYTHONPATH': env_path + ':' +
                               os.environ.get('PYTHONPATH', '')}, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == '[]'


def test_a_file_without_its_end_points_to_recover(tmp_path: Path, prefixes, typestore) -> None:
    import shutil

    from test_bag_writer import add_topics, write_messages

    writer = BagWriter(tmp_path / 'live')
    write_messages(writer, add_topics(writer, prefixes), typestore, 50)
    writer.flush()  # the chunks are in the file; the summary and footer are not (a SIGKILL)
    killed = tmp_path / 'killed'
    shutil.copytree(tmp_path / 'live', killed)
    writer.close()
    with pytest.raises(BagReadError, match='`recover` rebuilds it'), BagReader(killed):
        pass
