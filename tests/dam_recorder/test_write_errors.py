"""BagWriter on a file system that fills up (a real 2 MB tmpfs; needs root for mount, skipped
with the reason otherwise): the first write error is raised once, as ``BagWriteError`` naming
the bag, the file and ENOSPC; the bag is closed with what is on disk, ``metadata.yaml`` says
what the data file holds and counts every message not written; ``recover`` loses nothing of
what is on disk."""

from __future__ import annotations

import errno
import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from bag_readers import read_with_mcap, read_with_rosbags
from rosbag2_format import metadata_problems

from dam_recorder.bag_writer import UNWRITTEN_KEY, BagWriter
from dam_recorder.errors import BagWriteError
from dam_recorder.recovery import recover_bag
from dam_recorder.type_description import load_message_type

T0 = 1_700_000_000_000_000_000  # [ns]


@pytest.fixture
def small_fs(tmp_path: Path) -> Iterator[Path]:
    """A 2 MB tmpfs under ``tmp_path`` (unmounted afterwards)."""
    where = tmp_path / 'fs'
    where.mkdir()
    done = subprocess.run(['mount', '-t', 'tmpfs', '-o', 'size=2m', 'tmpfs', str(where)],
                          capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        pytest.skip(f'cannot mount a tmpfs: {done.stderr.strip()}')
    try:
        yield where
    finally:
        subprocess.run(['umount', str(where)], capture_output=True, timeout=30)


def blob(i: int, size: int = 4000) -> bytes:
    """A serialized std_msgs/msg/UInt8MultiArray of random bytes starting with ``i``."""
    data = i.to_bytes(4, 'little') + os.urandom(size - 4)
    layout = b'\x00\x00\x00\x00' + b'\x00\x00\x00\x00'  # no dims, data_offset 0
    return b'\x00\x01\x00\x00' + layout + len(data).to_bytes(4, 'little') + data


def indices(bag: Path, read=read_with_rosbags) -> list[int]:
    return [int.from_bytes(bytes(r.values['data'][:4]), 'little')
            for r in read(bag).get('/blobs', [])]


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_full_disk_is_raised_once_and_the_bag_closed_with_what_is_on_disk(
        small_fs: Path, prefixes, storage: str) -> None:
    bag = small_fs / 'bag'
    writer = BagWriter(bag, storage=storage, compression='zstd' if storage == 'mcap'
                       else 'none')
    blobs = load_message_type('std_msgs/msg/UInt8MultiArray', prefixes)
    topic = writer.add_topic('/blobs', blobs.name, blobs.definition(), blobs.type_hash, [])
    errors = []
    for i in range(1000):  # 4 MB
        try:
            writer.write(topic, T0 + i * 1000, blob(i))
            if i % 20 == 19:
                writer.flush()
        except BagWriteError as exc:
            errors.append(exc)
    writer.flush()  # nothing happens any more
    writer.close()
    assert len(errors) == 1
    failure = errors[0].failure
    assert failure.errno == errno.ENOSPC and failure.bag_dir == bag
    assert str(bag) in str(errors[0]) and 'ENOSPC' in str(errors[0])
    assert failure.path.name in (f'bag_0.{"mcap" if storage == "mcap" else "db3"}',
                                 'metadata.yaml.tmp')
    recorded = indices(bag)
    assert 0 < len(recorded) < 1000 and recorded == list(range(len(recorded)))
    assert metadata_problems(bag) == []
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['message_count'] == len(recorded) == writer.topics[0].message_count
    assert json.loads(info['custom_data'][UNWRITTEN_KEY]) == {'/blobs': 1000 - len(recorded)}
    assert writer.unwritten == {'/blobs': 1000 - len(recorded)}
    if storage == 'mcap':  # finished with its summary: the indexed reader reads it
        assert indices(bag, read_with_mcap) == recorded
    recover_bag(bag)
    assert indices(bag) == recorded


def test_the_error_line_does_not_say_the_reason_twice(tmp_path: Path) -> None:
    from dam_recorder.write_failure import WriteFailure

    same = WriteFailure(tmp_path, tmp_path / 'b_0.mcap', errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert same.describe().endswith('b_0.mcap: ENOSPC (No space left on device)'), same.describe()
    other = WriteFailure(tmp_path, tmp_path / 'b_0.db3', errno.ENOSPC, 'SQLITE_FULL: full')
    assert other.describe().endswith('ENOSPC (No space left on device; SQLITE_FULL: full)')


def test_a_write_after_the_file_was_released_is_a_write_error(tmp_path: Path) -> None:
    """A write that reaches a stream already released is an OSError (so the writer ends the
    recording as for any write error), not a ValueError that only a generic handler sees."""
    from dam_recorder.storage_stream import StorageStream

    path = tmp_path / 'b_0.mcap'
    stream = StorageStream(path, os.open(path, os.O_WRONLY | os.O_CREAT), 0)
    stream.write(b'abc')
    stream.release()
    stream.write(b'def')
    with pytest.raises(OSError) as raised:
        stream.flush()
    assert raised.value.errno == errno.EBADF and raised.value.filename == str(path)
