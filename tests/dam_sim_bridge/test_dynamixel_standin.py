"""Tests of the Dynamixel stand-in: physics behind the bus, lockstep, watchdog, the executable.

The dynamixel_sdk is the host, at the configured baud rate (the servos answer no other); the
world's own joint state is the independent truth.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from dynamixel_testing import fast_gil_handoff

from dam_common.config import DamConfig, load_config
from dam_sim_bridge.dynamixel_standin import DynamixelStandIn
from ros_testing import wait_for_signal_handlers

sdk = pytest.importorskip('dynamixel_sdk')

REPO = Path(__file__).resolve().parents[2]
RAD_PER_COUNT = 2.0 * math.pi / 4096


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    """The shipped configuration, finger 2 mounted the other way round (direction -1)."""
    base = load_config()
    if base.dynamixel is None:
        pytest.skip('the configuration has no dynamixel: section')
    servos = tuple(dataclasses.replace(s, direction=-1) if s.joint.startswith('finger2')
                   else s for s in base.dynamixel.servos)
    return dataclasses.replace(base, dynamixel=dataclasses.replace(base.dynamixel,
                                                                   servos=servos))



@pytest.fixture(autouse=True)
def _fast_gil_handoff() -> Iterator[None]:
    with fast_gil_handoff():
        yield

def _open(path: str, bps: int) -> sdk.PortHandler:
    """The SDK's port at ``bps`` [bit/s] (``openPort`` alone opens it at 1 Mbit/s)."""
    port = sdk.PortHandler(path)
    assert port.openPort() and port.setBaudRate(bps)
    return port


class _Rig:
    def __init__(self, standin: DynamixelStandIn) -> None:
        self.standin = standin
        self.port = _open(standin.port_path, standin.config.dynamixel.baud_rate)
        self.ph = sdk.PacketHandler(2.0)
        self.ids = [s.servo_id for s in standin.servo_configs]
        for i in self.ids:  # Return Delay Time 0, as a host at 250 Hz sets it
            self.write(i, 9, 1, 0)

    def state_sync(self) -> sdk.GroupSyncRead:
        read = sdk.GroupSyncRead(self.port, self.ph, 120, 16)
        for i in self.ids:
            read.addParam(i)
        result = read.txRxPacket()
        assert result == sdk.COMM_SUCCESS, self.ph.getTxRxResult(result)
        return read

    def write(self, servo_id: int, address: int, size: int, value: int) -> None:
        fn = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}
        assert fn[size](self.port, servo_id, address, value & ((1 << 8 * size) - 1)) == (0, 0)


@pytest.fixture
def lockstep(cfg: DamConfig) -> Iterator[_Rig]:
    standin = DynamixelStandIn(cfg, sim_time=True)
    thread = threading.Thread(target=standin.run, daemon=True)
    thread.start()
    rig = _Rig(standin)
    yield rig
    rig.port.closePort()
    standin.close()
    thread.join(2.0)
    assert not thread.is_alive()


def _signed(value: int, bits: int) -> int:
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def test_lockstep_one_period_per_state_read(lockstep: _Rig) -> None:
    st = lockstep.standin
    assert st.steps_per_cycle == round(st.period_s / st.world.time_step_s)
    assert st.now() == 0.0
    read = lockstep.state_sync()
    assert st.now() == pytest.approx(st.period_s)
    assert st.world.sim_time == pytest.approx(st.period_s)
    assert read.getData(1, 120, 2) == int(st.period_s * 1000)  # Realtime Tick [ms]
    # writes, pings and reads that miss Present Position do not advance the world
    lockstep.write(1, 65, 1, 1)
    assert lockstep.ph.ping(lockstep.port, 2)[1] == sdk.COMM_SUCCESS
    assert lockstep.ph.read4ByteTxRx(lockstep.port, 3, 128)[1] == sdk.COMM_SUCCESS
    other = sdk.GroupSyncRead(lockstep.port, lockstep.ph, 100, 32)  # 100..131
    other.addParam(1)
    assert other.txRxPacket() == sdk.COMM_SUCCESS
    assert st.stats.cycles == 1 and st.now() == pytest.approx(st.period_s)
    lockstep.ph.read4ByteTxRx(lockstep.port, 3, 132)  # a READ of Present Position does
    for _ in range(5):
        lockstep.state_sync()
    assert st.stats.cycles == 7
    assert st.now() == pytest.approx(7 * st.period_s)
    assert st.world.sim_time == pytest.approx(7 * st.steps_per_cycle * st.world.time_step_s)


def test_present_position_is_the_world_angle(lockstep: _Rig) -> None:
    st = lockstep.standin
    read = lockstep.state_sync()
    q = st.world.joint_states().positions
    for k, sc in enumerate(st.servo_configs):
        counts = _signed(read.getData(sc.servo_id, 132, 4), 32)
        theta = sc.direction * (counts - sc.zero_offset_counts) * RAD_PER_COUNT
        assert theta == pytest.approx(q[k], abs=RAD_PER_COUNT)


def test_current_mode_torque_follows_direction(lockstep: _Rig) -> None:
    st = lockstep.standin
    f1, f2 = 0, 3  # the compliant joints of fingers 1 and 2
    assert 'compliant' in st.world.joint_names[f1] and 'finger2' in st.world.joint_names[f2]
    s1, s2 = st.servo_configs[f1], st.servo_configs[f2]
    assert (s1.direction, s2.direction) == (1, -1)
    goal = 150
    for sc in (s1, s2):
        lockstep.write(sc.servo_id, 11, 1, 0)  # current mode
        lockstep.write(sc.servo_id, 64, 1, 1)
        lockstep.write(sc.servo_id, 102, 2, goal)
    q0 = st.world.joint_states().positions.copy()
    first = lockstep.state_sync()
    p0 = {sc.servo_id: _signed(first.getData(sc.servo_id, 132, 4), 32) for sc in (s1, s2)}
    for _ in range(25):  # 0.1 s: the torque has slewed to its goal
        read = lockstep.state_sync()
    q1 = st.world.joint_states().positions
    assert q1[f1] > q0[f1] + 0.02  # direction +1: positive current flexes the joint
    assert q1[f2] < q0[f2] - 0.02  # direction -1: the opposite
    for sc in (s1, s2):  # the servo itself turns positive either way
        assert _signed(read.getData(sc.servo_id, 132, 4), 32) > p0[sc.servo_id] + 10
        assert _signed(read.getData(sc.servo_id, 126, 2), 16) == pytest.approx(goal, abs=2)
    tau = st.world.joint_states().torques
    expected = goal * 2.69e-3 * s1.torque_constant_nm_per_a
    assert tau[f1] == pytest.approx(expected, rel=0.02)
    assert tau[f2] == pytest.approx(-expected, rel=0.02)


def test_position_mode_goes_to_the_goal_angle(lockstep: _Rig) -> None:
    st = lockstep.standin
    k = 4  # finger 2 (direction -1), the locked joint
    sc = st.servo_configs[k]
    lo, hi = st.world.joint_lower_limits[k], st.world.joint_upper_limits[k]
    target = lo + 0.3 * (hi - lo)
    goal = round(sc.zero_offset_counts + sc.direction * target / RAD_PER_COUNT)
    lockstep.write(sc.servo_id, 64, 1, 1)
    lockstep.write(sc.servo_id, 116, 4, goal)
    for _ in range(150):
        read = lockstep.state_sync()
    assert st.world.joint_states().positions[k] == pytest.approx(target, abs=0.02)
    assert _signed(read.getData(sc.servo_id, 132, 4), 32) == pytest.approx(goal, abs=15)


def test_torque_off_is_limp_and_hardware_error_cuts_torque(lockstep: _Rig) -> None:
    st = lockstep.standin
    sc = st.servo_configs[0]
    lockstep.write(sc.servo_id, 11, 1, 0)
    lockstep.write(sc.servo_id, 64, 1, 1)
    lockstep.write(sc.servo_id, 102, 2, 200)
    for _ in range(20):
        lockstep.state_sync()
    assert st.world.joint_states().torques[0] > 0.5
    st.hardware_error(sc.servo_id, 0x20)  # overload
    for _ in range(20):
        read = lockstep.state_sync()
    assert st.world.joint_states().torques[0] == pytest.approx(0.0, abs=1e-9)
    assert _signed(read.getData(sc.servo_id, 126, 2), 16) == 0
    value, result, error = lockstep.ph.read1ByteTxRx(lockstep.port, sc.servo_id, 70)
    assert (value, result) == (0x20, sdk.COMM_SUCCESS) and error & sdk.ERRBIT_ALERT


def test_bus_watchdog_on_the_device_clock(lockstep: _Rig) -> None:
    st = lockstep.standin
    watched, other = st.servo_configs[1].servo_id, st.servo_configs[0].servo_id
    lockstep.write(watched, 11, 1, 0)
    lockstep.write(watched, 98, 1, 2)  # 40 ms
    lockstep.write(watched, 64, 1, 1)
    lockstep.write(watched, 102, 2, 300)
    t0 = st.now()
    # Present Position READs of another servo advance the clock; the watched one hears none.
    while st.now() - t0 < 0.036:
        lockstep.ph.read4ByteTxRx(lockstep.port, other, 132)
    assert st.servos[1].table[98] == 2 and st.servos[1].output_enabled
    while st.now() - t0 < 0.044:
        lockstep.ph.read4ByteTxRx(lockstep.port, other, 132)
    value, result, _ = lockstep.ph.read1ByteTxRx(lockstep.port, watched, 98)
    assert (value, result) == (255, sdk.COMM_SUCCESS)
    assert lockstep.ph.write2ByteTxRx(lockstep.port, watched, 102, 100)[1] == 4  # Data Range
    for _ in range(15):
        lockstep.state_sync()
    assert st.world.joint_states().torques[1] == pytest.approx(0.0, abs=1e-9)  # stopped
    lockstep.write(watched, 98, 1, 0)  # clears the error
    lockstep.write(watched, 102, 2, 100)


def test_real_time_steps_on_its_own(cfg: DamConfig) -> None:
    standin = DynamixelStandIn(cfg)
    thread = threading.Thread(target=standin.run, daemon=True)
    thread.start()
    try:
        time.sleep(0.3)
        cycles = standin.stats.cycles
        assert 0.3 / standin.period_s * 0.3 < cycles <= 0.3 / standin.period_s + 2
        port = _open(standin.port_path, cfg.dynamixel.baud_rate)
        tick, result, _ = sdk.PacketHandler(2.0).read2ByteTxRx(port, 1, 120)
        assert result == sdk.COMM_SUCCESS
        assert (int(standin.now() * 1000) - tick) % 32768 < 50  # [ms], the device clock
        port.closePort()
    finally:
        standin.close()
        thread.join(2.0)
    assert not thread.is_alive()


def test_needs_a_dynamixel_section(cfg: DamConfig) -> None:
    from dam_sim_bridge.errors import WorldConfigError

    with pytest.raises(WorldConfigError, match='dynamixel'):
        DynamixelStandIn(dataclasses.replace(cfg, dynamixel=None))


def _with_baud_rate(cfg: DamConfig, bps: int) -> DamConfig:
    return dataclasses.replace(cfg, dynamixel=dataclasses.replace(cfg.dynamixel, baud_rate=bps))


@pytest.mark.parametrize(('bps', 'value'), [(4_000_000, 6), (1_000_000, 3), (57600, 1)])
def test_baud_rate_register_encodes_the_configured_rate(cfg: DamConfig, bps: int,
                                                        value: int) -> None:
    """e-manual, Baud Rate(8): 6 is 4 Mbit/s, 3 is 1 Mbit/s, 1 is 57600 bit/s. Every servo
    holds the configured rate's value and answers a host at that rate only."""
    standin = DynamixelStandIn(_with_baud_rate(cfg, bps), sim_time=True)
    thread = threading.Thread(target=standin.run, daemon=True)
    thread.start()
    ph = sdk.PacketHandler(2.0)
    port = _open(standin.port_path, bps)
    try:
        for sc in standin.servo_configs:
            assert ph.read1ByteTxRx(port, sc.servo_id, 8) == (value, sdk.COMM_SUCCESS, 0)
        assert port.setBaudRate(2_000_000)  # a rate no servo is set to
        assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT
        assert port.setBaudRate(bps)
        assert ph.ping(port, 1)[1] == sdk.COMM_SUCCESS
    finally:
        port.closePort()
        standin.close()
        thread.join(2.0)


def test_watchdog_feed_reaches_the_bus(cfg: DamConfig) -> None:
    from dam_sim_bridge.errors import WorldConfigError

    with DynamixelStandIn(cfg, sim_time=True) as standin:
        assert standin.watchdog_feed == standin.bus.watchdog_feed == 'addressed'
    with DynamixelStandIn(cfg, sim_time=True, watchdog_feed='any') as standin:
        assert standin.watchdog_feed == standin.bus.watchdog_feed == 'any'
    with pytest.raises(WorldConfigError, match="watchdog_feed 'sometimes' is not one of"):
        DynamixelStandIn(cfg, watchdog_feed='sometimes')


# -------------------------------------------------------------------------------------------
# The executable


def _env() -> dict[str, str]:
    """The source tree's packages first; C stdio buffered as by default (PYTHONUNBUFFERED
    would make Python switch C stdio's buffers off too, and hide what they hold back)."""
    env = dict(os.environ)
    env.pop('PYTHONUNBUFFERED', None)
    paths = [str(p) for p in sorted((REPO / 'src').iterdir()) if (p / 'setup.py').is_file()]
    env['PYTHONPATH'] = os.pathsep.join(paths + [env.get('PYTHONPATH', '')])
    return env


_CONSOLE_SCRIPT = ('import sys; from dam_sim_bridge.entry_points import dynamixel_bus; '
                   'sys.argv[0] = "dynamixel_bus"; dynamixel_bus()')


def _start(*args: str, code: str = _CONSOLE_SCRIPT) -> subprocess.Popen[str]:
    """The program as its console script runs it (or as ``code`` does), stdout a pipe."""
    return subprocess.Popen([sys.executable, '-c', code, *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=_env())


def _start_module(*args: str) -> subprocess.Popen[str]:
    """``python -m dam_sim_bridge.dynamixel_bus_program`` from the source tree."""
    return subprocess.Popen([sys.executable, '-m', 'dam_sim_bridge.dynamixel_bus_program',
                             *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env())


def _port_line_then_sigint(proc: subprocess.Popen[str]) -> tuple[str, str, str]:
    """The first stdout line, then SIGINT: (that line, the rest of stdout, stderr)."""
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return line, out, err


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_executable_prints_port_and_stops_cleanly(sig: signal.Signals, tmp_path: Path) -> None:
    link = tmp_path / 'ttyDXL'
    proc = _start('--link', str(link), '--sim-time')
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith('DYNAMIXEL_PORT /'), line
        path = line.split(maxsplit=1)[1].strip()
        assert os.path.realpath(link) == os.path.realpath(path)
        port = _open(path, 4_000_000)  # the shipped configuration's dynamixel.baud_rate
        assert sdk.PacketHandler(2.0).ping(port, 1)[1] == sdk.COMM_SUCCESS
        port.closePort()
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert 'Traceback' not in err and out == ''
    assert not link.is_symlink()


def test_python_m_prints_the_port_line_first() -> None:
    line, out, err = _port_line_then_sigint(_start_module())
    assert line.startswith('DYNAMIXEL_PORT /dev/'), (line, err)
    assert out == '' and 'Traceback' not in err
    assert 'argv[0]=' in err  # PyBullet's print, sent to stderr


#: The program, with a C library that prints into C stdio's buffer while the world is built and
#: does not flush (stdout is a pipe: block-buffered), as PyBullet's ``argv[0]=`` may.
_BUFFERED_C_PRINT = (
    'import ctypes, sys\n'
    'from dam_sim_bridge import world\n'
    'libc = ctypes.CDLL(None)\n'
    'build = world.HandWorld.__init__\n'
    'def build_and_print(self, *args, **kwargs):\n'
    '    build(self, *args, **kwargs)\n'
    '    libc.printf(b"buffered by C stdio\\n")\n'
    'world.HandWorld.__init__ = build_and_print\n'
    'from dam_sim_bridge.entry_points import dynamixel_bus\n'
    'sys.argv[0] = "dynamixel_bus"\n'
    'dynamixel_bus()\n')


def test_c_stdio_output_of_the_start_up_goes_to_stderr() -> None:
    """Nothing but the port line on stdout, even what C code left in its stdio buffer."""
    line, out, err = _port_line_then_sigint(_start(code=_BUFFERED_C_PRINT))
    assert line.startswith('DYNAMIXEL_PORT /dev/'), (line, err)
    assert out == '', out
    assert 'buffered by C stdio' in err and 'Traceback' not in err


@pytest.mark.parametrize(('feed', 'watchdog'), [('addressed', 255), ('any', 5)])
def test_executable_watchdog_feed(feed: str, watchdog: int) -> None:
    """--watchdog-feed: servo 1 armed with Bus Watchdog 5 (100 ms) hears only reads of servo 2
    for 160 ms of simulated time (40 lockstep cycles of 4 ms): under addressed it stops."""
    proc = _start('--sim-time', '--watchdog-feed', feed)
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith('DYNAMIXEL_PORT /'), line
        port = _open(line.split(maxsplit=1)[1].strip(), 4_000_000)
        ph = sdk.PacketHandler(2.0)
        assert ph.write1ByteTxRx(port, 1, 98, 5) == (sdk.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, 64, 1) == (sdk.COMM_SUCCESS, 0)
        for _ in range(40):
            assert ph.read4ByteTxRx(port, 2, 132)[1] == sdk.COMM_SUCCESS
        assert ph.read1ByteTxRx(port, 1, 98) == (watchdog, sdk.COMM_SUCCESS, 0)
        port.closePort()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err


def test_the_stand_in_does_not_import_the_entry_points() -> None:
    """No import cycle: the program's module is imported by the entry point when it runs, and
    neither the stand-in nor the program imports the entry points."""
    code = ('import sys\n'
            'import dam_sim_bridge.entry_points\n'
            'print(sorted(m for m in sys.modules if m.startswith("dam_sim_bridge.")))\n'
            'del sys.modules["dam_sim_bridge.entry_points"]\n'
            'import dam_sim_bridge.dynamixel_standin, dam_sim_bridge.dynamixel_bus_program\n'
            'print("dam_sim_bridge.entry_points" in sys.modules)\n')
    run = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=_env(), timeout=60, check=True)
    first, second = run.stdout.splitlines()[-2:]
    assert first == "['dam_sim_bridge.entry_points']"
    assert second == 'False'


def test_executable_signal_during_start_up() -> None:
    """SIGTERM while the program imports (its handlers are its first lines: a signal before
    them is the interpreter's to handle, so the test waits for them, not for a fixed time)."""
    proc = _start()
    wait_for_signal_handlers(proc)
    time.sleep(0.05)  # importing
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert 'Traceback' not in err


def test_executable_bad_arguments() -> None:
    proc = _start('--object', 'no_such_object')
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 2
    assert 'no_such_object' in err and 'usage' in err
    proc = _start('--frobnicate')
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and '--frobnicate' in err
    proc = _start('--watchdog-feed', 'sometimes')
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and "invalid choice: 'sometimes'" in err


# -------------------------------------------------------------------------------------------
# The stand-in node's watchdog_feed parameter


@pytest.fixture
def ros_args() -> Iterator[object]:
    """rclpy's default context, initialised by the test with its arguments."""
    rclpy = pytest.importorskip('rclpy')
    yield lambda *args: rclpy.init(args=['--ros-args', *args])
    rclpy.try_shutdown()


def test_node_refuses_another_watchdog_feed(ros_args) -> None:
    from dam_sim_bridge.errors import SimBridgeError
    from dam_sim_bridge.sim_bridge_node import SimBridgeNode

    ros_args('-p', 'bus:=dynamixel', '-p', 'watchdog_feed:=sometimes')
    with pytest.raises(SimBridgeError,
                       match="watchdog_feed 'sometimes' is not one of addressed, any"):
        SimBridgeNode()


def test_node_passes_watchdog_feed_to_the_bus(ros_args) -> None:
    from dam_sim_bridge.sim_bridge_node import SimBridgeNode

    ros_args('-p', 'bus:=dynamixel', '-p', 'watchdog_feed:=any')
    node = SimBridgeNode()
    try:
        assert node._device.watchdog_feed == 'any'
        descriptor = node.describe_parameter('watchdog_feed')
        assert descriptor.read_only and 'addressed or any' in descriptor.additional_constraints
    finally:
        node.destroy_node()
