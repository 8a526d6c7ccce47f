"""Tests of one emulated servo's control table and rules (no bus, no physics)."""

from __future__ import annotations

import struct

import pytest

from dam_sim_bridge.dynamixel_packets import ALERT_BIT, ErrorCode
from dam_sim_bridge.dynamixel_servo import (
    FIELDS,
    HW_INPUT_VOLTAGE,
    HW_OVERLOAD,
    SERVO_MODELS,
    DynamixelServo,
    Status,
)

OK = int(ErrorCode.NONE)


def _u16(value: int) -> bytes:
    return struct.pack('<H', value)


def _i16(value: int) -> bytes:
    return struct.pack('<h', value)


def _i32(value: int) -> bytes:
    return struct.pack('<i', value)


@pytest.fixture
def xm() -> DynamixelServo:
    return DynamixelServo(3, 'XM430-W350')


def test_models_agree_with_the_configuration_module() -> None:
    models = pytest.importorskip('dam_common.dynamixel_config').MODELS
    assert set(SERVO_MODELS) == set(models)
    for name, spec in models.items():
        m = SERVO_MODELS[name]
        assert m.model_number == spec.model_number
        assert m.current_unit_a == pytest.approx(spec.current_unit_a)
        assert m.current_limit == spec.current_limit_max


def test_defaults_and_layout(xm: DynamixelServo) -> None:
    xc = DynamixelServo(7, 'XC330-M288')
    t = xm.table
    assert struct.unpack_from('<H', t, 0)[0] == 1020
    assert struct.unpack_from('<H', xc.table, 0)[0] == 1240
    assert t[7] == 3 and xc.table[7] == 7
    assert t[8] == 1 and xc.table[8] == 1  # Baud Rate from the factory: 57600 bit/s
    assert xm.baud_rate_bps == xc.baud_rate_bps == 57600
    assert t[9] == 250 and t[11] == 3 and t[63] == 52 and t[68] == 2
    assert struct.unpack_from('<H', t, 38)[0] == 1193
    assert struct.unpack_from('<H', xc.table, 38)[0] == 2352
    assert struct.unpack_from('<I', t, 48)[0] == 4095
    assert struct.unpack_from('<I', t, 52)[0] == 0
    assert t[64] == 0 and t[70] == 0
    assert FIELDS['present_position'].address == 132 and FIELDS['present_position'].signed
    assert FIELDS['goal_current'].address == 102 and FIELDS['goal_current'].size == 2


def test_ping_answers_model_and_firmware(xm: DynamixelServo) -> None:
    status = xm.ping()
    assert status.error == OK
    assert status.params[:2] == _u16(1020) and len(status.params) == 3


def test_read_signed_present_values_and_tick(xm: DynamixelServo) -> None:
    xm.set_present(-5000, -12, -300)
    status = xm.read(120, 16, now_s=40.0125)
    assert status.error == OK
    tick, = struct.unpack_from('<H', status.params, 0)
    assert tick == 40012 % 32768
    assert struct.unpack_from('<h', status.params, 6)[0] == -300
    assert struct.unpack_from('<i', status.params, 8)[0] == -12
    assert struct.unpack_from('<i', status.params, 12)[0] == -5000
    assert xm.read(0, 0, 0.0).error == ErrorCode.DATA_LENGTH


def test_the_table_ends_where_the_e_manual_table_ends(xm: DynamixelServo) -> None:
    """XM430-W350: Indirect Data 56 at address 661 is the last item; XC330-M288: Indirect Data
    20 at 227. Past the end: Access Error. Inside, items not emulated read as zeros."""
    xc = DynamixelServo(7, 'XC330-M288')
    for servo, last in ((xm, 661), (xc, 227)):
        assert servo.read(last, 1, 0.0) == Status(OK, b'\x00')
        assert servo.read(last + 1, 1, 0.0).error == ErrorCode.ACCESS
        assert servo.read(last - 9, 11, 0.0).error == ErrorCode.ACCESS  # reaches past it
        assert servo.read(last - 9, 10, 0.0) == Status(OK, bytes(10))
        assert servo.read(168, 2, 0.0).error == OK  # Indirect Address 1 (not emulated)
        assert servo.write(last + 1, b'\x00').error == ErrorCode.ACCESS
        assert servo.write(last, b'\x00').error == ErrorCode.ACCESS  # not emulated
    assert xc.read(228, 4, 0.0).error == ErrorCode.ACCESS  # an XM430 has Indirect Data there
    assert xm.read(228, 4, 0.0).error == OK
    assert xm.read(250, 10, 0.0).error == OK
    assert xm.read(634, 28, 0.0).error == OK  # Indirect Data 29..56
    assert xm.read(634, 29, 0.0).error == ErrorCode.ACCESS


#: Baud Rate (address 8) values of the X series [bit/s] (e-manual, Baud Rate(8)).
E_MANUAL_BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000,
                       5: 3_000_000, 6: 4_000_000, 7: 4_500_000}


def test_baud_rate_values_per_model(xm: DynamixelServo) -> None:
    """0..7 on the XM430-W350 (4.5 Mbit/s its fastest); 0..6 on the XC330-M288 (4 Mbit/s)."""
    xc = DynamixelServo(7, 'XC330-M288')
    for value, bps in E_MANUAL_BAUD_RATES.items():
        assert SERVO_MODELS['XM430-W350'].baud_rate_value(bps) == value
        assert xm.write(8, bytes((value,))).error == OK
        assert xm.baud_rate_bps == bps
        if value <= 6:
            assert SERVO_MODELS['XC330-M288'].baud_rate_value(bps) == value
            assert xc.write(8, bytes((value,))).error == OK
            assert xc.baud_rate_bps == bps
    assert xc.write(8, b'\x07').error == ErrorCode.DATA_RANGE
    assert xc.baud_rate_bps == 4_000_000  # nothing written
    assert xm.write(8, b'\x08').error == ErrorCode.DATA_RANGE
    with pytest.raises(ValueError, match='XC330-M288 has no baud rate of 4500000'):
        SERVO_MODELS['XC330-M288'].baud_rate_value(4_500_000)
    with pytest.raises(ValueError, match='19200'):
        SERVO_MODELS['XM430-W350'].baud_rate_value(19200)
    xm.write(64, b'\x01')
    assert xm.write(8, b'\x03').error == ErrorCode.ACCESS  # EEPROM: torque off only


def test_write_rules(xm: DynamixelServo) -> None:
    assert xm.write(0, _u16(1)).error == ErrorCode.ACCESS  # model number: read-only
    assert xm.write(132, _i32(0)).error == ErrorCode.ACCESS  # present position
    assert xm.write(14, b'\x00').error == ErrorCode.ACCESS  # no item there
    assert xm.write(116, b'\x00\x01').error == ErrorCode.DATA_LENGTH  # half an item
    assert xm.write(11, b'\x02').error == ErrorCode.DATA_RANGE  # no mode 2
    assert xm.write(11, b'\x00').error == OK
    assert xm.write(102, _i16(1194)).error == ErrorCode.DATA_LIMIT
    assert xm.write(102, _i16(-1194)).error == ErrorCode.DATA_LIMIT
    assert xm.get('goal_current') == 0  # nothing written
    assert xm.write(102, _i16(-1193)).error == OK
    assert xm.get('goal_current') == -1193
    assert xm.write(11, b'\x03').error == OK
    assert xm.write(116, _i32(4096)).error == ErrorCode.DATA_LIMIT
    assert xm.write(116, _i32(-1)).error == ErrorCode.DATA_LIMIT
    assert xm.write(116, _i32(4095)).error == OK
    assert xm.write(11, b'\x04').error == OK  # extended position: beyond one turn is fine
    assert xm.write(116, _i32(-20000)).error == OK
    # a lower Current Limit narrows Goal Current; above the model's maximum is out of range
    assert xm.write(38, _u16(1194)).error == ErrorCode.DATA_RANGE
    assert xm.write(38, _u16(100)).error == OK
    assert xm.write(102, _i16(101)).error == ErrorCode.DATA_LIMIT


def test_multi_item_write_is_all_or_nothing(xm: DynamixelServo) -> None:
    # 100..103 = Goal PWM (2) + Goal Current (2): a bad Goal Current writes no Goal PWM either
    assert xm.write(100, _i16(100) + _i16(5000)).error == ErrorCode.DATA_LIMIT
    assert xm.get('goal_pwm') == 0
    assert xm.write(100, _i16(100) + _i16(50)).error == OK
    assert (xm.get('goal_pwm'), xm.get('goal_current')) == (100, 50)


def test_eeprom_locked_while_torque_on(xm: DynamixelServo) -> None:
    assert xm.write(64, b'\x01').error == OK
    assert xm.write(11, b'\x00').error == ErrorCode.ACCESS
    assert xm.get('operating_mode') == 3
    assert xm.write(65, b'\x01').error == OK  # RAM is fine
    assert xm.write(64, b'\x00').error == OK
    assert xm.write(11, b'\x00').error == OK


def test_hardware_error_alert_torque_and_reboot(xm: DynamixelServo) -> None:
    xm.write(20, _i32(100))  # EEPROM: kept over the reboot
    xm.write(64, b'\x01')
    xm.write(65, b'\x01')
    xm.set_hardware_error(HW_OVERLOAD)
    assert xm.table[70] == HW_OVERLOAD
    assert not xm.torque_enabled and not xm.output_enabled
    assert xm.ping().error == ALERT_BIT
    assert xm.read(70, 1, 0.0).error == ALERT_BIT
    refused = xm.write(64, b'\x01')
    assert refused.error == ALERT_BIT | ErrorCode.RESULT_FAIL
    assert not xm.torque_enabled
    assert xm.reboot().error == ALERT_BIT  # the answer goes out before the reboot
    assert xm.table[70] == 0 and xm.table[65] == 0 and not xm.torque_enabled
    assert xm.get('homing_offset') == 100
    assert xm.write(64, b'\x01').error == OK


def test_hardware_error_not_in_shutdown_keeps_torque(xm: DynamixelServo) -> None:
    xm.write(64, b'\x01')
    xm.set_hardware_error(HW_INPUT_VOLTAGE)  # not in the default Shutdown (52)
    assert xm.torque_enabled and xm.ping().error == ALERT_BIT


def test_status_return_level_and_return_delay(xm: DynamixelServo) -> None:
    assert xm.return_delay_s == pytest.approx(500e-6)
    assert xm.write(68, b'\x01').error == OK
    assert xm.status_return_level == 1
    assert xm.write(68, b'\x03').error == ErrorCode.DATA_RANGE


def test_bus_watchdog(xm: DynamixelServo) -> None:
    xm.write(11, b'\x00')
    xm.write(98, b'\x02')  # 40 ms
    xm.write(64, b'\x01')
    xm.heard(10.0)
    assert not xm.check_watchdog(10.039)
    xm.heard(10.039)  # a packet restarts the interval
    assert not xm.check_watchdog(10.078)
    assert xm.check_watchdog(10.0795)
    assert xm.table[98] == 255 and xm.torque_enabled and not xm.output_enabled
    assert xm.write(102, _i16(10)).error == ErrorCode.DATA_RANGE
    assert xm.write(98, b'\x00').error == OK  # clears the error
    assert xm.output_enabled
    assert xm.write(102, _i16(10)).error == OK


def test_watchdog_idle_while_torque_off(xm: DynamixelServo) -> None:
    xm.write(98, b'\x01')
    xm.heard(0.0)
    assert not xm.check_watchdog(5.0)
    assert xm.table[98] == 1


def test_homing_offset_shifts_present_position(xm: DynamixelServo) -> None:
    xm.write(20, _i32(-48))
    xm.set_present(2048, 0, 0)
    assert xm.get('present_position') == 2000
    with pytest.raises(ValueError, match='unknown servo model'):
        DynamixelServo(1, 'AX-12')
