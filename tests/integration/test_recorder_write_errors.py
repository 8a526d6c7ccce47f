"""The recorder on a file system that stops taking its bag (issue 20): full, read-only, an I/O
error, the bag directory removed while recording; real recorder and publisher processes, real
small file systems (a 2 MB tmpfs; an ext4 image on a loop device, made read-only by an ext4
error or shut down for EIO). Needs root for mount; skipped with the reason otherwise.

Before: on a full tmpfs the recorder logged ENOSPC every 20 ms, went on running, exited 1 with a
traceback on SIGINT, left ``metadata.yaml`` at 0 messages, counted no loss. Now, every time:
one error line naming the bag, the file and the errno; the bag closed with what is on disk;
every message not written counted; the process ends by itself with status 74 and no
traceback; ``recover`` afterwards gets back every message on disk.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from ros_testing import RosClient, fixture_command, installed_executable, node_process

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'fixtures'))
from bag_readers import read_with_mcap, read_with_rosbags  # noqa: E402
from blob_publisher import TOPIC, index_of  # noqa: E402

pytestmark = pytest.mark.integration

RECORDER = installed_executable('dam_recorder', 'recorder')
RECOVER = installed_executable('dam_recorder', 'recover')
#: The recorder's documented exit status after a write error.
WRITE_ERROR_STATUS = 74
UNWRITTEN_KEY = 'dam_recorder.unwritten_messages'
#: ext4's FS_IOC_SHUTDOWN (_IOR('X', 125, __u32)) and its "no log flush" mode.
EXT4_IOC_SHUTDOWN = 0x8004587D
SHUTDOWN_NOLOGFLUSH = 2


def _run(*command: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(list(command), capture_output=True, text=True, timeout=60)


@contextmanager
def _mounted(*command: str, where: Path) -> Iterator[Path]:
    where.mkdir(parents=True, exist_ok=True)
    done = _run(*command, str(where))
    if done.returncode != 0:
        pytest.skip(f'cannot mount a test file system ({" ".join(command)}): '
                    f'{done.stderr.strip()}')
    try:
        yield where
    finally:
        if _run('umount', str(where)).returncode != 0:
            _run('umount', '-l', str(where))


@pytest.fixture
def small_tmpfs(tmp_path: Path) -> Iterator[Path]:
    """A 2 MB tmpfs under ``tmp_path``."""
    with _mounted('mount', '-t', 'tmpfs', '-o', 'size=2m', 'tmpfs',
                  where=tmp_path / 'tmpfs') as where:
        yield where


@pytest.fixture
def ext4_image(tmp_path: Path) -> Path:
    """An empty 32 MB ext4 image (mounted by the test)."""
    image = tmp_path / 'ext4.img'
    with open(image, 'wb') as out:
        out.truncate(32 << 20)
    done = _run('mkfs.ext4', '-q', '-F', str(image))
    if done.returncode != 0:
        pytest.skip(f'mkfs.ext4 is not available: {done.stderr.strip()}')
    return image


def _wait_for(proc, text: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.output():
        assert proc.alive(), f'exited before printing {text!r}:\n{proc.output()}'
        assert time.monotonic() < deadline, f'no {text!r} within {timeout} s:\n{proc.output()}'
        time.sleep(0.05)


def _ends_by_itself(rec, timeout: float = 30.0) -> int:
    try:
        return rec.process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        pytest.fail(f'the recorder did not stop by itself:\n{rec.output()[-3000:]}')


def _check_one_error(log: str, errno_name: str, *names: str) -> str:
    """Exactly one error line, naming the errno and ``names``; no traceback."""
    errors = [line for line in log.splitlines() if '[ERROR]' in line or '[FATAL]' in line]
    assert len(errors) == 1, '\n'.join(errors[:20]) or log[-3000:]
    assert 'Traceback' not in log, log[-3000:]
    for text in (errno_name, *names):
        assert text in errors[0], errors[0]
    return errors[0]


def _metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def _indices(bag: Path) -> list[int]:
    return [index_of(r.values['data']) for r in read_with_rosbags(bag).get(TOPIC, [])]


def _unwritten_in_log(log: str) -> int:
    line = [x for x in log.splitlines() if 'not written' in x][-1]
    return int(line.split('not written ')[1].split(';')[0].split(' ')[0])


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_a_full_file_system_stops_the_recording_once_with_the_bag_closed(
        small_tmpfs: Path, storage: str) -> None:
    bag = small_tmpfs / 'full'
    count = 1000  # 4 MB into 2 MB
    with node_process(fixture_command('blob_publisher.py', '--count', str(count))) as pub:
        _wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '-s', storage, '--chunk-interval', '0.2',
                           TOPIC]) as rec:
            status = _ends_by_itself(rec)
            log = rec.output()
        assert f'published {count}' in pub.output()
    assert status == WRITE_ERROR_STATUS, log[-3000:]
    _check_one_error(log, 'ENOSPC', str(bag), f'full_0.{"mcap" if storage == "mcap" else "db3"}')
    info = _metadata(bag)
    recorded = _indices(bag)
    assert recorded == list(range(len(recorded))) and 0 < len(recorded) < count
    # metadata.yaml says what the data file holds, and counts the rest as not written.
    assert info['message_count'] == len(recorded)
    assert [f['message_count'] for f in info['files']] == [len(recorded)]
    unwritten = json.loads(info['custom_data'][UNWRITTEN_KEY])
    assert unwritten == {TOPIC: count - len(recorded)}
    assert _unwritten_in_log(log) == count - len(recorded)
    if storage == 'mcap':  # the file was finished: the indexed reader reads it
        assert [index_of(r.values['data']) for r in read_with_mcap(bag)[TOPIC]] == recorded
    done = _run(str(RECOVER), str(bag))
    assert done.returncode == 0, done.stderr
    assert _indices(bag) == recorded


def test_the_bag_directory_removed_while_recording(tmp_path: Path) -> None:
    bag = tmp_path / 'removed'
    with node_process(fixture_command('blob_publisher.py', '--count', '2000', '--size', '200',
                                      '--rate', '200')) as pub:
        _wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '--chunk-interval', '0.2',
                           TOPIC]) as rec:
            _wait_for(pub, 'publishing')
            time.sleep(1.0)
            shutil.rmtree(bag)
            status = _ends_by_itself(rec, timeout=10.0)
            log = rec.output()
    assert status == WRITE_ERROR_STATUS, log[-3000:]
    _check_one_error(log, 'ENOENT', str(bag))
    assert not bag.exists()  # nothing written where the user removed it
    assert _unwritten_in_log(log) > 0


def _ext4_device(where: Path) -> str:
    return os.path.basename(_run('findmnt', '-n', '-o', 'SOURCE', str(where)).stdout.strip())


def _make_read_only(where: Path) -> None:
    """An ext4 error with errors=remount-ro: the kernel makes the file system read-only under
    the open files (``mount -o remount,ro`` refuses while a file is open for writing)."""
    Path(f'/sys/fs/ext4/{_ext4_device(where)}/trigger_fs_error').write_text('test\n')


def _shut_down(where: Path) -> None:
    """ext4 shut down: every later write fails with EIO."""
    fd = os.open(where, os.O_RDONLY)
    try:
        fcntl.ioctl(fd, EXT4_IOC_SHUTDOWN, struct.pack('I', SHUTDOWN_NOLOGFLUSH))
    finally:
        os.close(fd)


@pytest.mark.parametrize(('fault', 'errno_name'), [(_make_read_only, 'EROFS'),
                                                   (_shut_down, 'EIO')])
def test_a_file_system_turned_read_only_or_failing(tmp_path: Path, ext4_image: Path, fault,
                                                   errno_name: str) -> None:
    where = tmp_path / 'ext4'
    with _mounted('mount', '-o', 'loop,errors=remount-ro', str(ext4_image), where=where):
        bag = where / 'bag'
        with node_process(fixture_command('blob_publisher.py', '--count', '2000', '--size',
                                          '500', '--rate', '200')) as pub:
            _wait_for(pub, 'waiting')
            with node_process([RECORDER, '-o', str(bag), '--chunk-interval', '0.2',
                               TOPIC]) as rec:
                _wait_for(pub, 'publishing')
                time.sleep(1.0)
                os.sync()  # (the recorder hands its files to the system, it does not sync)
                time.sleep(0.5)
                fault(where)
                status = _ends_by_itself(rec, timeout=10.0)
                log = rec.output()
    assert status == WRITE_ERROR_STATUS, log[-3000:]
    _check_one_error(log, errno_name, str(bag), 'bag_0.mcap')
    assert _unwritten_in_log(log) > 0
    # Mounted again (the journal replayed): recover gets back what reached the disk (at
    # least what was synced), a contiguous run from the first message, as both readers see
    # it.
    with _mounted('mount', '-o', 'loop', str(ext4_image), where=where):
        done = _run(str(RECOVER), str(bag))
        assert done.returncode == 0, done.stdout + done.stderr
        recorded = _indices(bag)
        assert recorded == list(range(len(recorded))) and len(recorded) >= 100, recorded[-5:]
        assert [index_of(r.values['data']) for r in read_with_mcap(bag)[TOPIC]] == recorded
        assert _metadata(bag)['message_count'] == len(recorded)


def test_episodes_on_a_full_file_system(small_tmpfs: Path) -> None:
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    from dam_interfaces.msg import GraspEpisode

    out = small_tmpfs / 'episodes'
    # 12 MB in 7.5 s: an episode holds each message back 3 s before it writes it.
    with node_process(fixture_command('blob_publisher.py', '--count', '3000',
                                      '--rate', '400')) as pub:
        _wait_for(pub, 'waiting')
        with node_process([RECORDER, '--episodes', '-o', str(out), '--pre-roll', '0.5',
                           '--chunk-interval', '0.2', TOPIC, '/dam/episode']) as rec:
            client = RosClient()
            try:
                events = client.node.create_publisher(GraspEpisode, '/dam/episode', QoSProfile(
                    depth=10, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE))
                _wait_for(rec, 'recording /dam/episode')
                msg = GraspEpisode(event=GraspEpisode.EVENT_STARTED, goal_id=uuid.uuid4().hex,
                                   object='cylinder', config_yaml='task: {}\n')
                msg.header.stamp = client.node.get_clock().now().to_msg()
                events.publish(msg)
                status = _ends_by_itself(rec)
                log = rec.output()
            finally:
                client.close()
    assert status == WRITE_ERROR_STATUS, log[-3000:]
    _check_one_error(log, 'ENOSPC', str(out))
    [episode] = [p for p in out.iterdir() if p.is_dir()]
    assert episode.name.endswith('_unknown_incomplete'), episode.name
    info = _metadata(episode)
    recorded = _indices(episode)
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    assert counts[TOPIC] == len(recorded) > 0  # (the bag also holds the STARTED event)
    unwritten = json.loads(info['custom_data'][UNWRITTEN_KEY])[TOPIC]
    assert unwritten > 0 and _unwritten_in_log(log) == unwritten
    missing = json.loads(info['custom_data']['dam_episode.missing'])
    assert any(m['kind'] == 'unwritten' and 'ENOSPC' in m['detail'] for m in missing), missing


def test_sigint_after_the_write_error_still_ends_cleanly(small_tmpfs: Path) -> None:
    bag = small_tmpfs / 'interrupted'
    with node_process(fixture_command('blob_publisher.py', '--count', '1000')) as pub:
        _wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '--chunk-interval', '0.2',
                           TOPIC]) as rec:
            _wait_for(rec, 'ENOSPC', timeout=30.0)
            rec.process.send_signal(signal.SIGINT)
            status = _ends_by_itself(rec, timeout=10.0)
            log = rec.output()
    assert status == WRITE_ERROR_STATUS, log[-3000:]
    _check_one_error(log, 'ENOSPC', str(bag))
