"""Opening a Dynamixel bus's serial port exclusively, reading it safely, and what caps its rate.

No rclpy. :func:`open_port` opens a port through the SDK's ``PortHandler`` at a baud rate and
takes an exclusive advisory lock on it (``flock``, as pyserial's ``exclusive=True`` does), so
that a second program on the same bus is refused with one line naming the port and, where
``/proc/locks`` tells it, the holder's PID, instead of corrupting the first one's reads. The
lock goes with the file descriptor: closing the port (or the process ending in any way)
releases it. Used by the driver (:mod:`dam_hand_driver.dynamixel_device`) and the set-up
command (``dynamixel_setup``). :func:`checked_sync_read` is the SDK's group sync read that
keeps the Alert bit and takes no answer of another transaction for its own.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import termios
from pathlib import Path

from dam_hand_driver.errors import HandDriverError

#: What the SDK's port raises when the device fails: pyserial's SerialException is an OSError,
#: its ioctls raise termios.error.
PORT_ERRORS = (OSError, termios.error)


class PortLost(HandDriverError):
    """The serial port failed (an adapter unplugged, a pseudo-terminal closed)."""


class PortBusyError(HandDriverError):
    """The port is held by another program (its lock); the message names the port and the
    holder's PID when it can be known."""


def usb_latency_timer_ms(port: str) -> int | None:
    """The USB serial adapter's latency timer [ms] (``None``: not a USB serial adapter, or it
    cannot be read)."""
    name = Path(os.path.realpath(port)).name
    try:
        return int(Path(f'/sys/bus/usb-serial/devices/{name}/latency_timer').read_text())
    except (OSError, ValueError):
        return None


def latency_timer_fix(port: str) -> str:
    """The shell command (and udev rule) that sets ``port``'s latency timer to 1 ms."""
    name = Path(os.path.realpath(port)).name
    return (f'echo 1 | sudo tee /sys/bus/usb-serial/devices/{name}/latency_timer (or a udev '
            f'rule setting ATTR{{latency_timer}}="1")')


def lock_holders(port: str) -> list[int]:
    """PIDs that hold an ``flock``/``fcntl`` lock on ``port``'s device node, from
    ``/proc/locks`` (empty: none, or not known here)."""
    try:
        st = os.stat(port)
        text = Path('/proc/locks').read_text(encoding='ascii', errors='replace')
    except OSError:
        return []
    wanted = (os.major(st.st_dev), os.minor(st.st_dev), st.st_ino)
    holders = []
    for line in text.splitlines():
        fields = line.split()
        # "1: FLOCK  ADVISORY  WRITE 4242 00:1a:5 0 EOF" ("->" marks a waiting lock)
        if '->' in fields or len(fields) < 6:
            continue
        try:
            pid = int(fields[4])
            major, minor, inode = fields[5].split(':')
            key = (int(major, 16), int(minor, 16), int(inode))
        except ValueError:
            continue
        if key == wanted and pid not in holders:
            holders.append(pid)
    return holders


def _process_name(pid: int) -> str:
    """What the process runs: the program a Python interpreter runs (``hand_driver``), not the
    interpreter's own name; empty when it cannot be known."""
    try:
        argv = Path(f'/proc/{pid}/cmdline').read_bytes().split(b'\0')
    except OSError:
        return ''
    args = [a.decode('utf-8', 'replace') for a in argv if a]
    if not args:
        return ''
    interpreter = os.path.basename(args[0]).startswith('python')
    if interpreter and len(args) > 2 and args[1] in ('-m', '-c'):
        return args[2] if args[1] == '-m' else os.path.basename(args[0])  # not the code
    programs = [a for a in args[1:] if not a.startswith('-')] if interpreter else args
    return os.path.basename((programs or args)[0]).splitlines()[0][:40]


def busy_message(port: str) -> str:
    """``the Dynamixel port '/dev/ttyUSB0' is in use by another program (PID 4242,
    hand_driver)``: what a refused open says."""
    holders = lock_holders(port)
    who = ', '.join(f'PID {pid}' + (f' {name}' if (name := _process_name(pid)) else '')
                    for pid in holders)
    return (f'the Dynamixel port {port!r} is in use by another program'
            + (f' ({who})' if who else '') + ': one program at a time drives a bus (stop '
            'the other one, or give this one another port)')


def lock_exclusive(port: str) -> int:
    """Open ``port`` once more and take its exclusive lock on that descriptor, before the
    port itself is opened: a refused program never touches the line (opening a serial port
    sets its termios and flushes its input, which would cost the holder a read).

    Returns
    -------
    int
        The descriptor that holds the lock: close it to release the lock.

    Raises
    ------
    PortBusyError
        Another program holds the lock.
    OSError
        The port cannot be opened (missing, no permission).
    """
    fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError as exc:
        os.close(fd)
        raise PortBusyError(busy_message(port)) from exc
    except OSError:  # a device without locks: nothing to take, nothing to hold
        pass
    return fd


#: How long one read of the port waits for a byte before the SDK looks at its packet timeout
#: again [s]. The SDK polls the port in a loop (a read returns at once, empty or not): a
#: thread that spins so takes a whole core while it waits for the servos' answers, from the
#: recorder, the controller and (on simulated time) the emulated bus itself. Waiting in
#: ``select`` returns as soon as a byte arrives; the SDK's timeouts come at most this late.
READ_WAIT_S = 0.002


def _port_handler(sdk_module: object, port: str, margin_ms: float) -> object:
    """The SDK's port handler whose reads wait for data (at most :data:`READ_WAIT_S`) instead
    of spinning, its packet timeouts longer by ``margin_ms`` [ms]."""
    base = sdk_module.PortHandler  # type: ignore[attr-defined]

    class _Waiting(base):  # type: ignore[misc, valid-type]
        def readPort(self, length: int) -> bytes:  # noqa: N802 - the SDK's name
            if self.ser.in_waiting == 0:
                select.select([self.ser.fileno()], [], [], READ_WAIT_S)
            return super().readPort(length)

        def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 - the SDK's
            super().setPacketTimeout(packet_length)
            self.packet_timeout += margin_ms

    return _Waiting(port)


def open_port(sdk_module: object, port: str, baud_rate: int, *,
              margin_ms: float = 0.0) -> object:
    """The SDK's ``PortHandler`` of ``port``, open at ``baud_rate`` and locked exclusively.

    Parameters
    ----------
    sdk_module
        The ``dynamixel_sdk`` module.
    port
        The serial device (``/dev/ttyUSB0``, a pseudo-terminal).
    baud_rate
        [bit/s]
    margin_ms
        Added to every packet timeout of the SDK [ms] (a slow emulated bus).

    Raises
    ------
    PortBusyError
        Another program holds the port.
    HandDriverError
        The port cannot be opened (missing, no permission: the message says what to do) or
        the baud rate is not one the SDK can set.
    """
    if not os.path.exists(port):
        raise HandDriverError(f'cannot open the Dynamixel port {port!r}: no such device (is '
                              f'the adapter plugged in? ls /dev/ttyUSB* /dev/serial/by-id/)')
    try:
        lock_fd = lock_exclusive(port)
    except PermissionError as exc:
        raise HandDriverError(
            f'cannot open the Dynamixel port {port!r}: permission denied; add yourself to '
            f'its group (sudo usermod -aG dialout $USER, then log in again) or install a udev '
            f'rule (docs/dynamixel.md)') from exc
    except PortBusyError:
        raise
    except OSError as exc:
        raise HandDriverError(f'cannot open the Dynamixel port {port!r}: {exc}') from exc
    handler = _port_handler(sdk_module, port, margin_ms)
    handler.dam_lock_fd = lock_fd  # type: ignore[attr-defined]
    try:
        opened = handler.openPort() and handler.setBaudRate(int(baud_rate))
    except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError
        close_port(handler)
        raise HandDriverError(f'cannot open the Dynamixel port {port!r}: {exc}') from exc
    if not opened:
        close_port(handler)
        raise HandDriverError(f'cannot open the Dynamixel port {port!r} at {baud_rate} bit/s')
    return handler


def close_port(handler: object) -> None:
    """Close a port :func:`open_port` opened and release its lock (idempotent; a port whose
    device went away is closed as far as it can be)."""
    with contextlib.suppress(Exception):
        if getattr(handler, 'ser', None) is not None:
            handler.closePort()  # type: ignore[attr-defined]
    fd = getattr(handler, 'dam_lock_fd', None)
    if fd is not None:
        handler.dam_lock_fd = None  # type: ignore[attr-defined]
        with contextlib.suppress(OSError):
            os.close(fd)


def set_baud_rate(handler: object, port: str, baud_rate: int) -> None:
    """Reopen an open port at another baud rate (the SDK's ``setBaudRate`` closes and opens
    the device again; the lock of :func:`open_port` is held by a descriptor of its own).

    Raises
    ------
    HandDriverError
        The baud rate cannot be set.
    """
    try:
        ok = handler.setBaudRate(int(baud_rate))  # type: ignore[attr-defined]
    except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError
        raise HandDriverError(f'cannot set {port!r} to {baud_rate} bit/s: {exc}') from exc
    if not ok:
        raise HandDriverError(f'cannot set {port!r} to {baud_rate} bit/s')


def checked_sync_read(sdk_module: object) -> type:
    """The SDK's ``GroupSyncRead`` that keeps each status packet's error byte (``errors``, by
    ID: the SDK's own drops it, and with it the Alert bit) and takes only status packets of
    exactly the block's length. The SDK matches an answer by ID alone and cuts its data to the
    length asked for: an answer of an earlier, longer read that came later than the host
    waited (the servo check's 56 bytes) would pass for this read's 16 (``stale`` names it)."""
    base = sdk_module.GroupSyncRead  # type: ignore[attr-defined]
    success = sdk_module.COMM_SUCCESS  # type: ignore[attr-defined]
    corrupt = sdk_module.COMM_RX_CORRUPT  # type: ignore[attr-defined]
    # Status packet: header (3), reserved, ID, length (2), instruction, error, data, CRC (2).
    id_at, length_at, error_at, data_at = 4, 5, 8, 9

    class _CheckedSyncRead(base):  # type: ignore[misc, valid-type]
        errors: dict[int, int]
        stale: int | None

        def rxPacket(self) -> int:  # noqa: N802 - the SDK's name
            self.last_result = False
            self.errors = {}
            self.stale = None
            result = sdk_module.COMM_NOT_AVAILABLE  # type: ignore[attr-defined]
            for dxl_id in self.data_dict:
                self.data_dict[dxl_id] = []
                while True:  # answers of other IDs are dropped, as the SDK does
                    packet, result = self.ph.rxPacket(self.port, False)
                    if result != success or packet[id_at] == dxl_id:
                        break
                if result != success:
                    return result
                if packet[length_at] | packet[length_at + 1] << 8 != self.data_length + 4:
                    self.stale = dxl_id
                    return corrupt
                self.errors[dxl_id] = int(packet[error_at])
                self.data_dict[dxl_id] = bytearray(
                    packet[data_at:data_at + self.data_length])
            self.last_result = result == success
            return result

    return _CheckedSyncRead
