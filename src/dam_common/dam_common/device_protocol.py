"""The DAM hand device link: frame codec, frame decoder, calibration and the device watchdog.

The link is modelled on the UDP links of torque-controlled arms (KUKA FRI, libfranka): the
device sends a *state frame* every cycle, the driver answers with a *command frame* computed
from the newest state. Both are small fixed-layout binary datagrams, little-endian, ending in a
CRC-32. ``docs/device_protocol.md`` is the normative description; this module implements it.

Everything here is pure Python (numpy, ``struct``, ``zlib``): no rclpy, no sockets.

Units on the wire are raw device units (encoder counts, counts per second, raw torque-sensor
units, fixed-point impedance gains). :class:`Calibration` converts them to SI with
``si = (raw - offset) * scale`` per joint role (gains: ``si = raw * scale``), from
``device.calibration`` of ``config/dam.yaml``.

Protocol version 2 added the joint mode IMPEDANCE: the device itself runs the compliant-joint
law ``tau = clip(k (theta_0 - theta) - d theta_dot, +-torque limit)`` at its physics rate, and
command frames carry a stiffness ``k`` and a damping ``d`` per joint besides the setpoint
(``theta_0`` for IMPEDANCE).
"""

from __future__ import annotations

import enum
import math
import struct
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from dam_common.errors import DeviceParameterError, EncodeError

if TYPE_CHECKING:
    from dam_common.config import DamConfig

# --------------------------------------------------------------------------------------------
# Constants and enums

#: First four bytes of every frame.
MAGIC: bytes = b'DAMH'
#: Protocol version this module speaks.
PROTOCOL_VERSION: int = 2
#: Longest watchdog timeout the device accepts [s]; the watchdog can never be switched off.
WATCHDOG_MAX_S: float = 0.2
#: Default watchdog timeout [s].
WATCHDOG_DEFAULT_S: float = 0.040
#: Stiffness of one raw unit when a :class:`Calibration` is built without one [N*m/rad].
STIFFNESS_SCALE_DEFAULT: float = 1.0e-4
#: Damping of one raw unit when a :class:`Calibration` is built without one [N*m*s/rad].
DAMPING_SCALE_DEFAULT: float = 1.0e-6

_INT32_MIN = -(2**31)
_INT32_MAX = 2**31 - 1
_SEQ_MOD = 2**32


class FrameKind(enum.IntEnum):
    """The ``kind`` byte of the header."""

    STATE = 1  #: device -> driver
    COMMAND = 2  #: driver -> device


class JointMode(enum.IntEnum):
    """Control mode of one joint (command frames request it, state frames report it).

    ``0`` is deliberately not a mode, so that an all-zero payload is never a valid command.
    """

    TORQUE = 1  #: setpoint is a joint torque [raw torque units]
    POSITION = 2  #: setpoint is a joint position [encoder counts]; the device servoes
    HOLD = 3  #: the device servoes the position it had when it entered HOLD; setpoint ignored
    #: setpoint is the equilibrium theta_0 [encoder counts]; the device applies
    #: ``clip(k (theta_0 - theta) - d theta_dot, +-torque limit)`` every physics step with the
    #: frame's stiffness k and damping d
    IMPEDANCE = 4


class JointFault(enum.IntFlag):
    """Per-joint fault bits of a state frame."""

    NONE = 0
    WATCHDOG = 1  #: the joint is in its watchdog safe state (torque zero or holding)
    LIMIT = 2  #: the joint is at a joint limit
    SATURATED = 4  #: the commanded torque was clipped to the device's torque limit
    SENSOR = 8  #: the encoder or the torque sensor reports an error


class DeviceStatus(enum.IntFlag):
    """Device-wide status bits of a state frame."""

    NONE = 0
    WATCHDOG_TRIPPED = 1  #: no valid command for the watchdog timeout
    SIMULATED = 2  #: the device is the simulated stand-in


_VALID_MODES = frozenset(int(m) for m in JointMode)

# Layouts (little-endian, no padding). See docs/device_protocol.md.
_HEADER = struct.Struct('<4sBBHI')  # magic, version, kind, length, seq
_STATE_BODY = struct.Struct('<QHH')  # timestamp_ns, n_joints, status
_STATE_JOINT = '<iiiHH'  # position, velocity, torque, mode, faults (per joint)
_COMMAND_BODY = struct.Struct('<IH')  # ref_state_seq, n_joints
_COMMAND_JOINT = '<Hiii'  # mode, setpoint, stiffness, damping (per joint)
_CRC = struct.Struct('<I')

HEADER_SIZE: int = _HEADER.size  # 12 bytes
CRC_SIZE: int = _CRC.size  # 4 bytes
STATE_JOINT_SIZE: int = struct.calcsize(_STATE_JOINT)  # 16 bytes
COMMAND_JOINT_SIZE: int = struct.calcsize(_COMMAND_JOINT)  # 14 bytes
MAX_JOINTS: int = 64


def state_frame_size(n_joints: int) -> int:
    """Length in bytes of a state frame with ``n_joints`` joints (``28 + 16 n``)."""
    return HEADER_SIZE + _STATE_BODY.size + STATE_JOINT_SIZE * n_joints + CRC_SIZE


def command_frame_size(n_joints: int) -> int:
    """Length in bytes of a command frame with ``n_joints`` joints (``22 + 14 n``)."""
    return HEADER_SIZE + _COMMAND_BODY.size + COMMAND_JOINT_SIZE * n_joints + CRC_SIZE


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32 of the frame checksum (``zlib.crc32``: CRC-32/ISO-HDLC, as in Ethernet, zip).

    Polynomial 0x04C11DB7 (reflected 0xEDB88320), initial value and final XOR 0xFFFFFFFF;
    ``crc32(b'123456789') == 0xCBF43926``.
    """
    return zlib.crc32(data) & 0xFFFFFFFF


# --------------------------------------------------------------------------------------------
# Sequence numbers


def seq_next(seq: int) -> int:
    """The sequence number after ``seq`` (32 bit, wraps from 2**32 - 1 to 0)."""
    return (seq + 1) % _SEQ_MOD


def seq_newer(seq: int, than: int) -> bool:
    """Whether ``seq`` is newer than ``than`` in 32-bit serial-number arithmetic (RFC 1982).

    ``seq`` is newer when ``0 < (seq - than) mod 2**32 < 2**31``: the counter may wrap, and a
    number more than 2**31 ahead is treated as old.
    """
    diff = (seq - than) % _SEQ_MOD
    return 0 < diff < 2**31


# --------------------------------------------------------------------------------------------
# Frames


@dataclass(frozen=True)
class StateFrame:
    """A decoded state frame (device -> driver), raw device units.

    Attributes
    ----------
    seq
        Sequence number of the device, 32 bit, +1 per frame sent.
    timestamp_ns
        Device clock when the state was sampled [ns], monotonic, arbitrary origin.
    position_counts, velocity_counts_per_s, torque_raw
        (n,) int64: encoder position [counts], velocity [counts/s], torque sensor [raw units].
    modes
        (n,) int64: the :class:`JointMode` each joint is in now.
    faults
        (n,) int64: :class:`JointFault` bits per joint.
    status
        :class:`DeviceStatus` bits.
    """

    seq: int
    timestamp_ns: int
    position_counts: np.ndarray
    velocity_counts_per_s: np.ndarray
    torque_raw: np.ndarray
    modes: np.ndarray
    faults: np.ndarray
    status: int = 0

    @property
    def n_joints(self) -> int:
        return int(self.position_counts.shape[0])


@dataclass(frozen=True)
class CommandFrame:
    """A decoded command frame (driver -> device), raw device units.

    Attributes
    ----------
    seq
        Sequence number of the driver, 32 bit, +1 per frame sent.
    ref_state_seq
        Sequence number of the newest state frame the command was computed from.
    modes
        (n,) int64: requested :class:`JointMode` per joint.
    setpoints
        (n,) int64: torque [raw units] for TORQUE, position [counts] for POSITION, the
        equilibrium theta_0 [counts] for IMPEDANCE, ignored (0) for HOLD.
    stiffness, damping
        (n,) int64: impedance stiffness and damping [raw gain units], positive and
        non-negative for IMPEDANCE joints, 0 for every other joint. ``None`` (the default
        when constructed by hand) means zeros.
    """

    seq: int
    ref_state_seq: int
    modes: np.ndarray
    setpoints: np.ndarray
    stiffness: np.ndarray | None = None
    damping: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ('stiffness', 'damping'):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(np.shape(self.modes), dtype=np.int64))

    @property
    def n_joints(self) -> int:
        return int(self.modes.shape[0])


def _int_array(name: str, values: Sequence[int] | np.ndarray, n: int,
               lo: int, hi: int) -> list[int]:
    arr = np.asarray(values)
    if arr.shape != (n,):
        raise EncodeError(f'{name}: expected shape ({n},), got {arr.shape}')
    if arr.dtype.kind == 'f':
        if not np.all(np.isfinite(arr)):
            raise EncodeError(f'{name}: non-finite value in {arr.tolist()!r}')
        if not np.all(arr == np.round(arr)):
            raise EncodeError(f'{name}: expected integers (raw device units), got '
                              f'{arr.tolist()!r}')
    elif arr.dtype.kind not in 'iub':
        raise EncodeError(f'{name}: expected integers, got dtype {arr.dtype}')
    out = [int(v) for v in arr.tolist()]
    for i, v in enumerate(out):
        if not lo <= v <= hi:
            raise EncodeError(f'{name}[{i}] = {v} is outside [{lo}, {hi}]')
    return out


def _check_header_ints(seq: int, n_joints: int) -> None:
    if not 0 <= int(seq) < _SEQ_MOD:
        raise EncodeError(f'sequence number {seq!r} is outside [0, 2**32)')
    if not 1 <= n_joints <= MAX_JOINTS:
        raise EncodeError(f'joint count {n_joints} is outside [1, {MAX_JOINTS}]')


def _check_modes(modes: list[int]) -> None:
    for i, m in enumerate(modes):
        if m not in _VALID_MODES:
            raise EncodeError(f'modes[{i}] = {m} is not a JointMode '
                              f'({sorted(_VALID_MODES)})')


def _check_gains(modes: list[int], stiffness: list[int], damping: list[int]) -> None:
    """IMPEDANCE joints: stiffness > 0, damping >= 0; every other joint: both 0."""
    for i, (m, k, d) in enumerate(zip(modes, stiffness, damping, strict=True)):
        if m == JointMode.IMPEDANCE:
            if k <= 0:
                raise EncodeError(f'stiffness[{i}] = {k} of an IMPEDANCE joint must be positive')
            if d < 0:
                raise EncodeError(f'damping[{i}] = {d} of an IMPEDANCE joint must be >= 0')
        elif k != 0 or d != 0:
            raise EncodeError(f'joint {i} in mode {m}: stiffness {k} and damping {d} must be 0 '
                              f'outside IMPEDANCE')


def encode_state(seq: int, timestamp_ns: int,
                 position_counts: Sequence[int] | np.ndarray,
                 velocity_counts_per_s: Sequence[int] | np.ndarray,
                 torque_raw: Sequence[int] | np.ndarray,
                 modes: Sequence[int] | np.ndarray,
                 faults: Sequence[int] | np.ndarray | None = None,
                 status: int = 0) -> bytes:
    """Encode a state frame.

    Parameters
    ----------
    seq
        Device sequence number, ``0 <= seq < 2**32``.
    timestamp_ns
        Device clock [ns], ``0 <= timestamp_ns < 2**64``.
    position_counts, velocity_counts_per_s, torque_raw
        (n,) integers in the int32 range [counts], [counts/s], [raw torque units].
    modes
        (n,) :class:`JointMode` values.
    faults
        (n,) :class:`JointFault` bits (0..65535); ``None`` means no faults.
    status
        :class:`DeviceStatus` bits (0..65535).

    Returns
    -------
    bytes
        The datagram, ``state_frame_size(n)`` bytes.

    Raises
    ------
    EncodeError
        A value is out of its field's range or the arrays differ in length.
    """
    n = int(np.asarray(position_counts).shape[0]) if np.ndim(position_counts) == 1 else -1
    if n < 0:
        raise EncodeError(f'position_counts must be a 1-D array, got {position_counts!r}')
    _check_header_ints(seq, n)
    if not 0 <= int(timestamp_ns) < 2**64:
        raise EncodeError(f'timestamp_ns {timestamp_ns!r} is outside [0, 2**64)')
    if not 0 <= int(status) <= 0xFFFF:
        raise EncodeError(f'status {status!r} is outside [0, 65535]')
    pos = _int_array('position_counts', position_counts, n, _INT32_MIN, _INT32_MAX)
    vel = _int_array('velocity_counts_per_s', velocity_counts_per_s, n, _INT32_MIN, _INT32_MAX)
    tor = _int_array('torque_raw', torque_raw, n, _INT32_MIN, _INT32_MAX)
    mod = _int_array('modes', modes, n, 0, 0xFFFF)
    _check_modes(mod)
    flt = [0] * n if faults is None else _int_array('faults', faults, n, 0, 0xFFFF)
    length = state_frame_size(n)
    buf = bytearray(length)
    _HEADER.pack_into(buf, 0, MAGIC, PROTOCOL_VERSION, FrameKind.STATE, length, int(seq))
    _STATE_BODY.pack_into(buf, HEADER_SIZE, int(timestamp_ns), n, int(status))
    joints = [v for j in range(n) for v in (pos[j], vel[j], tor[j], mod[j], flt[j])]
    struct.pack_into('<' + _STATE_JOINT[1:] * n, buf, HEADER_SIZE + _STATE_BODY.size, *joints)
    _CRC.pack_into(buf, length - CRC_SIZE, crc32(memoryview(buf)[:length - CRC_SIZE]))
    return bytes(buf)


def encode_command(seq: int, ref_state_seq: int, modes: Sequence[int] | np.ndarray,
                   setpoints: Sequence[int] | np.ndarray,
                   stiffness: Sequence[int] | np.ndarray | None = None,
                   damping: Sequence[int] | np.ndarray | None = None) -> bytes:
    """Encode a command frame.

    Parameters
    ----------
    seq
        Driver sequence number, ``0 <= seq < 2**32``.
    ref_state_seq
        Sequence number of the state frame the command was computed from.
    modes
        (n,) :class:`JointMode` values.
    setpoints
        (n,) integers in the int32 range: raw torque units (TORQUE), encoder counts
        (POSITION; the equilibrium theta_0 for IMPEDANCE), 0 (HOLD; ignored by the device).
    stiffness, damping
        (n,) raw impedance gains in the int32 range: stiffness positive and damping
        non-negative for IMPEDANCE joints, 0 for every other joint; ``None``: all zero.

    Returns
    -------
    bytes
        The datagram, ``command_frame_size(n)`` bytes.

    Raises
    ------
    EncodeError
        A value is out of its field's range, the arrays differ in length, or the gains break
        the rule above (the device's decoder would drop the frame as ``bad_value``).
    """
    if np.ndim(modes) != 1:
        raise EncodeError(f'modes must be a 1-D array, got {modes!r}')
    n = int(np.asarray(modes).shape[0])
    _check_header_ints(seq, n)
    if not 0 <= int(ref_state_seq) < _SEQ_MOD:
        raise EncodeError(f'ref_state_seq {ref_state_seq!r} is outside [0, 2**32)')
    mod = _int_array('modes', modes, n, 0, 0xFFFF)
    _check_modes(mod)
    spt = _int_array('setpoints', setpoints, n, _INT32_MIN, _INT32_MAX)
    stf = [0] * n if stiffness is None else _int_array('stiffness', stiffness, n, _INT32_MIN,
                                                        _INT32_MAX)
    dmp = [0] * n if damping is None else _int_array('damping', damping, n, _INT32_MIN,
                                                      _INT32_MAX)
    _check_gains(mod, stf, dmp)
    length = command_frame_size(n)
    buf = bytearray(length)
    _HEADER.pack_into(buf, 0, MAGIC, PROTOCOL_VERSION, FrameKind.COMMAND, length, int(seq))
    _COMMAND_BODY.pack_into(buf, HEADER_SIZE, int(ref_state_seq), n)
    joints = [v for j in range(n) for v in (mod[j], spt[j], stf[j], dmp[j])]
    struct.pack_into('<' + _COMMAND_JOINT[1:] * n, buf, HEADER_SIZE + _COMMAND_BODY.size,
                     *joints)
    _CRC.pack_into(buf, length - CRC_SIZE, crc32(memoryview(buf)[:length - CRC_SIZE]))
    return bytes(buf)


# --------------------------------------------------------------------------------------------
# Decoding


@dataclass
class RejectCounters:
    """How many frames a :class:`FrameDecoder` accepted, and why it rejected the others.

    The checks run in the order of the fields below; a frame is counted under the first check
    it fails.
    """

    accepted: int = 0
    short: int = 0  #: fewer bytes than a header and a CRC
    bad_magic: int = 0  #: first four bytes are not ``MAGIC``
    bad_version: int = 0  #: unknown protocol version
    bad_kind: int = 0  #: a command frame where a state frame was expected, or vice versa
    bad_length: int = 0  #: the length field differs from the datagram's size
    bad_crc: int = 0  #: checksum mismatch
    bad_joint_count: int = 0  #: joint count differs from the expected one, or from the length
    bad_value: int = 0  #: a mode that is not a JointMode, or impedance gains against the rules
    replayed: int = 0  #: sequence number equal to the newest accepted one
    stale: int = 0  #: sequence number older than the newest accepted one
    internal_error: int = 0  #: an unexpected exception inside the decoder (a bug; never raised)

    @property
    def rejected(self) -> int:
        """Total number of rejected frames."""
        return sum(getattr(self, f.name) for f in fields(self) if f.name != 'accepted')

    def as_dict(self) -> dict[str, int]:
        """All counters by name (for diagnostics)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class FrameDecoder:
    """Validates and decodes datagrams of one kind; never raises into the control loop.

    Each call to :meth:`decode` returns the decoded frame, or ``None`` when the datagram is
    rejected; :attr:`counters` says why. A frame is accepted only when its sequence number is
    newer (serial-number arithmetic, :func:`seq_newer`) than the newest accepted one, so stale,
    reordered and replayed datagrams are dropped. :meth:`reset` forgets the newest sequence
    number (after a reconnect, when the peer restarted its counter).

    Parameters
    ----------
    kind
        :attr:`FrameKind.STATE` (the driver's decoder) or :attr:`FrameKind.COMMAND` (the
        device's decoder).
    n_joints
        Number of joints every frame must carry.
    """

    def __init__(self, kind: FrameKind, n_joints: int) -> None:
        if not 1 <= int(n_joints) <= MAX_JOINTS:
            raise DeviceParameterError(f'n_joints {n_joints!r} is outside [1, {MAX_JOINTS}]')
        self.kind = FrameKind(kind)
        self.n_joints = int(n_joints)
        self.counters = RejectCounters()
        self.last_reject: str | None = None
        self._newest_seq: int | None = None
        if self.kind is FrameKind.STATE:
            self._size = state_frame_size(self.n_joints)
            self._joints = struct.Struct('<' + _STATE_JOINT[1:] * self.n_joints)
            self._body = _STATE_BODY
        else:
            self._size = command_frame_size(self.n_joints)
            self._joints = struct.Struct('<' + _COMMAND_JOINT[1:] * self.n_joints)
            self._body = _COMMAND_BODY

    @property
    def newest_seq(self) -> int | None:
        """Sequence number of the newest accepted frame (``None`` before the first)."""
        return self._newest_seq

    def reset(self) -> None:
        """Accept any sequence number next (the counters are kept)."""
        self._newest_seq = None

    def decode(self, data: bytes | bytearray | memoryview) -> StateFrame | CommandFrame | None:
        """Validate a datagram and decode it.

        Parameters
        ----------
        data
            The received datagram.

        Returns
        -------
        StateFrame | CommandFrame | None
            The frame, or ``None`` if it was rejected (see :attr:`counters`,
            :attr:`last_reject`).
        """
        try:
            reason, frame = self._decode(data)
        except Exception:  # noqa: BLE001 - the decoder must never raise into the loop
            reason, frame = 'internal_error', None
        if frame is None:
            setattr(self.counters, reason, getattr(self.counters, reason) + 1)
            self.last_reject = reason
            return None
        self.counters.accepted += 1
        self._newest_seq = frame.seq
        return frame

    def _decode(self, data: bytes | bytearray | memoryview
                ) -> tuple[str, StateFrame | CommandFrame | None]:
        buf = bytes(data)
        size = len(buf)
        if size < HEADER_SIZE + CRC_SIZE:
            return 'short', None
        magic, version, kind, length, seq = _HEADER.unpack_from(buf, 0)
        if magic != MAGIC:
            return 'bad_magic', None
        if version != PROTOCOL_VERSION:
            return 'bad_version', None
        if kind != self.kind:
            return 'bad_kind', None
        if length != size:
            return 'bad_length', None
        (crc,) = _CRC.unpack_from(buf, size - CRC_SIZE)
        if crc != crc32(buf[:size - CRC_SIZE]):
            return 'bad_crc', None
        if size != self._size or size < HEADER_SIZE + self._body.size + CRC_SIZE:
            return 'bad_joint_count', None
        body = self._body.unpack_from(buf, HEADER_SIZE)
        if body[1] != self.n_joints:
            return 'bad_joint_count', None
        values = np.asarray(
            self._joints.unpack_from(buf, HEADER_SIZE + self._body.size), dtype=np.int64)
        if self.kind is FrameKind.STATE:
            table = values.reshape(self.n_joints, 5)
            modes = table[:, 3]
        else:
            table = values.reshape(self.n_joints, 4)
            modes = table[:, 0]
        if not np.all((modes >= min(_VALID_MODES)) & (modes <= max(_VALID_MODES))):
            return 'bad_value', None
        if self.kind is FrameKind.COMMAND:
            impedance = modes == int(JointMode.IMPEDANCE)
            k, d = table[:, 2], table[:, 3]
            if np.any(np.where(impedance, (k <= 0) | (d < 0), (k != 0) | (d != 0))):
                return 'bad_value', None
        if self._newest_seq is not None:
            if seq == self._newest_seq:
                return 'replayed', None
            if not seq_newer(seq, self._newest_seq):
                return 'stale', None
        if self.kind is FrameKind.STATE:
            frame: StateFrame | CommandFrame = StateFrame(
                seq=seq, timestamp_ns=body[0], position_counts=table[:, 0].copy(),
                velocity_counts_per_s=table[:, 1].copy(), torque_raw=table[:, 2].copy(),
                modes=modes.copy(), faults=table[:, 4].copy(), status=body[2])
        else:
            frame = CommandFrame(seq=seq, ref_state_seq=body[0], modes=modes.copy(),
                                 setpoints=table[:, 1].copy(), stiffness=table[:, 2].copy(),
                                 damping=table[:, 3].copy())
        return 'accepted', frame


# --------------------------------------------------------------------------------------------
# Calibration


class Calibration:
    """Raw device units <-> SI for every joint, in ``HandConfig.joint_names`` order.

    ``si = (raw - offset) * scale`` with the per-role scale and offset of
    ``device.calibration``; velocities use the position scale without offset
    (``rad/s = counts/s * scale``). The impedance gains of a command frame are unsigned
    fixed-point numbers without offset: ``k [N*m/rad] = stiffness_raw * stiffness_scale``,
    ``d [N*m*s/rad] = damping_raw * damping_scale``.

    Parameters
    ----------
    position_scale_rad_per_count, position_offset_counts, torque_scale_nm_per_raw, \
torque_offset_raw
        (n,) per joint.
    stiffness_scale_nm_per_rad_per_raw, damping_scale_nms_per_rad_per_raw
        (n,) per joint, positive; ``None``: :data:`STIFFNESS_SCALE_DEFAULT` and
        :data:`DAMPING_SCALE_DEFAULT` for every joint.
    """

    def __init__(self, position_scale_rad_per_count: Sequence[float] | np.ndarray,
                 position_offset_counts: Sequence[float] | np.ndarray,
                 torque_scale_nm_per_raw: Sequence[float] | np.ndarray,
                 torque_offset_raw: Sequence[float] | np.ndarray,
                 stiffness_scale_nm_per_rad_per_raw: Sequence[float] | np.ndarray | None = None,
                 damping_scale_nms_per_rad_per_raw: Sequence[float] | np.ndarray | None = None
                 ) -> None:
        n_in = int(np.size(position_scale_rad_per_count))
        arrays = {
            'position_scale_rad_per_count': position_scale_rad_per_count,
            'position_offset_counts': position_offset_counts,
            'torque_scale_nm_per_raw': torque_scale_nm_per_raw,
            'torque_offset_raw': torque_offset_raw,
            'stiffness_scale_nm_per_rad_per_raw': (
                [STIFFNESS_SCALE_DEFAULT] * n_in if stiffness_scale_nm_per_rad_per_raw is None
                else stiffness_scale_nm_per_rad_per_raw),
            'damping_scale_nms_per_rad_per_raw': (
                [DAMPING_SCALE_DEFAULT] * n_in if damping_scale_nms_per_rad_per_raw is None
                else damping_scale_nms_per_rad_per_raw),
        }
        checked: dict[str, np.ndarray] = {}
        n = None
        for name, values in arrays.items():
            arr = np.asarray(values, dtype=np.float64)
            if arr.ndim != 1 or arr.size == 0:
                raise DeviceParameterError(f'{name} must be a non-empty 1-D array, got {values!r}')
            if n is not None and arr.size != n:
                raise DeviceParameterError(f'{name} has {arr.size} joints, expected {n}')
            n = arr.size
            if not np.all(np.isfinite(arr)):
                raise DeviceParameterError(f'{name} has a non-finite value: {arr.tolist()!r}')
            if name.endswith(('_per_count', '_per_raw')) and np.any(arr == 0.0):
                raise DeviceParameterError(f'{name} has a zero scale: {arr.tolist()!r}')
            if name.startswith(('stiffness', 'damping')) and np.any(arr <= 0.0):
                raise DeviceParameterError(f'{name} must be positive: {arr.tolist()!r}')
            checked[name] = arr
        self.position_scale = checked['position_scale_rad_per_count']
        self.position_offset = checked['position_offset_counts']
        self.torque_scale = checked['torque_scale_nm_per_raw']
        self.torque_offset = checked['torque_offset_raw']
        self.stiffness_scale = checked['stiffness_scale_nm_per_rad_per_raw']
        self.damping_scale = checked['damping_scale_nms_per_rad_per_raw']

    @classmethod
    def from_config(cls, config: DamConfig) -> Calibration:
        """Build from a ``DamConfig`` (its ``hand`` joint order and ``device.calibration``)."""
        hand = config.hand
        cal = config.device.calibration
        roles = [role for _ in hand.fingers for role in hand.joint_roles]
        return cls([cal[r].position_scale_rad_per_count for r in roles],
                   [cal[r].position_offset_counts for r in roles],
                   [cal[r].torque_scale_nm_per_raw for r in roles],
                   [cal[r].torque_offset_raw for r in roles],
                   [cal[r].stiffness_scale_nm_per_rad_per_raw for r in roles],
                   [cal[r].damping_scale_nms_per_rad_per_raw for r in roles])

    @property
    def n_joints(self) -> int:
        return int(self.position_scale.size)

    def position_si(self, counts: np.ndarray | Sequence[float]) -> np.ndarray:
        """Encoder counts -> joint angles [rad]."""
        return (np.asarray(counts, dtype=np.float64) - self.position_offset) * self.position_scale

    def velocity_si(self, counts_per_s: np.ndarray | Sequence[float]) -> np.ndarray:
        """Encoder velocity [counts/s] -> joint velocities [rad/s]."""
        return np.asarray(counts_per_s, dtype=np.float64) * self.position_scale

    def torque_si(self, raw: np.ndarray | Sequence[float]) -> np.ndarray:
        """Torque-sensor readings [raw units] -> joint torques [N*m]."""
        return (np.asarray(raw, dtype=np.float64) - self.torque_offset) * self.torque_scale

    def position_raw(self, rad: np.ndarray | Sequence[float]) -> np.ndarray:
        """Joint angles [rad] -> encoder counts (int64, rounded to the nearest count)."""
        return self._to_raw('position', rad, self.position_scale, self.position_offset)

    def velocity_raw(self, rad_per_s: np.ndarray | Sequence[float]) -> np.ndarray:
        """Joint velocities [rad/s] -> encoder velocity [counts/s] (int64, rounded)."""
        return self._to_raw('velocity', rad_per_s, self.position_scale, 0.0)

    def torque_raw(self, nm: np.ndarray | Sequence[float]) -> np.ndarray:
        """Joint torques [N*m] -> torque units of the device (int64, rounded)."""
        return self._to_raw('torque', nm, self.torque_scale, self.torque_offset)

    def state_si(self, frame: StateFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A state frame's joint positions [rad], velocities [rad/s] and torques [N*m]."""
        return (self.position_si(frame.position_counts),
                self.velocity_si(frame.velocity_counts_per_s), self.torque_si(frame.torque_raw))

    def state_raw(self, positions_rad: np.ndarray | Sequence[float],
                  velocities_rad_per_s: np.ndarray | Sequence[float],
                  torques_nm: np.ndarray | Sequence[float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """SI joint state -> raw (counts, counts/s, torque units) for :func:`encode_state`."""
        return (self.position_raw(positions_rad), self.velocity_raw(velocities_rad_per_s),
                self.torque_raw(torques_nm))

    def setpoints_raw(self, modes: np.ndarray | Sequence[int],
                      setpoints_si: np.ndarray | Sequence[float]) -> np.ndarray:
        """SI setpoints -> raw setpoints of a command frame, per joint mode.

        TORQUE: N*m -> raw torque units; POSITION and IMPEDANCE (theta_0): rad -> counts;
        HOLD: 0 (the value is ignored and may be NaN).
        """
        m = np.asarray(modes, dtype=np.int64)
        sp = np.asarray(setpoints_si, dtype=np.float64)
        if m.shape != (self.n_joints,) or sp.shape != (self.n_joints,):
            raise DeviceParameterError(f'modes {m.shape} and setpoints {sp.shape} must both have '
                                       f'shape ({self.n_joints},)')
        out = np.zeros(self.n_joints, dtype=np.int64)
        torque = m == JointMode.TORQUE
        position = (m == JointMode.POSITION) | (m == JointMode.IMPEDANCE)
        bad = ~(torque | position | (m == JointMode.HOLD))
        if np.any(bad):
            raise DeviceParameterError(f'modes {m.tolist()!r} contain a value that is not a '
                                       'JointMode')
        if np.any(torque):
            out[torque] = self.torque_raw(np.where(torque, sp, 0.0))[torque]
        if np.any(position):
            out[position] = self.position_raw(np.where(position, sp, 0.0))[position]
        return out

    def setpoints_si(self, modes: np.ndarray | Sequence[int],
                     setpoints_raw: np.ndarray | Sequence[int]) -> np.ndarray:
        """Raw setpoints of a command frame -> SI (N*m; rad for POSITION and IMPEDANCE; NaN
        for HOLD)."""
        m = np.asarray(modes, dtype=np.int64)
        sp = np.asarray(setpoints_raw, dtype=np.float64)
        angle = (m == JointMode.POSITION) | (m == JointMode.IMPEDANCE)
        return np.where(m == JointMode.TORQUE, self.torque_si(sp),
                        np.where(angle, self.position_si(sp), np.nan))

    def gains_raw(self, modes: np.ndarray | Sequence[int],
                  stiffness_nm_per_rad: np.ndarray | Sequence[float],
                  damping_nms_per_rad: np.ndarray | Sequence[float]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """SI impedance gains -> raw gains of a command frame (int64, rounded).

        Joints not in IMPEDANCE get 0 whatever their value (NaN allowed there).

        Parameters
        ----------
        modes
            (n,) :class:`JointMode` per joint.
        stiffness_nm_per_rad, damping_nms_per_rad
            (n,) stiffness k [N*m/rad] and damping d [N*m*s/rad].

        Raises
        ------
        DeviceParameterError
            Wrong shape, or an IMPEDANCE joint whose stiffness is not finite or rounds to
            less than one raw unit, whose damping is negative or not finite, or whose gain
            does not fit the int32 field.
        """
        m = np.asarray(modes, dtype=np.int64)
        k = np.asarray(stiffness_nm_per_rad, dtype=np.float64)
        d = np.asarray(damping_nms_per_rad, dtype=np.float64)
        if m.shape != (self.n_joints,) or k.shape != m.shape or d.shape != m.shape:
            raise DeviceParameterError(f'modes {m.shape}, stiffness {k.shape} and damping '
                                       f'{d.shape} must all have shape ({self.n_joints},)')
        imp = m == JointMode.IMPEDANCE
        k_raw = np.zeros(self.n_joints, dtype=np.int64)
        d_raw = np.zeros(self.n_joints, dtype=np.int64)
        if not np.any(imp):
            return k_raw, d_raw
        if not (np.all(np.isfinite(k[imp])) and np.all(np.isfinite(d[imp]))):
            raise DeviceParameterError(f'impedance gains must be finite: stiffness {k.tolist()!r}, '
                                       f'damping {d.tolist()!r}')
        kr = np.rint(np.where(imp, k, 0.0) / self.stiffness_scale)
        dr = np.rint(np.where(imp, d, 0.0) / self.damping_scale)
        if np.any(kr[imp] < 1):
            raise DeviceParameterError(f'stiffness {k.tolist()!r} N*m/rad: an IMPEDANCE joint '
                                       'needs at least one raw unit '
                                       f'({self.stiffness_scale.tolist()!r})')
        if np.any(dr[imp] < 0):
            raise DeviceParameterError(f'damping {d.tolist()!r} N*m*s/rad must be >= 0')
        if np.any(kr > _INT32_MAX) or np.any(dr > _INT32_MAX):
            raise DeviceParameterError(f'stiffness {k.tolist()!r} or damping {d.tolist()!r} does '
                                       f'not fit the int32 raw field')
        k_raw[imp] = kr[imp].astype(np.int64)
        d_raw[imp] = dr[imp].astype(np.int64)
        return k_raw, d_raw

    def gains_si(self, stiffness_raw: np.ndarray | Sequence[int],
                 damping_raw: np.ndarray | Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
        """Raw gains of a command frame -> stiffness [N*m/rad] and damping [N*m*s/rad]."""
        return (np.asarray(stiffness_raw, dtype=np.float64) * self.stiffness_scale,
                np.asarray(damping_raw, dtype=np.float64) * self.damping_scale)

    def _to_raw(self, what: str, si: np.ndarray | Sequence[float], scale: np.ndarray,
                offset: np.ndarray | float) -> np.ndarray:
        arr = np.asarray(si, dtype=np.float64)
        if arr.shape != (self.n_joints,):
            raise DeviceParameterError(f'{what}: expected shape ({self.n_joints},), got '
                                       f'{arr.shape}')
        if not np.all(np.isfinite(arr)):
            raise DeviceParameterError(f'{what}: non-finite value in {arr.tolist()!r}')
        raw = np.rint(arr / scale + offset)
        if np.any(raw < _INT32_MIN) or np.any(raw > _INT32_MAX):
            raise DeviceParameterError(f'{what}: {arr.tolist()!r} does not fit the int32 raw field')
        return raw.astype(np.int64)


# --------------------------------------------------------------------------------------------
# Device-side watchdog


def check_watchdog_timeout(timeout_s: float) -> float:
    """Validate a watchdog timeout: finite, ``0 < timeout_s <= WATCHDOG_MAX_S`` [s].

    Raises
    ------
    DeviceParameterError
        Zero, negative, infinite or NaN (the watchdog can never be off) or above 0.2 s.
    """
    t = float(timeout_s)
    if not math.isfinite(t) or t <= 0.0 or t > WATCHDOG_MAX_S:
        raise DeviceParameterError(f'watchdog timeout {timeout_s!r} s is outside (0, '
                                   f'{WATCHDOG_MAX_S}] s (it can never be switched off)')
    return t


class DeviceOutput(NamedTuple):
    """What the device applies now (:meth:`DeviceWatchdog.output`), raw units."""

    modes: np.ndarray  #: (n,) int64 :class:`JointMode` values
    setpoints: np.ndarray  #: (n,) int64 raw setpoints (0 for HOLD)
    stiffness: np.ndarray  #: (n,) int64 raw stiffness (0 outside IMPEDANCE)
    damping: np.ndarray  #: (n,) int64 raw damping (0 outside IMPEDANCE)
    tripped: bool  #: the watchdog is tripped (safe state)


class DeviceWatchdog:
    """What the device does with the commands it receives (pure logic, injected clock).

    While valid commands keep arriving, :meth:`output` is the newest command. When no valid
    command has arrived for ``timeout_s`` (or none ever did), the watchdog is *tripped* and
    :meth:`output` is the safe state: joints whose last command was TORQUE or IMPEDANCE get
    zero torque (in TORQUE mode: a device-side impedance is a torque-controlled joint), every
    other joint HOLDs its position. It stays tripped until the next command is fed.

    Parameters
    ----------
    n_joints
        Number of joints.
    timeout_s
        Watchdog timeout [s], ``0 < timeout_s <= 0.2`` (default 0.040).
    clock
        Monotonic clock [s] (``time.monotonic`` by default; tests inject a fake one).
    """

    def __init__(self, n_joints: int, timeout_s: float = WATCHDOG_DEFAULT_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not 1 <= int(n_joints) <= MAX_JOINTS:
            raise DeviceParameterError(f'n_joints {n_joints!r} is outside [1, {MAX_JOINTS}]')
        self.n_joints = int(n_joints)
        self.timeout_s = check_watchdog_timeout(timeout_s)
        self._clock = clock
        self._last_feed_s: float | None = None
        self._modes = np.full(self.n_joints, int(JointMode.HOLD), dtype=np.int64)
        self._setpoints = np.zeros(self.n_joints, dtype=np.int64)
        self._stiffness = np.zeros(self.n_joints, dtype=np.int64)
        self._damping = np.zeros(self.n_joints, dtype=np.int64)
        self._was_tripped = True
        #: Number of times the watchdog went from running to tripped.
        self.trips = 0

    def feed(self, modes: np.ndarray | Sequence[int], setpoints: np.ndarray | Sequence[int],
             stiffness: np.ndarray | Sequence[int] | None = None,
             damping: np.ndarray | Sequence[int] | None = None) -> None:
        """A valid, fresh command arrived (already accepted by the device's decoder).

        Parameters
        ----------
        modes, setpoints
            (n,) :class:`JointMode` values and raw setpoints.
        stiffness, damping
            (n,) raw impedance gains (``None``: zeros): positive stiffness and non-negative
            damping for IMPEDANCE joints, zero for the others.

        Raises
        ------
        DeviceParameterError
            Wrong array length, a mode that is not a :class:`JointMode`, or gains against
            the rule above.
        """
        m = np.asarray(modes, dtype=np.int64)
        s = np.asarray(setpoints, dtype=np.int64)
        n = self.n_joints
        k = np.zeros(n, dtype=np.int64) if stiffness is None else np.asarray(stiffness,
                                                                             dtype=np.int64)
        d = np.zeros(n, dtype=np.int64) if damping is None else np.asarray(damping,
                                                                           dtype=np.int64)
        if any(a.shape != (n,) for a in (m, s, k, d)):
            raise DeviceParameterError(f'modes {m.shape}, setpoints {s.shape}, stiffness {k.shape} '
                                       f'and damping {d.shape} must all have shape ({n},)')
        if not all(int(v) in _VALID_MODES for v in m):
            raise DeviceParameterError(f'modes {m.tolist()!r} contain a value that is not a '
                                       'JointMode')
        imp = m == int(JointMode.IMPEDANCE)
        if np.any(np.where(imp, (k <= 0) | (d < 0), (k != 0) | (d != 0))):
            raise DeviceParameterError(f'impedance gains against the rules (IMPEDANCE: '
                                       f'stiffness > 0, damping >= 0; others 0): modes '
                                       f'{m.tolist()!r}, stiffness '
                                       f'{k.tolist()!r}, damping {d.tolist()!r}')
        self._modes = m.copy()
        self._setpoints = s.copy()
        self._stiffness = k.copy()
        self._damping = d.copy()
        self._last_feed_s = self._clock()
        self._was_tripped = False

    def feed_frame(self, frame: CommandFrame) -> None:
        """:meth:`feed` with a decoded command frame."""
        self.feed(frame.modes, frame.setpoints, frame.stiffness, frame.damping)

    @property
    def tripped(self) -> bool:
        """Whether the device is in its safe state now (no command for ``timeout_s``)."""
        if self._last_feed_s is None:
            return True
        return self._clock() - self._last_feed_s >= self.timeout_s

    def output(self) -> DeviceOutput:
        """Modes, raw setpoints (0 for HOLD), raw impedance gains and the tripped flag the
        device applies now."""
        tripped = self.tripped
        if tripped and not self._was_tripped:
            self.trips += 1
        self._was_tripped = tripped
        if not tripped:
            return DeviceOutput(self._modes.copy(), self._setpoints.copy(),
                                self._stiffness.copy(), self._damping.copy(), False)
        torque = (self._modes == JointMode.TORQUE) | (self._modes == JointMode.IMPEDANCE)
        modes = np.where(torque, int(JointMode.TORQUE), int(JointMode.HOLD)).astype(np.int64)
        zeros = np.zeros(self.n_joints, dtype=np.int64)
        return DeviceOutput(modes, zeros, zeros.copy(), zeros.copy(), True)
