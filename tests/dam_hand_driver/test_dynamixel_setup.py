"""``dynamixel_setup`` against the emulated bus, through the real SDK (no ROS).

The command's ``main`` runs in this process beside the emulated bus (``DynamixelStandIn`` on a
pseudo-terminal, lockstep); what it reports and writes is checked against the emulated
servos' control tables and the shipped configuration file, read independently of the command.
The busy-port and signal tests start the command as a process of its own (a lock's holder is
named only when it is another process; signals end a whole process).
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from dynamixel_testing import fast_gil_handoff

from dam_common.config import DamConfig, load_config
from dam_common.shutdown import StartupInterrupted
from ros_testing import stop_with_signal

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = REPO_ROOT / 'config' / 'dam.yaml'
CONFIGURED_BAUD = 4000000
#: Model numbers of the ROBOTIS e-manual.
MODEL_NUMBERS = {'XM430-W350': 1020, 'XC330-M288': 1240}
#: A table line of the scan: ID, model (number), firmware, baud rates, Return Delay Time.
ROW = re.compile(r'^\s+(\d+)\s+(\S+) \((\d+)\)\s+(\d+)\s+(\d[\d, ]*?)\s+(\d+) us \((\d+)\)\s')


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config(CONFIG)


@pytest.fixture(scope='module')
def shipped() -> dict:
    """config/dam.yaml as plain YAML (not through the loader)."""
    return yaml.safe_load(CONFIG.read_text(encoding='utf-8'))


@contextlib.contextmanager
def emulated_bus(cfg: DamConfig, **kwargs: Any) -> Iterator[Any]:
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn

    with fast_gil_handoff():
        bus = DynamixelStandIn(cfg, sim_time=True, **kwargs)
        thread = threading.Thread(target=bus.run, daemon=True)
        thread.start()
        try:
            yield bus
        finally:
            bus.close()
            thread.join(2.0)


@pytest.fixture
def standin(cfg: DamConfig) -> Iterator[Any]:
    with emulated_bus(cfg) as bus:
        yield bus


def run(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    """``main`` of the command with ``args`` (and the shipped configuration unless given)."""
    from dam_hand_driver.dynamixel_setup import main

    argv = [str(a) for a in args]
    if '--config' not in argv and argv and argv[0] != '--help':
        argv += ['--config', str(CONFIG)]
    capsys.readouterr()
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


def table(bus: Any, j: int, name: str) -> int:
    with bus.lock:
        return int(bus.servos[j].get(name))


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith('dynamixel_setup: ')
    return lines[0]


def src_env() -> dict[str, str]:
    """The environment of a command started from ``src/`` (as the unit tests import it)."""
    paths = [str(p) for p in sorted((REPO_ROOT / 'src').iterdir()) if (p / 'setup.py').is_file()]
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(paths + [env.get('PYTHONPATH', '')]).rstrip(os.pathsep)
    env['PYTHONUNBUFFERED'] = '1'
    return env


def command(*args: object) -> list[str]:
    return [sys.executable, '-m', 'dam_hand_driver.dynamixel_setup',
            *(str(a) for a in args), '--config', str(CONFIG)]


# -------------------------------------------------------------------------------------------
# scan


def test_scan_lists_the_servos_the_bus_reports_with_the_fixes(cfg: DamConfig, shipped: dict,
                                                              capsys, monkeypatch) -> None:
    from dam_hand_driver import dynamixel_port

    with emulated_bus(cfg, return_delay_time_raw=250) as bus:
        # A pseudo-terminal has no USB latency timer: the adapter's factory 16 ms, as sysfs
        # would give it.
        monkeypatch.setattr(dynamixel_port, 'usb_latency_timer_ms',
                            lambda port: 16 if port == bus.port_path else None)
        status, out, err = run(capsys, 'scan', '--port', bus.port_path,
                               '--baud-rate', CONFIGURED_BAUD, 1000000)
        firmware = [table(bus, j, 'firmware_version') for j in range(9)]
        ids = [table(bus, j, 'id') for j in range(9)]
    assert status == 0, err
    rows = {int(m[1]): m for m in (ROW.match(line) for line in out.splitlines()) if m}
    assert sorted(rows) == list(range(1, 10))
    servos = shipped['dynamixel']['servos']
    for joint, servo in servos.items():
        row = rows[servo['id']]
        assert (row[2], int(row[3])) == (servo['model'], MODEL_NUMBERS[servo['model']])
        assert int(row[4]) == firmware[ids.index(servo['id'])]
        assert CONFIGURED_BAUD in [int(r) for r in row[5].split(',')]
        assert (int(row[6]), int(row[7])) == (500, 250)  # 250 x 2 us
        assert row.string.rstrip().endswith(joint)
    assert re.search(r'Return Delay Time \(address 9\) is not 0 on ID 1-9 .*write 0 to address '
                     r'9 with torque off', out)
    assert 'latency timer' in out and '16 ms' in out and 'latency_timer' in out
    assert 'the bus matches dynamixel.servos' in out


def test_scan_names_a_servo_that_does_not_answer_and_a_hardware_error(cfg: DamConfig,
                                                                     standin, capsys) -> None:
    standin.silent_ids = [7]
    standin.hardware_error(3, 0x20)  # overload
    status, out, err = run(capsys, 'scan', '--port', standin.port_path,
                           '--baud-rate', CONFIGURED_BAUD)
    assert status == 1
    assert 'servo ID 7 (finger3_compliant_joint) does not answer' in one_line(err)
    rows = {int(m[1]): m for m in (ROW.match(line) for line in out.splitlines()) if m}
    assert sorted(rows) == [1, 2, 3, 4, 5, 6, 8, 9]
    assert '32 (overload error)' in rows[3].string
    assert ' 0 ' in rows[1].string and 'error' not in rows[1].string


def test_nothing_answering_is_refused(cfg: DamConfig, standin, capsys) -> None:
    standin.silent_ids = list(range(1, 10))
    status, _, err = run(capsys, 'scan', '--port', standin.port_path,
                         '--baud-rate', CONFIGURED_BAUD)
    assert status == 1
    assert f'no servo answers on {standin.port_path} at any of 4000000 bit/s' in one_line(err)


def test_a_wrong_model_is_refused_by_scan_and_zero(cfg: DamConfig, shipped: dict, standin,
                                                   capsys, tmp_path: Path) -> None:
    edited = dict(shipped)
    edited['dynamixel'] = dict(shipped['dynamixel'])
    edited['dynamixel']['servos'] = dict(shipped['dynamixel']['servos'])
    edited['dynamixel']['servos']['finger1_locked_joint'] = dict(
        shipped['dynamixel']['servos']['finger1_locked_joint'], model='XM430-W350',
        current_limit_a=1.0)
    wrong = tmp_path / 'wrong.yaml'
    wrong.write_text(yaml.safe_dump(edited), encoding='utf-8')
    load_config(wrong)  # a valid configuration, of another hand
    expected = ('servo ID 2 (finger1_locked_joint) is XC330-M288 (model number 1240), the '
                'configuration says XM430-W350 (1020)')
    status, _, err = run(capsys, 'scan', '--port', standin.port_path, '--config', wrong,
                         '--baud-rate', CONFIGURED_BAUD)
    assert status == 1 and expected in one_line(err)
    output = tmp_path / 'zero.yaml'
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '--config', wrong,
                         '-o', output)
    assert status == 1 and expected in one_line(err)
    assert not output.exists()


def test_an_unknown_model_number_is_named(cfg: DamConfig, standin, capsys,
                                          tmp_path: Path) -> None:
    with standin.lock:
        standin.servos[4].set('model_number', 1200)
    status, out, err = run(capsys, 'scan', '--port', standin.port_path,
                           '--baud-rate', CONFIGURED_BAUD)
    assert status == 1
    assert re.search(r'^\s+5\s+unknown model 1200: not supported\s', out, re.MULTILINE)
    assert ('servo ID 5 (finger2_locked_joint) is unknown model 1200: not supported'
            in one_line(err))
    output = tmp_path / 'zero.yaml'
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output)
    assert status == 1
    assert ('servo ID 5 (finger2_locked_joint) is unknown model 1200: not supported'
            in one_line(err))
    assert not output.exists()


# -------------------------------------------------------------------------------------------
# zero


def test_zero_writes_the_present_positions_as_an_overlay_the_loader_accepts(
        cfg: DamConfig, standin, capsys, tmp_path: Path) -> None:
    output = tmp_path / 'zero.yaml'
    status, out, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output)
    assert status == 0, err
    assert 'Hold every finger straight' in out
    present = {table(standin, j, 'id'): table(standin, j, 'present_position') for j in range(9)}
    text = output.read_text(encoding='utf-8')
    written = yaml.safe_load(text)
    assert list(written) == ['dynamixel'] and list(written['dynamixel']) == ['servos']
    by_joint = {s.joint: s.servo_id for s in cfg.dynamixel.servos}
    assert {joint: entry['zero_offset_counts']
            for joint, entry in written['dynamixel']['servos'].items()} == {
        joint: present[servo_id] for joint, servo_id in by_joint.items()}
    loaded = load_config(CONFIG, [output])
    assert [s.zero_offset_counts for s in loaded.dynamixel.servos] == [
        present[s.servo_id] for s in cfg.dynamixel.servos]
    assert [s.model for s in loaded.dynamixel.servos] == [s.model for s in cfg.dynamixel.servos]
    comments = [line for line in text.splitlines() if line.startswith('#')]
    assert text.startswith('#')
    assert any('hand_driver --ros-args -p backend:=dynamixel -p config_overlay:=' in line
               for line in comments)
    assert any('load_config(path, [' in line for line in comments)
    # An existing file is kept without --force, replaced with it; no temporary file is left.
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output)
    assert status == 1 and '--force' in one_line(err)
    assert output.read_text(encoding='utf-8') == text
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output, '--force')
    assert status == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ['zero.yaml']


def test_zero_section_writes_the_port_the_baud_rate_and_the_models(
        cfg: DamConfig, shipped: dict, standin, capsys, tmp_path: Path) -> None:
    output = tmp_path / 'hand.yaml'
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output,
                         '--section', '--baud-rate', 57600, CONFIGURED_BAUD)
    assert status == 0, err
    loaded = load_config(CONFIG, [output]).dynamixel
    assert loaded.port == standin.port_path
    assert loaded.baud_rate == CONFIGURED_BAUD  # where the servos answer
    assert table(standin, 0, 'baud_rate') == 6  # the Baud Rate value of 4 Mbit/s
    for servo in loaded.servos:
        assert servo.model == shipped['dynamixel']['servos'][servo.joint]['model']
        j = [table(standin, k, 'id') for k in range(9)].index(servo.servo_id)
        assert servo.zero_offset_counts == table(standin, j, 'present_position')
    assert loaded.rate_hz == cfg.dynamixel.rate_hz


def test_zero_refuses_offsets_the_loader_refuses_without_writing(cfg: DamConfig, standin,
                                                                 capsys,
                                                                 tmp_path: Path) -> None:
    # A Homing Offset puts Present Position of finger1_position_joint near the encoder's
    # end: its joint limits (0..95 deg, 1081 counts) cannot fit above it.
    with standin.lock:
        standin.servos[2].set('homing_offset', 1800)
    output = tmp_path / 'zero.yaml'
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output)
    assert status == 1
    line = one_line(err)
    assert 'not written' in line
    assert 'dynamixel.servos.finger1_position_joint.zero_offset_counts' in line
    assert '.tmp' not in line
    assert list(tmp_path.iterdir()) == []


def test_zero_names_a_servo_that_does_not_answer(cfg: DamConfig, standin, capsys,
                                                 tmp_path: Path) -> None:
    standin.silent_ids = [4]
    output = tmp_path / 'zero.yaml'
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o', output)
    assert status == 1
    assert 'servo ID 4 (finger2_compliant_joint) does not answer' in one_line(err)
    assert list(tmp_path.iterdir()) == []


# What the command's handler of SIGINT and SIGTERM raises, and Python's own of SIGINT.
@pytest.mark.parametrize('interrupt', [StartupInterrupted, KeyboardInterrupt],
                         ids=lambda e: e.__name__)
def test_an_interrupt_while_writing_leaves_no_file(cfg: DamConfig, standin, capsys,
                                                   tmp_path: Path, monkeypatch,
                                                   interrupt: type[BaseException]) -> None:
    from dam_hand_driver import dynamixel_setup_cli

    real = dynamixel_setup_cli.load_config

    def interrupted(path: object = None, overlays: object = ()) -> DamConfig:
        if overlays and any(str(o).endswith('.tmp') for o in overlays):
            raise interrupt
        return real(path, overlays)

    monkeypatch.setattr(dynamixel_setup_cli, 'load_config', interrupted)
    status, _, err = run(capsys, 'zero', '--port', standin.port_path, '-o',
                         tmp_path / 'zero.yaml')
    assert status == 130
    assert 'interrupted' in one_line(err)
    assert list(tmp_path.iterdir()) == []


# -------------------------------------------------------------------------------------------
# set-id and fix


def test_set_id_gives_a_servo_another_id_and_refuses_a_taken_one(cfg: DamConfig, standin,
                                                                 capsys) -> None:
    status, out, err = run(capsys, 'set-id', '--port', standin.port_path, '--id', 9,
                           '--new-id', 20, '--baud-rate', CONFIGURED_BAUD)
    assert status == 0, err
    assert table(standin, 8, 'id') == 20 and table(standin, 8, 'torque_enable') == 0
    assert 'is now ID 20' in out
    status, _, err = run(capsys, 'set-id', '--port', standin.port_path, '--id', 1,
                         '--new-id', 2, '--baud-rate', CONFIGURED_BAUD)
    assert status == 1 and 'ID 2 is taken' in one_line(err)
    assert table(standin, 0, 'id') == 1
    status, _, err = run(capsys, 'set-id', '--port', standin.port_path, '--id', 30,
                         '--new-id', 31, '--baud-rate', CONFIGURED_BAUD)
    assert status == 1 and 'no servo ID 30 answers' in one_line(err)


def test_fix_clears_return_delay_time_and_sets_the_configured_baud_rate(cfg: DamConfig,
                                                                        capsys) -> None:
    with emulated_bus(cfg, return_delay_time_raw=250) as bus:
        with bus.lock:
            for s in bus.servos:
                s.set('baud_rate', 3)  # 1 Mbit/s (a scan at 57600 takes twice as long)
        status, out, err = run(capsys, 'fix', '--port', bus.port_path, '--baud-rate', 1000000)
        assert status == 0, err
        for j in range(9):
            assert table(bus, j, 'return_delay_time') == 0
            assert table(bus, j, 'baud_rate') == 6  # 4 Mbit/s (e-manual)
            assert table(bus, j, 'torque_enable') == 0
    assert '9 servos at 4000000 bit/s with Return Delay Time 0' in out


# -------------------------------------------------------------------------------------------
# Refusals of the port and the command line


def test_a_busy_port_is_refused_naming_the_holder() -> None:
    import dynamixel_sdk

    from dam_hand_driver.dynamixel_port import close_port, open_port

    master, slave = os.openpty()
    try:
        path = os.ttyname(slave)
        held = open_port(dynamixel_sdk, path, 57600)
        try:
            done = subprocess.run(command('scan', '--port', path), env=src_env(),
                                  capture_output=True, text=True, timeout=60)
        finally:
            close_port(held)
    finally:
        os.close(master)
        os.close(slave)
    assert done.returncode == 1, done.stderr
    line = one_line(done.stderr)
    assert 'in use by another program' in line and f'PID {os.getpid()}' in line


def test_a_missing_port_is_named(capsys, tmp_path: Path) -> None:
    missing = tmp_path / 'ttyUSB9'
    status, _, err = run(capsys, 'scan', '--port', missing)
    assert status == 1
    assert f"'{missing}': no such device" in one_line(err)


def test_no_port_and_a_repeated_option_are_usage_errors(shipped: dict, capsys) -> None:
    assert shipped['dynamixel']['port'] == ''
    status, _, err = run(capsys, 'scan')
    assert status == 2 and 'no port: give --port DEV' in one_line(err)
    status, _, err = run(capsys, 'scan', '--port', '/dev/null', '--port', '/dev/null')
    assert status == 2 and '--port given twice' in err
    status, _, err = run(capsys, 'set-id', '--port', '/dev/null', '--id', 3, '--new-id', 3)
    assert status == 2 and '--id and --new-id are both 3' in one_line(err)
    status, _, err = run(capsys, 'scan', '--port', '/dev/null', '--baud-rate', 12345)
    assert status == 2 and '12345' in err
    status, out, _ = run(capsys, '--help')
    assert status == 0 and 'exit status' in out and 'zero' in out


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_it_cleanly(cfg: DamConfig, standin, signum: int) -> None:
    import dynamixel_sdk

    from dam_hand_driver.dynamixel_port import close_port, open_port

    proc = subprocess.Popen(command('scan', '--port', standin.port_path, '--baud-rate', 57600,
                                    115200, 1000000), env=src_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()  # the scan has begun: the port is open
        assert first.startswith('scanning'), first
        time.sleep(0.3)  # inside the first broadcast ping
    finally:
        _, err = stop_with_signal(proc, signum, timeout_s=30.0)
    assert proc.returncode == 130, err
    assert 'Traceback' not in err
    assert 'interrupted' in one_line(err)
    close_port(open_port(dynamixel_sdk, standin.port_path, 57600))  # the lock went with it


# -------------------------------------------------------------------------------------------
# Pure parts


def test_baud_rates_are_tried_configured_first_and_differences_say_what_to_change(
        cfg: DamConfig) -> None:
    from dam_hand_driver.dynamixel_setup_bus import (
        FoundServo,
        ScanResult,
        baud_rate_order,
        id_ranges,
    )
    from dam_hand_driver.dynamixel_setup_cli import compare

    assert baud_rate_order(4000000, None) == (4000000, 57600, 115200, 1000000, 2000000,
                                              3000000)
    assert baud_rate_order(4000000, [57600, 57600, 1000000]) == (57600, 1000000)
    assert id_ranges([9, 1, 2, 3, 5, 7, 8]) == '1-3, 5, 7-9'
    servos = [FoundServo(s.servo_id, MODEL_NUMBERS[s.model], 48,
                         (57600,) if s.servo_id in (3, 4, 6) else (4000000,), 0, 0)
              for s in cfg.dynamixel.servos if s.servo_id != 8]
    servos.append(FoundServo(12, 1020, 48, (4000000,), 0, 0))
    result = ScanResult((4000000, 57600), {}, (), tuple(servos))
    problems = compare(result, cfg.dynamixel, '/dev/ttyUSB0')
    assert len(problems) == 3
    assert problems[0].startswith('servo ID 8 (finger3_locked_joint) does not answer')
    assert problems[1].startswith('servos ID 3-4, 6 answer at 57600 bit/s, not at '
                                  'dynamixel.baud_rate 4000000')
    assert 'Baud Rate (address 8) 6' in problems[1]
    assert problems[2].startswith("servo ID 12 (XM430-W350 (model number 1020)) is no joint's")
    one = ScanResult((4000000, 57600), {}, (), tuple(
        FoundServo(s.servo_id, MODEL_NUMBERS[s.model], 48,
                   (57600,) if s.servo_id == 3 else (4000000,), 0, 0)
        for s in cfg.dynamixel.servos))
    assert compare(one, cfg.dynamixel, '/dev/ttyUSB0') == [
        'servo ID 3 (finger1_position_joint) answers at 57600 bit/s, not at dynamixel.baud_rate '
        '4000000: dynamixel_setup fix --port /dev/ttyUSB0 writes the Baud Rate (address 8) 6 '
        'with torque off (or set dynamixel.baud_rate to the rate every servo answers at)']
