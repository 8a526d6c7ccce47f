"""The device interface of the driver: what a backend (a way to reach a hand) provides.

The driver node (:mod:`dam_hand_driver.driver_node`) knows nothing of wires: it asks a
:class:`HandDevice` for the newest :class:`JointSample` (SI units), answers each with one
command (modes and slew-limited setpoints, SI units) and goes to ERROR when samples stop. Two
backends implement it:

- :class:`dam_hand_driver.udp_device.UdpDevice`: the suite's own UDP device link
  (``docs/device_protocol.md``), spoken by the PyBullet stand-in and by firmware written for it;
- :class:`dam_hand_driver.dynamixel_device.DynamixelDevice`: Dynamixel Protocol 2.0 servos on
  one serial bus, through ``dynamixel-sdk`` (``docs/dynamixel.md``).

A third backend (a CAN bus, a vendor SDK) subclasses :class:`HandDevice`, implements the
abstract methods and is named in ``driver_node.BACKENDS``; ``docs/architecture.md``, "Adding a
device backend", lists what each method must guarantee.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np


class JointSample(NamedTuple):
    """One reading of every joint, in the configured joint order."""

    seq: int  #: the device's (or the host's cycle) sequence number
    stamp_ns: int  #: the device clock [ns] (simulated time on a stand-in on simulated time)
    position: np.ndarray  #: (n,) joint angles [rad]
    velocity: np.ndarray  #: (n,) joint velocities [rad/s]
    effort: np.ndarray  #: (n,) joint torques [N*m] (sensor or estimate: see the backend)
    simulated: bool = False  #: the device says it is a simulation
    watchdog_tripped: bool = False  #: the device's own watchdog has stopped it
    #: A fault of the device that the driver must stop for (an ERROR), e.g. a servo's
    #: hardware error, named; empty: none.
    fault: str = ''


class CommandItemLike(NamedTuple):
    """What :meth:`HandDevice.command_error` sees of one joint command (SI units)."""

    joint: int
    mode: int  #: :class:`dam_common.device_protocol.JointMode` value
    setpoint: float
    stiffness: float
    damping: float


class HandDevice(abc.ABC):
    """A hand (or its stand-in) the driver reads and commands.

    Thread use: :meth:`receive`, :meth:`send`, :meth:`arm`, :meth:`disarm` and :meth:`resend`
    are called from the driver's device-link thread only; :meth:`diagnostics` from the
    executor (it must only read counters); :meth:`recover` from the executor while the link
    thread waits (the driver is in ERROR and does not call :meth:`send`).
    """

    #: The backend's name (``udp``, ``dynamixel``).
    kind: str = ''
    #: One device cycle [s]: the rate of samples and commands.
    period_s: float = 0.0
    #: Where the device is reached, for ``/diagnostics`` (``hardware_id``).
    hardware_id: str = ''
    #: ``time.monotonic()`` of the newest sample (``None``: none yet).
    last_sample_time: float | None = None
    #: Samples returned so far (the achieved rate in ``/diagnostics`` comes from it).
    samples_received: int = 0
    #: Reads that failed or came back incomplete or garbled (a WARN while they grow).
    read_failures: int = 0

    @abc.abstractmethod
    def receive(self, timeout_s: float) -> JointSample | None:
        """The newest sample within ``timeout_s`` [s], or ``None``. Never raises on bad input
        from the device: a sample that is incomplete or garbled is counted and not returned."""

    @abc.abstractmethod
    def send(self, sample: JointSample, modes: np.ndarray, setpoints: np.ndarray,
             stiffness: np.ndarray, damping: np.ndarray) -> None:
        """Answer ``sample`` with one command.

        Parameters
        ----------
        sample
            The sample the command answers.
        modes
            (n,) :class:`~dam_common.device_protocol.JointMode` per joint.
        setpoints
            (n,) slew-limited setpoints: torque [N*m] (TORQUE), angle [rad] (POSITION, and
            the impedance equilibrium ``theta_0`` of IMPEDANCE), ignored (HOLD).
        stiffness, damping
            (n,) impedance gains [N*m/rad], [N*m*s/rad] of the IMPEDANCE joints (0 elsewhere).
        """

    def command_error(self, items: Sequence[CommandItemLike]) -> str | None:
        """Why this device cannot carry a validated command (``None``: it can), e.g. a mode
        that a joint's actuator does not have. Checked before a command is taken."""
        return None

    def arm(self, sample: JointSample) -> None:  # noqa: B027 - optional for a backend
        """The driver became ACTIVE, every joint HOLDing ``sample``'s posture: switch the
        actuators on (a device that runs whenever commanded does nothing)."""

    def disarm(self) -> None:  # noqa: B027 - optional for a backend
        """The driver entered ERROR: switch the actuators off, if the device can be told."""

    def needs_rearm(self) -> str:
        """Why an ACTIVE device must go through ``~/reset``'s re-arming (empty: it need not),
        e.g. actuators that restarted with torque off."""
        return ''

    def recover(self) -> str:
        """Prepare to leave ERROR (``~/reset``): clear what the device can clear. Returns what
        was done, for the reply (empty: nothing needed).

        Raises
        ------
        HandDriverError
            The device cannot leave ERROR now (the message says why): the driver stays in
            ERROR with that reason.
        """
        return ''

    def resend(self) -> bool:
        """Send the newest command again (a stand-in on simulated time that lost it)."""
        return False

    def restart_sequence(self) -> None:  # noqa: B027 - optional for a backend
        """Forget the device's sequence numbers (it may have restarted)."""

    @property
    def link_lost(self) -> str:
        """Why the device cannot be reached at all (a port that failed, named): an ERROR at
        once, until :meth:`recover` reaches it again (empty: it can be reached)."""
        return ''

    @property
    def failing_reads(self) -> int:
        """Reads that failed in a row since the last good one (a WARN while above 0)."""
        return 0

    @property
    def last_failure(self) -> str:
        """What went wrong with the newest failed read, naming the part (empty: nothing):
        the driver adds it to an ERROR for silence."""
        return ''

    @abc.abstractmethod
    def diagnostics(self) -> dict[str, str]:
        """Counters and state for ``/diagnostics`` (read only)."""

    @abc.abstractmethod
    def close(self) -> None:
        """Release the port or socket (idempotent)."""
