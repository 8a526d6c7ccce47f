"""Tests of the device link codec, decoder, calibration and watchdog (no ROS, no sockets)."""

from __future__ import annotations

import math
import socket
import struct
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from dam_common.config import load_config
from dam_common.device_protocol import (
    MAGIC,
    PROTOCOL_VERSION,
    Calibration,
    CommandFrame,
    DeviceWatchdog,
    FrameDecoder,
    FrameKind,
    JointMode,
    StateFrame,
    check_watchdog_timeout,
    command_frame_size,
    crc32,
    encode_command,
    encode_state,
    seq_newer,
    seq_next,
    state_frame_size,
)
from dam_common.errors import DeviceParameterError, EncodeError

N = 9
T, P, H = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMP = int(JointMode.IMPEDANCE)


def _state(seq: int, n: int = N, rng: np.random.Generator | None = None) -> bytes:
    rng = rng or np.random.default_rng(seq)
    big = 2**31
    return encode_state(
        seq, int(rng.integers(0, 2**63)),
        rng.integers(-big, big, n), rng.integers(-big, big, n), rng.integers(-big, big, n),
        rng.integers(1, 4, n), rng.integers(0, 2**16, n), status=int(rng.integers(0, 2**16)))


def _command(seq: int, ref: int = 0, n: int = N) -> bytes:
    modes = [IMP, T, H, P, IMP, P, T, H, IMP][:n]
    stiffness = [100_000 + seq % 1000 if m == IMP else 0 for m in modes]
    damping = [(seq * 7) % 300_000 if m == IMP else 0 for m in modes]
    return encode_command(seq, ref, modes, list(range(-4, n - 4)), stiffness, damping)


def _with_crc(body: bytes) -> bytes:
    """Re-seal a modified frame (without its old CRC) with a correct checksum."""
    return body + struct.pack('<I', zlib.crc32(body) & 0xFFFFFFFF)


# --------------------------------------------------------------------------------------------
# Codec


def test_crc_is_the_standard_crc32_check_value() -> None:
    # The published check value of CRC-32/ISO-HDLC.
    assert crc32(b'123456789') == 0xCBF43926


def test_frame_sizes_match_the_documented_layout() -> None:
    assert state_frame_size(N) == 12 + 12 + 16 * N + 4 == len(_state(1))
    assert command_frame_size(N) == 12 + 6 + 14 * N + 4 == len(_command(1))


def test_state_round_trip_with_extreme_values() -> None:
    lo, hi = -(2**31), 2**31 - 1
    pos = [lo, hi, 0, 1, -1, 12345, -54321, 7, 8]
    vel = [hi, lo, 3, 4, 5, 6, 7, 8, 9]
    tor = [0, -1, 1, lo, hi, 100, -100, 2, 3]
    modes = [T, P, H] * 3
    faults = [0, 1, 2, 4, 8, 15, 0xFFFF, 0, 3]
    data = encode_state(2**32 - 1, 2**64 - 1, pos, vel, tor, modes, faults, status=3)
    frame = FrameDecoder(FrameKind.STATE, N).decode(data)
    assert isinstance(frame, StateFrame)
    assert frame.seq == 2**32 - 1 and frame.timestamp_ns == 2**64 - 1 and frame.status == 3
    assert frame.position_counts.tolist() == pos
    assert frame.velocity_counts_per_s.tolist() == vel
    assert frame.torque_raw.tolist() == tor
    assert frame.modes.tolist() == modes and frame.faults.tolist() == faults


def test_state_header_bytes_follow_the_layout() -> None:
    data = _state(0x01020304)
    assert data[:4] == MAGIC
    assert data[4] == PROTOCOL_VERSION and data[5] == FrameKind.STATE
    assert struct.unpack_from('<H', data, 6)[0] == len(data)
    assert struct.unpack_from('<I', data, 8)[0] == 0x01020304
    assert struct.unpack_from('<I', data, len(data) - 4)[0] == zlib.crc32(data[:-4])


def test_command_round_trip() -> None:
    modes = [T, P, H, T, P, H, T, P, H]
    setpoints = [-(2**31), 2**31 - 1, 0, 5, -5, 0, 123, 456, 0]
    data = encode_command(77, 76, modes, setpoints)
    assert data[5] == FrameKind.COMMAND
    frame = FrameDecoder(FrameKind.COMMAND, N).decode(data)
    assert isinstance(frame, CommandFrame)
    assert (frame.seq, frame.ref_state_seq) == (77, 76)
    assert frame.modes.tolist() == modes and frame.setpoints.tolist() == setpoints
    assert frame.stiffness.tolist() == [0] * N and frame.damping.tolist() == [0] * N


def test_command_round_trip_with_impedance_gains() -> None:
    modes = [IMP, T, H, IMP, P, H, IMP, P, IMP]
    setpoints = [2618, 5, 0, -(2**31), 7, 0, 2**31 - 1, 1, 0]
    stiffness = [1, 0, 0, 2**31 - 1, 0, 0, 100_000, 0, 5]
    damping = [0, 0, 0, 2**31 - 1, 0, 0, 200_000, 0, 0]
    data = encode_command(3, 2, modes, setpoints, stiffness, damping)
    assert len(data) == command_frame_size(N)
    # joint 0 record right after the 18 bytes of header and body: mode, setpoint, k, d
    assert struct.unpack_from('<Hiii', data, 18) == (IMP, 2618, 1, 0)
    frame = FrameDecoder(FrameKind.COMMAND, N).decode(data)
    assert isinstance(frame, CommandFrame)
    assert frame.modes.tolist() == modes and frame.setpoints.tolist() == setpoints
    assert frame.stiffness.tolist() == stiffness and frame.damping.tolist() == damping


@pytest.mark.parametrize('stiffness, damping, word', [
    ([0] + [0] * 8, None, r'stiffness\[0\] = 0'),
    ([-5] + [0] * 8, None, r'stiffness\[0\] = -5'),
    ([10] + [0] * 8, [-1] + [0] * 8, r'damping\[0\] = -1'),
    ([10, 3] + [0] * 7, None, r'joint 1 in mode 1: stiffness 3'),
    ([10] + [0] * 8, [0, 0, 4] + [0] * 6, r'joint 2 in mode 3'),
    ([2**31] + [0] * 8, None, r'stiffness\[0\]'),
])
def test_encode_rejects_bad_gains(stiffness, damping, word) -> None:
    modes = [IMP, T, H] + [P] * 6
    with pytest.raises(EncodeError, match=word):
        encode_command(1, 0, modes, [0] * N, stiffness, damping)


def _command_with_raw_gains(seq: int, modes, stiffness, damping) -> bytes:
    """A correctly sealed command frame whose gains bypass the encoder's checks."""
    body = struct.pack('<4sBBHI', MAGIC, PROTOCOL_VERSION, FrameKind.COMMAND,
                       command_frame_size(len(modes)), seq)
    body += struct.pack('<IH', 0, len(modes))
    for m, k, d in zip(modes, stiffness, damping, strict=True):
        body += struct.pack('<Hiii', m, 0, k, d)
    return _with_crc(body)


def test_decoder_rejects_garbage_gains_as_bad_value() -> None:
    """Negative or zero stiffness, negative damping on an IMPEDANCE joint, or any gain on
    another joint: the whole frame is dropped and counted as bad_value (never clamped)."""
    dec = FrameDecoder(FrameKind.COMMAND, 3)
    seq = 1
    bad_cases = [
        ([IMP, T, H], [-1, 0, 0], [0, 0, 0]),
        ([IMP, T, H], [0, 0, 0], [0, 0, 0]),
        ([IMP, T, H], [-(2**31), 0, 0], [0, 0, 0]),
        ([IMP, T, H], [5, 0, 0], [-3, 0, 0]),
        ([IMP, T, H], [5, 1, 0], [0, 0, 0]),
        ([IMP, T, P], [5, 0, 0], [0, 0, 9]),
    ]
    for modes, k, d in bad_cases:
        assert dec.decode(_command_with_raw_gains(seq, modes, k, d)) is None, (modes, k, d)
        assert dec.last_reject == 'bad_value'
        seq += 1
    assert dec.counters.bad_value == len(bad_cases)
    good = dec.decode(_command_with_raw_gains(seq, [IMP, T, H], [5, 0, 0], [0, 0, 0]))
    assert good is not None and good.stiffness.tolist() == [5, 0, 0]


def test_fuzz_random_gains_accepted_exactly_when_valid() -> None:
    """2 * 10**4 sealed frames with random modes and int32 gains: accepted if and only if
    IMPEDANCE joints have k > 0 and d >= 0 and every other joint has k = d = 0."""
    rng = np.random.default_rng(5)
    dec = FrameDecoder(FrameKind.COMMAND, N)
    accepted = 0
    for seq in range(1, 20_001):
        modes = rng.integers(1, 5, N)
        # mostly plausible values, sometimes garbage anywhere in the int32 range
        k = np.where(rng.random(N) < 0.9, np.where(modes == IMP, rng.integers(1, 10**6, N), 0),
                     rng.integers(-(2**31), 2**31, N))
        d = np.where(rng.random(N) < 0.9, np.where(modes == IMP, rng.integers(0, 10**6, N), 0),
                     rng.integers(-(2**31), 2**31, N))
        valid = all((k[j] > 0 and d[j] >= 0) if modes[j] == IMP else (k[j] == 0 and d[j] == 0)
                    for j in range(N))
        frame = dec.decode(_command_with_raw_gains(seq, modes.tolist(), k.tolist(),
                                                   d.tolist()))
        assert (frame is not None) == valid, (seq, modes, k, d, dec.last_reject)
        if frame is not None:
            accepted += 1
            assert frame.stiffness.tolist() == k.tolist()
            assert frame.damping.tolist() == d.tolist()
    assert 0 < accepted < 20_000
    assert dec.counters.bad_value == 20_000 - accepted


def test_version_1_frames_are_rejected_as_bad_version() -> None:
    """A protocol-1 command frame (6-byte joint records, version byte 1) is counted under
    bad_version, whatever else it holds."""
    n = 3
    body = struct.pack('<4sBBHI', MAGIC, 1, FrameKind.COMMAND, 22 + 6 * n, 1)
    body += struct.pack('<IH', 0, n) + struct.pack('<HiHiHi', T, 10, P, 20, H, 0)
    old = _with_crc(body)
    dec = FrameDecoder(FrameKind.COMMAND, n)
    assert dec.decode(old) is None
    assert dec.counters.bad_version == 1 and dec.counters.rejected == 1
    assert PROTOCOL_VERSION == 2


@pytest.mark.parametrize('kwargs, word', [
    ({'seq': -1}, 'sequence'),
    ({'seq': 2**32}, 'sequence'),
    ({'setpoints': [2**31] + [0] * 8}, 'setpoints[0]'),
    ({'setpoints': [0.5] + [0] * 8}, 'integers'),
    ({'setpoints': [float('nan')] + [0] * 8}, 'non-finite'),
    ({'modes': [0] + [T] * 8}, 'modes[0] = 0'),
    ({'modes': [T] * 8}, 'shape'),
])
def test_encode_rejects_bad_values_and_names_them(kwargs: dict, word: str) -> None:
    args = {'seq': 1, 'ref_state_seq': 0, 'modes': [T] * N, 'setpoints': [0] * N}
    args.update(kwargs)
    with pytest.raises(EncodeError, match=word.replace('[', r'\[').replace(']', r'\]')):
        encode_command(**args)


def _doc_example(marker: str) -> bytes:
    doc = Path(__file__).resolve().parents[2] / 'docs' / 'device_protocol.md'
    text = doc.read_text(encoding='utf-8')
    block = text.split(f'<!-- {marker} -->', 1)[1].split('```', 2)[1]
    return bytes.fromhex(block)


def test_documented_examples_match_the_codec() -> None:
    assert _doc_example('example-command') == encode_command(1, 0, [T], [1000])
    assert _doc_example('example-impedance') == encode_command(2, 1, [IMP], [2618], [100_000],
                                                               [200_000])
    assert _doc_example('example-state') == encode_state(7, 1_000_000, [2618], [-25], [150],
                                                         [H], [0], status=2)


# --------------------------------------------------------------------------------------------
# Decoder: each rejection counted under its own reason


def test_each_rejection_reason_is_counted() -> None:
    dec = FrameDecoder(FrameKind.STATE, N)
    good = _state(10)
    body = good[:-4]
    cases = {
        'short': good[:15],
        'bad_magic': b'XAMH' + good[4:],
        'bad_version': _with_crc(body[:4] + bytes([PROTOCOL_VERSION + 1]) + body[5:]),
        'bad_kind': _command(10),
        'bad_length': good + b'\x00',
        'bad_crc': body + bytes([good[-4] ^ 0x01]) + good[-3:],
        'bad_joint_count': _state(10, n=N - 1),
        'bad_value': _with_crc(body[:24 + 12] + struct.pack('<H', 9) + body[24 + 14:]),
    }
    for reason, data in cases.items():
        assert dec.decode(data) is None, reason
        assert getattr(dec.counters, reason) == 1, (reason, dec.counters)
        assert dec.last_reject == reason
    assert dec.counters.rejected == len(cases)
    assert dec.counters.accepted == 0
    assert dec.decode(good) is not None
    assert dec.counters.accepted == 1
    assert dec.counters.internal_error == 0


def test_joint_count_in_body_must_match() -> None:
    good = _state(3)
    # Same length, but the body claims 8 joints.
    forged = _with_crc(good[:20] + struct.pack('<H', N - 1) + good[22:-4])
    dec = FrameDecoder(FrameKind.STATE, N)
    assert dec.decode(forged) is None
    assert dec.counters.bad_joint_count == 1


def test_stale_and_replayed_frames_are_dropped() -> None:
    dec = FrameDecoder(FrameKind.COMMAND, N)
    assert dec.decode(_command(100)) is not None
    assert dec.decode(_command(100)) is None  # replay of the newest
    assert dec.decode(_command(99)) is None  # reordered / old
    assert dec.decode(_command(50)) is None
    assert (dec.counters.replayed, dec.counters.stale) == (1, 2)
    assert dec.decode(_command(103)) is not None  # gaps (lost datagrams) are fine
    assert dec.decode(_command(101)) is None
    assert dec.newest_seq == 103
    dec.reset()  # peer restarted
    assert dec.decode(_command(1)) is not None
    assert dec.counters.accepted == 3


def test_sequence_numbers_wrap_around() -> None:
    assert seq_next(2**32 - 1) == 0
    assert seq_newer(0, 2**32 - 1) and not seq_newer(2**32 - 1, 0)
    assert seq_newer(5, 3) and not seq_newer(3, 5) and not seq_newer(7, 7)
    assert not seq_newer(2**31 + 10, 10)  # half the circle ahead counts as old
    dec = FrameDecoder(FrameKind.STATE, N)
    assert dec.decode(_state(2**32 - 2)) is not None
    assert dec.decode(_state(2**32 - 1)) is not None
    assert dec.decode(_state(0)) is not None
    assert dec.decode(_state(2**32 - 1)) is None
    assert dec.counters.stale == 1


def test_decoder_accepts_memoryview_and_bytearray() -> None:
    dec = FrameDecoder(FrameKind.STATE, N)
    assert dec.decode(bytearray(_state(1))) is not None
    assert dec.decode(memoryview(_state(2))) is not None


def test_decoder_never_raises_on_non_bytes() -> None:
    dec = FrameDecoder(FrameKind.STATE, N)
    assert dec.decode(None) is None  # type: ignore[arg-type]
    assert dec.counters.internal_error == 1


def test_frames_survive_a_loopback_udp_round_trip() -> None:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.bind(('127.0.0.1', 0))
        rx.settimeout(2.0)
        dec = FrameDecoder(FrameKind.STATE, N)
        sent = [_state(seq) for seq in range(1, 21)]
        for data in sent:
            tx.sendto(data, rx.getsockname())
        received = [rx.recvfrom(2048)[0] for _ in sent]
        assert received == sent  # one frame per datagram, unfragmented
        assert all(dec.decode(d) is not None for d in received)
        assert dec.decode(received[-1]) is None and dec.counters.replayed == 1
    finally:
        rx.close()
        tx.close()


# --------------------------------------------------------------------------------------------
# Fuzz


def _flip_bits(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    n_bits = int(rng.integers(1, 9))
    for bit in rng.choice(len(buf) * 8, size=n_bits, replace=False):
        buf[bit // 8] ^= 1 << (bit % 8)
    return bytes(buf)


@pytest.mark.parametrize('kind', [FrameKind.STATE, FrameKind.COMMAND])
def test_fuzz_no_corrupt_frame_accepted_and_next_valid_frame_is(kind: FrameKind) -> None:
    """10**5 corrupt datagrams in all, half per decoder kind; after each, a fresh valid frame
    must pass."""
    rng = np.random.default_rng(20261123 + int(kind))
    dec = FrameDecoder(kind, N)
    make = _state if kind is FrameKind.STATE else _command
    size = state_frame_size(N) if kind is FrameKind.STATE else command_frame_size(N)
    header_prefix = MAGIC + bytes([PROTOCOL_VERSION, int(kind)]) + struct.pack('<H', size)
    n_corrupt = 50_000
    seq = 1
    valid = make(seq)
    assert dec.decode(valid) is not None
    started = time.perf_counter()
    for i in range(n_corrupt):
        choice = i % 5
        if choice == 0:  # random bytes of random length
            bad = rng.bytes(int(rng.integers(0, 2 * size)))
        elif choice == 1:  # random body behind a plausible header
            bad = header_prefix + rng.bytes(size - len(header_prefix))
        elif choice == 2:  # a few flipped bits of a fresh valid frame
            bad = _flip_bits(make(seq + 1), rng)
        elif choice == 3:  # truncated or extended
            fresh = make(seq + 1)
            cut = int(rng.integers(0, len(fresh)))
            bad = fresh[:cut] if rng.random() < 0.5 else fresh + rng.bytes(int(rng.integers(1, 9)))
        else:  # a valid frame replayed
            bad = valid
        assert dec.decode(bad) is None, (i, choice, bad.hex())
        seq += 1
        valid = make(seq)
        assert dec.decode(valid) is not None, (i, dec.last_reject)
    elapsed = time.perf_counter() - started
    c = dec.counters
    assert c.internal_error == 0
    assert c.accepted == n_corrupt + 1
    assert c.rejected == n_corrupt
    assert c.replayed == n_corrupt // 5
    assert c.bad_crc > 0 and c.short > 0 and c.bad_magic > 0 and c.bad_length > 0
    print(f'fuzz {kind.name}: {2 * n_corrupt} decodes in {elapsed:.2f} s; {c.as_dict()}')


# --------------------------------------------------------------------------------------------
# Calibration


def test_calibration_from_config_follows_the_formula() -> None:
    cfg = load_config()
    cal = Calibration.from_config(cfg)
    assert cal.n_joints == len(cfg.hand.joint_names)
    role = cfg.hand.joint_roles[0]
    c = cfg.device.calibration[role]
    raw = np.arange(N) * 1000 - 3000
    expected = (raw[0] - c.position_offset_counts) * c.position_scale_rad_per_count
    assert cal.position_si(raw)[0] == pytest.approx(expected)


def test_calibration_round_trips_and_offsets() -> None:
    cal = Calibration([1e-4, 2e-4, 1e-3], [100, -50, 0], [1e-5, 2e-5, 1e-3], [10, 0, -7])
    counts = np.array([100, 0, 2000])
    # (raw - offset) * scale computed by hand.
    np.testing.assert_allclose(cal.position_si(counts), [0.0, 50 * 2e-4, 2.0])
    np.testing.assert_allclose(cal.torque_si([10, 100, 3]), [0.0, 2e-3, 10e-3])
    np.testing.assert_allclose(cal.velocity_si([10, 10, 10]), [1e-3, 2e-3, 1e-2])
    angles = np.array([0.3, -1.2, 2.5])
    np.testing.assert_allclose(cal.position_si(cal.position_raw(angles)), angles, atol=1e-3)
    torques = np.array([0.12, -0.3, 0.0])
    np.testing.assert_allclose(cal.torque_si(cal.torque_raw(torques)), torques, atol=1e-3)
    assert cal.position_raw(angles).dtype == np.int64


def test_setpoints_per_mode() -> None:
    cal = Calibration([1e-4] * 3, [0] * 3, [1e-5] * 3, [0] * 3)
    raw = cal.setpoints_raw([T, P, H], [0.1, math.radians(15.0), float('nan')])
    assert raw.tolist() == [10000, round(math.radians(15.0) / 1e-4), 0]
    si = cal.setpoints_si([T, P, H], raw)
    assert si[0] == pytest.approx(0.1) and math.isnan(si[2])
    # IMPEDANCE: the setpoint is the equilibrium angle theta_0, in counts like POSITION
    raw = cal.setpoints_raw([IMP, T, H], [0.2618, 0.0, 0.0])
    assert raw.tolist() == [2618, 0, 0]
    assert cal.setpoints_si([IMP, T, H], raw)[0] == pytest.approx(0.2618)


def test_impedance_gains_in_fixed_point() -> None:
    cal = Calibration([1e-4] * 3, [0] * 3, [1e-5] * 3, [0] * 3, [1e-4, 1e-3, 1e-4],
                      [1e-6, 1e-6, 1e-5])
    k_raw, d_raw = cal.gains_raw([IMP, IMP, T], [10.0, 0.5, float('nan')],
                                 [0.2, 0.0, float('nan')])
    assert k_raw.tolist() == [100_000, 500, 0]  # 10 / 1e-4, 0.5 / 1e-3; not IMPEDANCE: 0
    assert d_raw.tolist() == [200_000, 0, 0]  # 0.2 / 1e-6
    k, d = cal.gains_si(k_raw, d_raw)
    assert k.tolist() == pytest.approx([10.0, 0.5, 0.0])
    assert d.tolist() == pytest.approx([0.2, 0.0, 0.0])
    with pytest.raises(DeviceParameterError, match='at least one raw unit'):
        cal.gains_raw([IMP, T, T], [-1.0, 0, 0], [0.0, 0, 0])
    with pytest.raises(DeviceParameterError, match='at least one raw unit'):
        cal.gains_raw([IMP, T, T], [1e-6, 0, 0], [0.0, 0, 0])
    with pytest.raises(DeviceParameterError, match='>= 0'):
        cal.gains_raw([IMP, T, T], [1.0, 0, 0], [-0.1, 0, 0])
    with pytest.raises(DeviceParameterError, match='finite'):
        cal.gains_raw([IMP, T, T], [float('inf'), 0, 0], [0.0, 0, 0])
    with pytest.raises(DeviceParameterError, match='int32'):
        cal.gains_raw([IMP, T, T], [1e6, 0, 0], [0.0, 0, 0])
    with pytest.raises(DeviceParameterError, match='positive'):
        Calibration([1e-4], [0], [1e-5], [0], [-1e-4], [1e-6])


def test_gain_calibration_comes_from_the_config() -> None:
    cfg = load_config()
    cal = Calibration.from_config(cfg)
    c = cfg.device.calibration['compliant']
    assert cal.stiffness_scale[0] == c.stiffness_scale_nm_per_rad_per_raw
    assert cal.damping_scale[0] == c.damping_scale_nms_per_rad_per_raw


def test_state_si_and_raw_round_trip_through_a_frame() -> None:
    cal = Calibration.from_config(load_config())
    q = np.linspace(-0.5, 1.5, N)
    qd = np.linspace(2.0, -2.0, N)
    tau = np.linspace(-0.3, 0.3, N)
    raw = cal.state_raw(q, qd, tau)
    frame = FrameDecoder(FrameKind.STATE, N).decode(encode_state(1, 0, *raw, [H] * N))
    assert isinstance(frame, StateFrame)
    q2, qd2, tau2 = cal.state_si(frame)
    # Quantisation: half a count, half a raw torque unit.
    np.testing.assert_allclose(q2, q, atol=0.5 * cal.position_scale.max() + 1e-15)
    np.testing.assert_allclose(qd2, qd, atol=0.5 * cal.position_scale.max() + 1e-15)
    np.testing.assert_allclose(tau2, tau, atol=0.5 * cal.torque_scale.max() + 1e-15)


def test_calibration_rejects_bad_values() -> None:
    with pytest.raises(DeviceParameterError, match='zero scale'):
        Calibration([0.0], [0], [1e-5], [0])
    cal = Calibration([1e-4], [0], [1e-5], [0])
    with pytest.raises(DeviceParameterError, match='non-finite'):
        cal.torque_raw([float('inf')])
    with pytest.raises(DeviceParameterError, match='int32'):
        cal.position_raw([1e6])
    with pytest.raises(DeviceParameterError, match='JointMode'):
        cal.setpoints_raw([7], [0.0])


# --------------------------------------------------------------------------------------------
# Watchdog


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_watchdog_starts_tripped_and_holds() -> None:
    wd = DeviceWatchdog(3, 0.04, clock=FakeClock())
    modes, setpoints, _k, _d, tripped = wd.output()
    assert tripped and modes.tolist() == [H, H, H] and setpoints.tolist() == [0, 0, 0]


def test_watchdog_zeroes_torque_holds_positions_until_fresh_command() -> None:
    clock = FakeClock()
    wd = DeviceWatchdog(3, 0.04, clock=clock)
    wd.feed([T, P, H], [500, 1234, 0])
    clock.now += 0.039
    modes, setpoints, _k, _d, tripped = wd.output()
    assert not tripped and modes.tolist() == [T, P, H] and setpoints.tolist() == [500, 1234, 0]
    clock.now += 0.002  # 41 ms without a command
    modes, setpoints, _k, _d, tripped = wd.output()
    assert tripped
    assert modes.tolist() == [T, H, H]  # torque joint stays in torque mode, at zero torque
    assert setpoints.tolist() == [0, 0, 0]
    assert wd.trips == 1
    clock.now += 10.0  # stays tripped however long
    assert wd.output().tripped and wd.trips == 1
    wd.feed_frame(CommandFrame(seq=2, ref_state_seq=1, modes=np.array([T, T, P]),
                               setpoints=np.array([-7, 8, 9])))
    modes, setpoints, _k, _d, tripped = wd.output()
    assert not tripped and modes.tolist() == [T, T, P] and setpoints.tolist() == [-7, 8, 9]
    clock.now += 0.05
    assert wd.output().tripped and wd.trips == 2


def test_watchdog_passes_gains_and_zeroes_impedance_torque_on_timeout() -> None:
    clock = FakeClock()
    wd = DeviceWatchdog(3, 0.04, clock=clock)
    wd.feed([IMP, P, T], [2618, 100, 5], [100_000, 0, 0], [200_000, 0, 0])
    out = wd.output()
    assert not out.tripped and out.modes.tolist() == [IMP, P, T]
    assert out.setpoints.tolist() == [2618, 100, 5]
    assert out.stiffness.tolist() == [100_000, 0, 0] and out.damping.tolist() == [200_000, 0, 0]
    clock.now += 0.05
    out = wd.output()
    assert out.tripped
    assert out.modes.tolist() == [T, H, T]  # IMPEDANCE joint: torque-controlled, zero torque
    assert out.setpoints.tolist() == [0, 0, 0]
    assert out.stiffness.tolist() == [0, 0, 0] and out.damping.tolist() == [0, 0, 0]
    with pytest.raises(DeviceParameterError, match='gains'):
        wd.feed([IMP, P, T], [0, 0, 0], [0, 0, 0], [0, 0, 0])
    with pytest.raises(DeviceParameterError, match='gains'):
        wd.feed([T, P, T], [0, 0, 0], [4, 0, 0], [0, 0, 0])


def test_watchdog_timeout_is_bounded_and_never_off() -> None:
    for bad in (0.0, -0.01, 0.2001, 1.0, float('inf'), float('nan')):
        with pytest.raises(DeviceParameterError, match='never be switched off'):
            DeviceWatchdog(3, bad)
    assert check_watchdog_timeout(0.2) == 0.2
    cfg = load_config()
    assert check_watchdog_timeout(cfg.device.watchdog_s) == cfg.device.watchdog_s


def test_watchdog_rejects_bad_feed() -> None:
    wd = DeviceWatchdog(3, clock=FakeClock())
    with pytest.raises(DeviceParameterError, match='JointMode'):
        wd.feed([T, 0, P], [0, 0, 0])
    with pytest.raises(DeviceParameterError, match='shape'):
        wd.feed([T, P], [0, 0])
    assert wd.output().tripped  # a rejected feed does not disarm the watchdog
