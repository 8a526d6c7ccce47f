"""The driver's link end over loopback UDP and HandCommand validation."""

from __future__ import annotations

import math
import re
import socket

import numpy as np
import pytest

from dam_common.device_protocol import (
    FrameDecoder,
    FrameKind,
    JointMode,
    encode_state,
)
from dam_hand_driver.errors import ParameterError
from dam_hand_driver.link import DeviceLink

N = 3


@pytest.fixture
def pair():
    device = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    device.bind(('127.0.0.1', 0))
    device.settimeout(2.0)
    link = DeviceLink(N, '127.0.0.1', 0, device.getsockname()[1])
    yield link, device
    link.close()
    device.close()


def _state(seq: int, pos: int = 0) -> bytes:
    return encode_state(seq, 1000 * seq, [pos] * N, [0] * N, [0] * N, [3] * N)


def test_receive_returns_newest_frame_and_counts_rejections(pair) -> None:
    link, device = pair
    addr = link.state_address
    assert link.receive(0.01) is None
    for seq, pos in ((1, 10), (2, 20), (3, 30)):
        device.sendto(_state(seq, pos), addr)
    device.sendto(_state(2, 99), addr)  # stale
    device.sendto(b'DAMH-rubbish', addr)  # short / bad
    frame = None
    for _ in range(5):
        frame = link.receive(0.2) or frame
        if link.stats.datagrams >= 5:
            break
    assert frame is not None and frame.seq == 3
    assert frame.position_counts.tolist() == [30] * N
    assert link.decoder.counters.stale == 1
    assert link.decoder.counters.rejected == 2
    assert link.last_state_time is not None
    # after reset() a restarted device (seq from 0 again) is accepted
    link.reset()
    device.sendto(_state(0, 5), addr)
    frame = link.receive(1.0)
    assert frame is not None and frame.seq == 0


def test_send_produces_valid_command_frames(pair) -> None:
    link, device = pair
    assert link.send([1, 2, 3], [100, -200, 0], ref_state_seq=41)
    assert link.send([3, 3, 3], [0, 0, 0], ref_state_seq=42)
    decoder = FrameDecoder(FrameKind.COMMAND, N)
    first = decoder.decode(device.recv(2048))
    second = decoder.decode(device.recv(2048))
    assert first is not None and second is not None
    assert first.setpoints.tolist() == [100, -200, 0]
    assert first.ref_state_seq == 41
    assert second.seq == first.seq + 1
    assert link.stats.commands_sent == 2


def test_bad_port_is_refused() -> None:
    with pytest.raises(ParameterError, match='70000'):
        DeviceLink(N, '127.0.0.1', 70000, 1)


# --- driver logic (needs the generated dam_interfaces messages) -----------------------------

driver_node = pytest.importorskip('dam_hand_driver.driver_node')


def _msg(names, modes, setpoints, stiffness=(), damping=()):
    from dam_interfaces.msg import HandCommand

    return HandCommand(name=names, mode=modes, setpoint=setpoints, stiffness=list(stiffness),
                       damping=list(damping))


INDEX = {'a': 0, 'b': 1, 'c': 2}
LO = np.radians([-45.0, -10.0, 0.0])
HI = np.radians([60.0, 10.0, 95.0])


MAX_K, MAX_D = 100.0, 2.0


def _validate(names, modes, setpoints, stiffness=(), damping=()):
    return driver_node.validate_command(_msg(names, modes, setpoints, stiffness, damping), INDEX,
                                        1.0, LO, HI, MAX_K, MAX_D)


def test_message_modes_map_to_wire_modes() -> None:
    from dam_interfaces.msg import HandCommand

    assert driver_node.MSG_TO_WIRE_MODE[HandCommand.MODE_TORQUE] is JointMode.TORQUE
    assert driver_node.MSG_TO_WIRE_MODE[HandCommand.MODE_POSITION] is JointMode.POSITION
    assert driver_node.MSG_TO_WIRE_MODE[HandCommand.MODE_HOLD] is JointMode.HOLD
    assert driver_node.MSG_TO_WIRE_MODE[HandCommand.MODE_IMPEDANCE] is JointMode.IMPEDANCE
    out = _validate(['c', 'a'], [0, 1], [0.5, 0.2])
    assert out == [(2, JointMode.TORQUE, 0.5, 0.0, 0.0), (0, JointMode.POSITION, 0.2, 0.0, 0.0)]
    out = _validate(['a', 'c'], [3, 0], [0.3, 0.1], [10.0, math.nan], [0.2, math.nan])
    assert out == [(0, JointMode.IMPEDANCE, 0.3, 10.0, 0.2), (2, JointMode.TORQUE, 0.1, 0.0, 0.0)]
    # the limits themselves are accepted
    assert _validate(['a'], [3], [HI[0]], [MAX_K], [MAX_D])[0].stiffness == MAX_K
    assert _validate(['a'], [3], [LO[0]], [1e-3], [0.0])[0].damping == 0.0


@pytest.mark.parametrize(('names', 'modes', 'setpoints', 'match'), [
    (['a', 'b'], [0], [0.1, 0.1], 'differ in length'),
    (['x'], [0], [0.1], "unknown joint name 'x'"),
    (['a', 'a'], [0, 0], [0.1, 0.1], "'a' appears more than once"),
    (['a'], [7], [0.1], 'mode 7'),
    (['a'], [0], [math.nan], 'nan'),
    (['a'], [1], [math.inf], 'inf'),
    (['a'], [0], [1.5], 'torque 1.5'),
    (['b'], [1], [0.5], 'angle 0.5'),
])
def test_bad_commands_are_rejected_with_a_reason(names, modes, setpoints, match) -> None:
    with pytest.raises(driver_node.CommandRejected, match=match):
        _validate(names, modes, setpoints)


@pytest.mark.parametrize(('setpoint', 'stiffness', 'damping', 'match'), [
    (0.1, [], [], 'needs stiffness and damping'),
    (0.1, [5.0], [], 'needs stiffness and damping'),
    (0.1, [5.0, 5.0], [0.1, 0.1], 'stiffness has 2 entries for 1 names'),
    (0.1, [0.0], [0.1], r'stiffness 0\.0 N\*m/rad is outside \(0, 100\.0\]'),
    (0.1, [-3.0], [0.1], r'stiffness -3\.0'),
    (0.1, [150.0], [0.1], r'stiffness 150\.0'),
    (0.1, [math.nan], [0.1], 'stiffness nan'),
    (0.1, [math.inf], [0.1], 'stiffness inf'),
    (0.1, [5.0], [-0.01], r'damping -0\.01 N\*m\*s/rad is outside \[0, 2\.0\]'),
    (0.1, [5.0], [2.5], r'damping 2\.5'),
    (0.1, [5.0], [math.nan], 'damping nan'),
    (math.radians(70.0), [5.0], [0.1], r'equilibrium theta_0 1\.22'),
    (math.nan, [5.0], [0.1], 'setpoint nan'),
])
def test_bad_impedance_commands_are_rejected_naming_field_and_value(
        setpoint, stiffness, damping, match) -> None:
    with pytest.raises(driver_node.CommandRejected, match=match):
        _validate(['a'], [3], [setpoint], stiffness, damping)


def test_impedance_gains_the_link_cannot_carry_are_rejected() -> None:
    """A stiffness below one raw unit of the calibration (1e-4 N*m/rad by default) passes the
    range check but could not be encoded into any frame: refused on arrival, by joint."""
    from dam_common.device_protocol import Calibration

    calibration = Calibration(position_scale_rad_per_count=[1e-4] * N,
                              position_offset_counts=[0] * N,
                              torque_scale_nm_per_raw=[1e-5] * N, torque_offset_raw=[0] * N)
    tiny = _validate(['a'], [3], [0.1], [1e-5], [0.1])
    from dam_hand_driver.udp_device import gains_error

    assert re.search('cannot carry.*stiffness', gains_error(tiny, calibration) or '')
    fine = _validate(['a', 'b'], [3, 0], [0.1, 0.2], [5.0, 0.0], [0.1, 0.0])
    assert gains_error(fine, calibration) is None
