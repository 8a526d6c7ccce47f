"""The simulated hand as nine Dynamixel servos on an emulated bus (no rclpy).

:class:`DynamixelStandIn` puts a :class:`~dam_sim_bridge.world.HandWorld` behind a
:class:`~dam_sim_bridge.dynamixel_bus.DynamixelBus`: one emulated X-series servo per joint,
mapped by the configuration's ``dynamixel:`` section
(:class:`dam_common.dynamixel_config.DynamixelConfig`). It has the surface of
:class:`~dam_sim_bridge.sim_device.SimDevice` (``run``, ``stop``, ``close``, ``now``,
``reset_world``, ``lock``, ``world``, ``steps_per_cycle``, ``period_s``, ``stats``), so the
stand-in node can serve either.

Every cycle (``period_s = 1 / dynamixel.rate_hz``, ``steps_per_cycle`` physics steps) the
servos' goals go to the world, the world is stepped, and the joint state comes back as the
servos' present values. Per joint, with its servo's ``direction``, ``zero_offset_counts``,
torque constant ``kt`` [N*m/A] and the model's current unit [A]:

* torque off, a hardware error or a tripped Bus Watchdog: TORQUE mode with 0 N*m (the joint is
  limp, as an unpowered servo);
* Operating Mode 0 (current): TORQUE mode, ``tau = direction * goal_current * unit * kt`` with
  the goal clipped to Current Limit (the world also clips to its own torque limit and slews);
* Operating Mode 3, 4, 5 (position, extended, current-based position): POSITION mode to
  ``direction * (goal_position - homing_offset - zero_offset_counts) * 2 pi / 4096`` [rad] with
  the world's position servo; in mode 5 the Goal Current cap is not emulated (the world's servo
  force limit applies instead);
* other modes (velocity, PWM): HOLD, the joint holds where it is;
* present values: shaft position ``zero_offset + direction * theta / (2 pi / 4096)`` plus the
  Homing Offset, velocity ``direction * theta_dot`` in 0.229 rev/min, current
  ``direction * tau / (kt * unit)`` from the world's joint torque reading.

Two ways of running (:meth:`DynamixelStandIn.run`):

* **real time** (default): a thread steps one period per period of ``time.monotonic``, never
  catching up a backlog; the device clock is ``clock``;
* **lockstep on the bus** (``sim_time=True``): the world advances one period exactly when a
  READ or SYNC_READ whose address range overlaps Present Position (132..135) arrives, before
  that read is answered; the host's bus cycle is the clock, and the device clock is the
  simulated time.

Realtime Tick (120) and the Bus Watchdog run on the device clock. Every servo's Baud Rate
(address 8) encodes ``dynamixel.baud_rate``, and the bus answers a host only at that rate
(:mod:`dam_sim_bridge.dynamixel_bus`); Return Delay Time (9) is ``return_delay_time_raw``.

The ``dynamixel_bus`` program (:mod:`dam_sim_bridge.dynamixel_bus_program`) serves a stand-in
alone, without ROS.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

from dam_common.device_protocol import JointMode
from dam_sim_bridge.dynamixel_bus import (
    WATCHDOG_FEED_ADDRESSED,
    WATCHDOG_FEEDS,
    BusStats,
    DynamixelBus,
)
from dam_sim_bridge.dynamixel_packets import Instruction, Packet, from_le
from dam_sim_bridge.dynamixel_servo import (
    MODE_CURRENT,
    MODE_CURRENT_POSITION,
    MODE_EXTENDED_POSITION,
    MODE_POSITION,
    SERVO_MODELS,
    DynamixelServo,
)
from dam_sim_bridge.errors import WorldConfigError
from dam_sim_bridge.world import HandWorld

if TYPE_CHECKING:
    from dam_common.config import DamConfig

#: One position count [rad] (4096 per revolution).
RAD_PER_COUNT = 2.0 * math.pi / 4096
#: One velocity unit, 0.229 rev/min [rad/s].
RAD_S_PER_VELOCITY_UNIT = 0.229 * 2.0 * math.pi / 60.0
#: Present Position's addresses: a read overlapping them advances the world in lockstep.
PRESENT_POSITION = range(132, 136)

_TORQUE, _POSITION, _HOLD = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
_POSITION_MODES = (MODE_POSITION, MODE_EXTENDED_POSITION, MODE_CURRENT_POSITION)


def reads_present_position(packet: Packet) -> bool:
    """Whether ``packet`` is a READ or SYNC_READ whose range overlaps Present Position."""
    if packet.instruction == Instruction.READ and not packet.is_broadcast:
        ok = len(packet.params) == 4
    elif packet.instruction == Instruction.SYNC_READ and packet.is_broadcast:
        ok = len(packet.params) >= 4
    else:
        return False
    if not ok:
        return False
    start, length = from_le(packet.params[0:2]), from_le(packet.params[2:4])
    return start < PRESENT_POSITION.stop and start + length > PRESENT_POSITION.start


class DynamixelStandIn:
    """A :class:`HandWorld` behind an emulated Dynamixel bus.

    Parameters
    ----------
    config
        ``DamConfig`` with a ``dynamixel`` section (servos in ``hand.joint_names`` order,
        ``rate_hz``).
    world
        The world to serve; by default ``HandWorld(config)``.
    sim_time
        Lockstep on the bus: the world steps one period per read of Present Position.
    link_path
        Symlink to the pty, created here and removed by :meth:`close`.
    clock
        Device clock in real time [s].
    return_delay_time_raw
        Return Delay Time of every servo [2 us units]: 0, as a hand set up for speed; 250 as
        a servo from the factory.
    watchdog_feed
        Which packets feed a servo's Bus Watchdog: ``'addressed'`` (packets with its ID, plain
        broadcasts, sync and bulk packets that list it) or ``'any'`` (every packet).

    Raises
    ------
    WorldConfigError
        No ``dynamixel`` section, a servo per joint missing or out of order, an unknown model,
        a baud rate a servo's model does not have, a bus period shorter than the physics step,
        or a ``watchdog_feed`` that is neither.
    OSError
        The pty or the link cannot be created.
    """

    def __init__(self, config: DamConfig, world: HandWorld | None = None, *,
                 sim_time: bool = False, link_path: str | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 return_delay_time_raw: int = 0,
                 watchdog_feed: str = WATCHDOG_FEED_ADDRESSED) -> None:
        dxl = getattr(config, 'dynamixel', None)
        if dxl is None:
            raise WorldConfigError('the configuration has no dynamixel: section')
        rate = float(dxl.rate_hz)
        if not (math.isfinite(rate) and rate > 0.0):
            raise WorldConfigError(f'dynamixel.rate_hz {dxl.rate_hz!r} must be positive')
        names = tuple(config.hand.joint_names)
        joints = tuple(s.joint for s in dxl.servos)
        if joints != names:
            raise WorldConfigError(f'dynamixel.servos {list(joints)} are not the joints '
                                   f'{list(names)} in order')
        unknown = sorted({s.model for s in dxl.servos} - set(SERVO_MODELS))
        if unknown:
            raise WorldConfigError(f'dynamixel.servos: model {unknown} is not emulated '
                                   f'(emulated: {sorted(SERVO_MODELS)})')
        try:
            baud_values = tuple(SERVO_MODELS[s.model].baud_rate_value(dxl.baud_rate)
                                for s in dxl.servos)
        except ValueError as exc:
            raise WorldConfigError(f'dynamixel.baud_rate: {exc}') from None
        if watchdog_feed not in WATCHDOG_FEEDS:
            raise WorldConfigError(f'watchdog_feed {watchdog_feed!r} is not one of '
                                   f'{WATCHDOG_FEEDS}')
        self.config = config
        self.period_s = 1.0 / rate
        own_world = world is None
        self.world = world if world is not None else HandWorld(config)
        try:
            steps = round(self.period_s / self.world.time_step_s)
            if steps < 1:
                raise WorldConfigError(f'bus period {self.period_s!r} s is shorter than the '
                                       f'physics step {self.world.time_step_s!r} s')
            #: Physics steps per bus cycle.
            self.steps_per_cycle = int(steps)
            self.sim_time = bool(sim_time)
            self._rt_clock = clock
            self._sim_clock_s = 0.0
            self.lock = threading.RLock()  #: guards the world and the servos' tables
            self.servo_configs = tuple(dxl.servos)
            #: The emulated servos, in joint order.
            self.servos = tuple(DynamixelServo(s.servo_id, s.model) for s in dxl.servos)
            self._applied: tuple[tuple[int, ...], tuple[float, ...]] | None = None
            self._stop = threading.Event()
            self._running = threading.Lock()
            self.bus = DynamixelBus(self.servos, link_path=link_path, clock=self.now,
                                    lock=self.lock, before_dispatch=self._before_dispatch,
                                    watchdog_feed=watchdog_feed)
        except BaseException:
            if own_world:
                self.world.close()
            raise
        self.port_path: str = self.bus.port_path
        self.link_path: str | None = self.bus.link_path
        self.stats: BusStats = self.bus.stats
        with self.lock:
            self._refresh_present()
            for s, baud in zip(self.servos, baud_values, strict=True):
                s.set('goal_position', s.get('present_position'))  # where it stands
                # A hand set up as docs/dynamixel.md says: the configured baud rate (a servo
                # from the factory has 57600 bit/s) and no Return Delay Time (500 us).
                s.set('baud_rate', baud)
                s.set('return_delay_time', return_delay_time_raw)

    # ---------------------------------------------------------------------------------------
    # Clock and physics

    def now(self) -> float:
        """Device clock [s]: simulated time with ``sim_time``, else the real-time clock."""
        return self._sim_clock_s if self.sim_time else self._rt_clock()

    def _commands(self) -> tuple[tuple[int, ...], tuple[float, ...]]:
        modes: list[int] = []
        setpoints: list[float] = []
        for cfg, s in zip(self.servo_configs, self.servos, strict=True):
            mode = s.get('operating_mode')
            if not s.output_enabled:
                modes.append(_TORQUE)
                setpoints.append(0.0)
            elif mode == MODE_CURRENT:
                limit = s.get('current_limit')
                current = max(-limit, min(limit, s.get('goal_current')))
                modes.append(_TORQUE)
                setpoints.append(cfg.direction * current * s.model.current_unit_a
                                 * cfg.torque_constant_nm_per_a)
            elif mode in _POSITION_MODES:
                shaft = s.get('goal_position') - s.get('homing_offset')
                modes.append(_POSITION)
                setpoints.append(cfg.direction * (shaft - cfg.zero_offset_counts)
                                 * RAD_PER_COUNT)
            else:
                modes.append(_HOLD)
                setpoints.append(math.nan)
        return tuple(modes), tuple(setpoints)

    def _refresh_present(self) -> None:
        q, dq, tau = self.world.joint_states()
        for i, (cfg, s) in enumerate(zip(self.servo_configs, self.servos, strict=True)):
            d = cfg.direction
            counts_per_amp = 1.0 / (cfg.torque_constant_nm_per_a * s.model.current_unit_a)
            s.set_present(round(cfg.zero_offset_counts + d * float(q[i]) / RAD_PER_COUNT),
                          round(d * float(dq[i]) / RAD_S_PER_VELOCITY_UNIT),
                          round(d * float(tau[i]) * counts_per_amp))

    def cycle(self) -> None:
        """One bus period: goals to the world, ``steps_per_cycle`` physics steps, present
        values back (what the real-time thread and the lockstep reads run)."""
        with self.lock:
            now = self.now()
            for s in self.servos:
                s.check_watchdog(now)
            command = self._commands()
            if command != self._applied:  # the world keeps a command until the next call
                self.world.set_joint_commands(command[0], command[1])
                self._applied = command
            self.world.step(self.steps_per_cycle)
            self._sim_clock_s += self.steps_per_cycle * self.world.time_step_s
            now = self.now()
            for s in self.servos:
                s.check_watchdog(now)
            self._refresh_present()
            self.stats.cycles += 1

    def _before_dispatch(self, packet: Packet) -> None:
        if self.sim_time and reads_present_position(packet):
            self.cycle()

    def reset_world(self) -> None:
        """Reset the world to its initial state, the hand power-cycled: every servo restarts
        (torque off, RAM defaults, hardware errors cleared; EEPROM kept) with its goal at the
        posture it then stands in. A host that held its old goals would otherwise drive the
        reset fingers back to them; the driver notices the torque gone and re-arms on
        ``~/reset``."""
        with self.lock:
            self.world.reset()
            self._applied = None
            for servo in self.servos:
                servo.reboot()
            self._refresh_present()
            for servo in self.servos:
                servo.set('goal_position', servo.get('present_position'))

    # ---------------------------------------------------------------------------------------
    # Running

    def _stopped(self, *events: threading.Event | None) -> bool:
        return self._stop.is_set() or any(e is not None and e.is_set() for e in events)

    def _real_time_loop(self, stop: threading.Event | None, done: threading.Event) -> None:
        next_deadline = time.monotonic() + self.period_s
        while not self._stopped(stop, done):
            now = time.monotonic()
            if now - next_deadline > self.period_s:
                self.stats.missed_deadlines += 1
                next_deadline = now  # never catch up a backlog
            elif next_deadline > now:
                time.sleep(next_deadline - now)
            self.cycle()
            next_deadline += self.period_s

    def run(self, stop: threading.Event | None = None) -> None:
        """Serve the bus (and, in real time, step the world) until :meth:`stop` or ``stop``.

        Parameters
        ----------
        stop
            An extra stop request.
        """
        with self._running:
            done = threading.Event()
            physics = None
            if not self.sim_time:
                physics = threading.Thread(target=self._real_time_loop, args=(stop, done),
                                           name='dynamixel-physics', daemon=True)
                physics.start()
            try:
                while not self._stopped(stop):
                    self.bus.poll()
            finally:
                done.set()
                if physics is not None:
                    physics.join()

    def stop(self) -> None:
        """Ask :meth:`run` to return (within a few tens of milliseconds)."""
        self._stop.set()

    def close(self) -> None:
        """Stop, close the bus (pty and link) and the world (idempotent)."""
        self._stop.set()
        acquired = self._running.acquire(timeout=2.0)
        try:
            self.bus.close()
            with self.lock:
                self.world.close()
        finally:
            if acquired:
                self._running.release()

    # ---------------------------------------------------------------------------------------
    # The bus's options and fault injection

    @property
    def watchdog_feed(self) -> str:
        """``'addressed'`` or ``'any'``: which packets feed a servo's Bus Watchdog."""
        return self.bus.watchdog_feed

    @property
    def crc_error_ids(self) -> frozenset[int]:
        """IDs whose status packets carry a corrupted CRC (see :class:`DynamixelBus`)."""
        return self.bus.crc_error_ids

    @crc_error_ids.setter
    def crc_error_ids(self, ids: Iterable[int]) -> None:
        self.bus.crc_error_ids = ids

    @property
    def silent_ids(self) -> frozenset[int]:
        """IDs that never answer."""
        return self.bus.silent_ids

    @silent_ids.setter
    def silent_ids(self, ids: Iterable[int]) -> None:
        self.bus.silent_ids = ids

    @property
    def status_delay_s(self) -> float:
        """Extra delay of every status packet [s]."""
        return self.bus.status_delay_s

    @status_delay_s.setter
    def status_delay_s(self, delay_s: float) -> None:
        self.bus.status_delay_s = delay_s

    def hardware_error(self, servo_id: int, bits: int) -> None:
        """Set Hardware Error Status ``bits`` on servo ``servo_id`` (see
        :meth:`DynamixelBus.hardware_error`).

        Raises
        ------
        KeyError
            No servo has this ID.
        ValueError
            ``bits`` is not a byte.
        """
        self.bus.hardware_error(servo_id, bits)

    def __enter__(self) -> DynamixelStandIn:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
