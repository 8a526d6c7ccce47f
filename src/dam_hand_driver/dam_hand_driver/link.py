"""The driver's end of the UDP device link (no rclpy).

:class:`DeviceLink` receives state frames on ``device.state_port`` and sends command frames to
the device's ``device.command_port`` (``docs/device_protocol.md``). It validates every datagram
with a :class:`~dam_common.device_protocol.FrameDecoder` (state kind) and never raises on bad
input; socket errors while sending are counted.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dam_common.device_protocol import (
    FrameDecoder,
    FrameKind,
    StateFrame,
    encode_command,
    seq_next,
)
from dam_hand_driver.errors import ParameterError

_MAX_DATAGRAM = 2048


@dataclass
class LinkStats:
    """Counters of a :class:`DeviceLink`."""

    datagrams: int = 0  #: datagrams received (accepted or not)
    commands_sent: int = 0  #: command frames sent
    send_errors: int = 0  #: command frames the socket refused


def _default_bind_host(device_host: str) -> str:
    try:
        loopback = ipaddress.ip_address(device_host).is_loopback
    except ValueError:
        loopback = device_host == 'localhost'
    return '127.0.0.1' if loopback else '0.0.0.0'


class DeviceLink:
    """Exchanges frames with the hand (or its stand-in).

    Parameters
    ----------
    n_joints
        Joints per frame.
    device_host
        Address of the device [IPv4 or host name].
    state_port
        Port this end binds to receive state frames (``0``: a free port, see
        :attr:`state_address`).
    command_port
        Port of the device that receives command frames.
    bind_host
        Address to bind; default loopback for a loopback device, else every interface.

    Raises
    ------
    ParameterError
        A port is outside [0, 65535].
    OSError
        The state port cannot be bound (another driver runs?).
    """

    def __init__(self, n_joints: int, device_host: str, state_port: int, command_port: int,
                 bind_host: str | None = None) -> None:
        for name, port in (('state_port', state_port), ('command_port', command_port)):
            if not 0 <= int(port) <= 65535:
                raise ParameterError(f'{name} {port!r} is outside [0, 65535]')
        self.n_joints = int(n_joints)
        self.decoder = FrameDecoder(FrameKind.STATE, self.n_joints)
        self.stats = LinkStats()
        self._command_addr = (device_host, int(command_port))
        self._seq = 0
        self._last_frame: bytes | None = None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((bind_host or _default_bind_host(device_host), int(state_port)))
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        #: ``time.monotonic()`` when the newest accepted state frame arrived (None: never).
        self.last_state_time: float | None = None

    @property
    def state_address(self) -> tuple[str, int]:
        """(host, port) this end receives state frames on."""
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def receive(self, timeout_s: float) -> StateFrame | None:
        """Wait up to ``timeout_s`` [s] for state frames, read every pending one, return the
        newest accepted one (``None`` if none was accepted)."""
        newest: StateFrame | None = None
        deadline = time.monotonic() + max(0.0, timeout_s)
        while newest is None:
            remaining = deadline - time.monotonic()
            try:
                ready, _, _ = select.select([self.sock], [], [], max(0.0, remaining))
            except (InterruptedError, ValueError, OSError):
                return None
            if not ready:
                return None
            while True:
                try:
                    data = self.sock.recv(_MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # ICMP errors of an earlier send, closed socket
                    break
                self.stats.datagrams += 1
                frame = self.decoder.decode(data)
                if frame is not None:
                    newest = frame  # type: ignore[assignment]
                    self.last_state_time = time.monotonic()
            if remaining <= 0.0:
                break
        return newest

    def send(self, modes: Sequence[int] | np.ndarray, setpoints_raw: Sequence[int] | np.ndarray,
             ref_state_seq: int, stiffness_raw: Sequence[int] | np.ndarray | None = None,
             damping_raw: Sequence[int] | np.ndarray | None = None) -> bool:
        """Send one command frame (raw units); ``False`` if the socket refused it.

        ``stiffness_raw`` and ``damping_raw`` are the raw impedance gains (``None``: zeros,
        no joint in IMPEDANCE).

        Raises
        ------
        EncodeError
            A mode, setpoint or gain does not fit the frame (a bug of the caller).
        """
        self._seq = seq_next(self._seq)
        frame = encode_command(self._seq, ref_state_seq, modes, setpoints_raw, stiffness_raw,
                               damping_raw)
        self._last_frame = frame
        return self._send_frame(frame)

    def resend(self) -> bool:
        """Send the newest command frame again (same content and sequence number: a device
        takes it once); ``False`` if there is none or the socket refused it."""
        return self._last_frame is not None and self._send_frame(self._last_frame)

    def _send_frame(self, frame: bytes) -> bool:
        try:
            self.sock.sendto(frame, self._command_addr)
        except OSError:
            self.stats.send_errors += 1
            return False
        self.stats.commands_sent += 1
        return True

    def reset(self) -> None:
        """Forget the device's newest sequence number (after the device restarted)."""
        self.decoder.reset()

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()
