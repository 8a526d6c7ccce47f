"""The simulated DAM hand as a device on the UDP link (no rclpy).

:class:`SimDevice` plays the part of the hand's firmware for a :class:`HandWorld`: every device
period (``1 / device.rate_hz``) it

1. reads every pending command datagram on ``device.command_port`` through a
   :class:`~dam_common.device_protocol.FrameDecoder` (command kind) and feeds the accepted ones to
   a :class:`~dam_common.device_protocol.DeviceWatchdog`;
2. applies the watchdog's output (the newest command, or the safe state) to the world, raw
   setpoints and impedance gains converted to SI with
   :class:`~dam_common.device_protocol.Calibration`; IMPEDANCE joints then run their law
   ``clip(k (theta_0 - theta) - d theta_dot)`` inside the world at every physics step (1 kHz),
   not once per device cycle, and every TORQUE and IMPEDANCE torque is slew-limited there to
   ``device.torque_rate_limit_nm_per_s`` (:mod:`dam_sim_bridge.joint_commands`);
3. steps the world by one period (``round(period / sim.time_step_s)`` physics steps);
4. encodes the joint state in raw units, with fault and status bits, and sends it to the
   driver's ``device.state_port``.

:meth:`SimDevice.run` runs the cycles in one of three ways:

* **real time** (the default): paced to absolute deadlines, missed ones skipped, the device
  clock is the machine's monotonic clock: a device with a hardware clock, whose deadlines a
  stalled driver misses;
* **simulated time** (``sim_time=True``, the stand-in of a suite run with
  ``use_sim_time:=true``): the device clock is the simulated time, and the world is stepped to
  the next period only once the driver has answered the newest state frame (a command frame
  whose ``ref_state_seq`` is that frame's). Cycles are paced to at most real time (a real-time
  factor of at most 1); a stall of the machine, of the driver or of this process
  stretches wall time and changes nothing else. A state frame that stays unanswered is sent
  again every :data:`RESEND_S` (a driver that starts later, or a lost datagram);
* **lockstep** (:meth:`SimDevice.cycle`, or ``lockstep=True``): as fast as possible, the
  device clock is the simulated time, for tests.
"""

from __future__ import annotations

import math
import select
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dam_common.device_protocol import (
    Calibration,
    CommandFrame,
    DeviceStatus,
    DeviceWatchdog,
    FrameDecoder,
    FrameKind,
    JointFault,
    encode_state,
    seq_newer,
)
from dam_common.realtime import reduce_timer_slack
from dam_sim_bridge.errors import WorldConfigError
from dam_sim_bridge.pacing import sleep_until
from dam_sim_bridge.world import HandWorld

if TYPE_CHECKING:
    from dam_common.config import DamConfig

_MAX_DATAGRAM = 2048
#: In real time, the physics of the next cycle starts this fraction of a period after a state
#: frame is sent (see :meth:`SimDevice.run`).
STEP_OFFSET_FRACTION = 0.3
#: Simulated time: an unanswered state frame is sent again after this long [s of wall time].
RESEND_S = 0.1


@dataclass
class DeviceStats:
    """Counters of a :class:`SimDevice` (read them for diagnostics)."""

    cycles: int = 0  #: device cycles run
    states_sent: int = 0  #: state frames sent
    send_errors: int = 0  #: state frames that could not be sent (socket error)
    encode_errors: int = 0  #: states that did not fit the raw fields
    command_errors: int = 0  #: accepted commands the world refused (should stay 0)
    missed_deadlines: int = 0  #: cycles that started more than a period late
    states_resent: int = 0  #: simulated time: unanswered state frames sent again
    latency_cycles: int = -1  #: state seq - ref_state_seq of the newest command (-1: none yet)


class SimDevice:
    """A :class:`HandWorld` behind the device's UDP link.

    Parameters
    ----------
    config
        ``DamConfig``: ``device`` (addresses, rate, watchdog, calibration) and ``sim``.
    world
        The world to serve; by default ``HandWorld(config)``.
    host, command_port, state_port
        Override ``device.host``, ``device.command_port`` (bound here) and
        ``device.state_port`` (state frames are sent there). ``command_port = 0`` binds a free
        port (see :attr:`command_address`).
    lockstep
        :meth:`run` as fast as possible, device clock = simulated time (for tests).
    sim_time
        :meth:`run` in simulated time: device clock = simulated time, each cycle waits for
        the driver's answer to the previous state frame, paced to at most real time.
    clock
        Monotonic clock [s] for real-time operation and pacing.

    Raises
    ------
    WorldConfigError
        The device period is shorter than the physics step or the rate is not positive.
    OSError
        The command port cannot be bound.
    """

    def __init__(self, config: DamConfig, world: HandWorld | None = None, *,
                 host: str | None = None, command_port: int | None = None,
                 state_port: int | None = None, lockstep: bool = False,
                 sim_time: bool = False,
                 clock: Callable[[], float] = time.monotonic) -> None:
        dev = config.device
        rate = float(dev.rate_hz)
        if not (math.isfinite(rate) and rate > 0.0):
            raise WorldConfigError(f'device.rate_hz {dev.rate_hz!r} must be positive')
        self.config = config
        self.world = world if world is not None else HandWorld(config)
        self.period_s = 1.0 / rate
        steps = round(self.period_s / self.world.time_step_s)
        if steps < 1:
            raise WorldConfigError(f'device period {self.period_s!r} s is shorter than the '
                                   f'physics step {self.world.time_step_s!r} s')
        #: Physics steps per device cycle.
        self.steps_per_cycle = int(steps)
        self.lockstep = bool(lockstep)
        self.sim_time = bool(sim_time)
        self._rt_clock = clock
        self._sim_clock_s = 0.0
        n = self.world.n_joints
        self.calibration = Calibration.from_config(config)
        self.decoder = FrameDecoder(FrameKind.COMMAND, n)
        self.watchdog = DeviceWatchdog(n, dev.watchdog_s, clock=self.now)
        self.stats = DeviceStats()
        self.lock = threading.RLock()  #: guards the world between the loop and other threads
        self._seq = 0
        #: ``ref_state_seq`` of the newest command frame accepted (None: none yet).
        self._newest_ref: int | None = None
        self._host = host if host is not None else dev.host
        self._state_addr = (self._host, int(state_port if state_port is not None
                                            else dev.state_port))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((self._host, int(command_port if command_port is not None
                                            else dev.command_port)))
        except OSError:
            self.sock.close()
            raise
        self.sock.setblocking(False)
        self._stop = threading.Event()
        self._applied: tuple[bytes, bytes, bytes, bytes] | None = None
        self.tripped = True

    # ---------------------------------------------------------------------------------------

    @property
    def command_address(self) -> tuple[str, int]:
        """(host, port) the device receives command frames on."""
        host, port = self.sock.getsockname()[:2]
        return str(host), int(port)

    def now(self) -> float:
        """Device clock [s]: simulated time in lockstep and simulated-time mode, else the
        real-time clock."""
        return self._sim_clock_s if (self.lockstep or self.sim_time) else self._rt_clock()

    def _drain_commands(self) -> None:
        while True:
            try:
                data = self.sock.recv(_MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. ICMP port unreachable reported on a later call
                continue
            frame = self.decoder.decode(data)
            if isinstance(frame, CommandFrame):
                self.watchdog.feed_frame(frame)
                self._newest_ref = frame.ref_state_seq
                self.stats.latency_cycles = (self._seq - frame.ref_state_seq) % 2**32

    def cycle(self) -> bytes | None:
        """Run one device cycle: commands in, world stepped one period, state out.

        Returns
        -------
        bytes | None
            The state frame sent, or ``None`` if the state could not be encoded.
        """
        frame = self._compute_cycle(None)
        if frame is not None:
            self._send_state(frame)
        return frame

    def _compute_cycle(self, stamp_s: float | None, drain: bool = True) -> bytes | None:
        """Commands in (if ``drain``), world stepped one period; the encoded state frame (not
        sent yet), stamped ``stamp_s`` [s] on the device clock (``None``: now, after the
        step)."""
        with self.lock:
            if drain:
                self._drain_commands()
            out = self.watchdog.output()
            modes, setpoints, tripped = out.modes, out.setpoints, out.tripped
            self.tripped = tripped
            key = (modes.tobytes(), setpoints.tobytes(), out.stiffness.tobytes(),
                   out.damping.tobytes())
            if key != self._applied:  # the world keeps a command until the next call
                try:
                    stiffness, damping = self.calibration.gains_si(out.stiffness, out.damping)
                    self.world.set_joint_commands(
                        modes, self.calibration.setpoints_si(modes, setpoints), stiffness,
                        damping)
                    self._applied = key
                except ValueError:
                    self.stats.command_errors += 1
            self.world.step(self.steps_per_cycle)
            self._sim_clock_s += self.steps_per_cycle * self.world.time_step_s
            q, dq, tau = self.world.joint_states()
            faults = self.world.joint_faults()
            status = int(DeviceStatus.SIMULATED)
            if tripped:
                faults = faults | int(JointFault.WATCHDOG)
                status |= int(DeviceStatus.WATCHDOG_TRIPPED)
            self.stats.cycles += 1
            try:
                pos, vel, tor = self.calibration.state_raw(q, dq, tau)
                stamp = self.now() if stamp_s is None else stamp_s
                frame = encode_state(self._seq, int(stamp * 1e9), pos, vel, tor,
                                     self.world.joint_modes(), faults, status)
            except ValueError:
                self.stats.encode_errors += 1
                return None
            self._seq = (self._seq + 1) % 2**32
        return frame

    def _send_state(self, frame: bytes) -> None:
        try:
            self.sock.sendto(frame, self._state_addr)
            self.stats.states_sent += 1
        except OSError:
            self.stats.send_errors += 1

    def reset_world(self) -> None:
        """Reset the world to its initial state (all joints HOLD, object at rest)."""
        with self.lock:
            self.world.reset()
            self._applied = None  # reset() put every joint in HOLD: apply the command again

    def run(self, stop: threading.Event | None = None) -> None:
        """Run cycles until :meth:`stop` (or ``stop`` is set): paced in real time, or as fast
        as possible in lockstep mode.

        In real time the world is stepped from t to t + period ahead of time and its state is
        sent at the deadline t + period, the moment it describes, as a device with a hardware
        clock would: the period between two state frames does not depend on how long the
        physics took. Right after a state frame goes out the commands received so far are
        taken (those computed from older states: one period of latency, as on a real hand);
        the physics waits :data:`STEP_OFFSET_FRACTION` of a period, so that the driver and
        its subscribers have the CPU in the moment the frame arrives.
        """
        stop_event = stop if stop is not None else self._stop
        if self.lockstep:
            while not (stop_event.is_set() or self._stop.is_set()):
                self.cycle()
            return
        if self.sim_time:
            self._run_sim_time(stop_event)
            return
        reduce_timer_slack()
        next_deadline = self._rt_clock() + self.period_s
        frame = self._compute_cycle(next_deadline)
        while not (stop_event.is_set() or self._stop.is_set()):
            late = self._rt_clock() - next_deadline
            if late > self.period_s:
                self.stats.missed_deadlines += 1
                next_deadline = self._rt_clock()  # do not try to catch up a backlog
            else:
                sleep_until(next_deadline, self._rt_clock)
            if frame is not None:
                self._send_state(frame)
            with self.lock:
                self._drain_commands()
            time.sleep(STEP_OFFSET_FRACTION * self.period_s)
            next_deadline += self.period_s
            frame = self._compute_cycle(next_deadline, drain=False)

    def _stopped(self, stop_event: threading.Event) -> bool:
        return stop_event.is_set() or self._stop.is_set()

    def _run_sim_time(self, stop_event: threading.Event) -> None:
        """Simulated time: send state k, wait for the driver's answer to it, step to k + 1.

        The command that answers state k was computed from the joint state before it (the
        driver answers with the newest command it has), so a command reaches the world two
        periods after the state it was computed from, as in the lockstep trial
        (:func:`dam_experiments.experiment.run_experiment`, ``latency_cycles=2``).
        """
        frame = self._compute_cycle(None)
        next_deadline = self._rt_clock()
        while not self._stopped(stop_event):
            now = self._rt_clock()
            if now > next_deadline + self.period_s:  # stalled: stretch, never catch up
                self.stats.missed_deadlines += 1
                next_deadline = now
            elif now < next_deadline:
                time.sleep(next_deadline - now)
            if frame is not None:
                seq = (self._seq - 1) % 2**32  # the frame's own number
                self._send_state(frame)
                if not self._await_answer(frame, seq, stop_event):
                    return
            next_deadline += self.period_s
            frame = self._compute_cycle(None, drain=False)

    def _await_answer(self, frame: bytes, seq: int, stop_event: threading.Event) -> bool:
        """Take command frames until one answers state ``seq``; send ``frame`` again every
        :data:`RESEND_S`. ``False`` if stopped meanwhile."""
        resend_at = self._rt_clock() + RESEND_S
        while not self._stopped(stop_event):
            with self.lock:
                self._drain_commands()
                ref = self._newest_ref
            if ref is not None and not seq_newer(seq, ref):
                return True
            now = self._rt_clock()
            if now >= resend_at:
                self._send_state(frame)
                self.stats.states_resent += 1
                resend_at = now + RESEND_S
            try:
                select.select([self.sock], [], [], min(0.01, max(0.0, resend_at - now)))
            except (OSError, ValueError):  # the socket was closed: stopping
                return False
        return False

    def stop(self) -> None:
        """Ask :meth:`run` to return after the current cycle."""
        self._stop.set()

    def close(self) -> None:
        """Close the socket and the world."""
        self._stop.set()
        self.sock.close()
        self.world.close()

    def joint_torques_si(self) -> np.ndarray:
        """(n,) current torque-sensor readings of the world [N*m]."""
        with self.lock:
            return self.world.joint_states().torques
