"""The UDP device link as a :class:`~dam_hand_driver.device.HandDevice` (no rclpy).

State frames in, command frames out (``docs/device_protocol.md``); raw device units are
converted with the configured :class:`~dam_common.device_protocol.Calibration`. The device runs
the impedance law itself (MODE_IMPEDANCE is sent as such) and has its own watchdog.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dam_common.config import DamConfig
from dam_common.device_protocol import Calibration, DeviceStatus, JointMode, StateFrame
from dam_common.errors import DeviceParameterError
from dam_hand_driver.device import CommandItemLike, HandDevice, JointSample
from dam_hand_driver.link import DeviceLink


def gains_error(items: Sequence[CommandItemLike], calibration: Calibration) -> str | None:
    """Impedance gains the link cannot carry (e.g. a stiffness below one raw unit of the
    calibration), which would fail every frame after the command was taken; ``None``: none.
    """
    n = calibration.n_joints
    modes = np.full(n, int(JointMode.HOLD), dtype=np.int64)
    stiffness = np.zeros(n)
    damping = np.zeros(n)
    for item in items:
        if int(item.mode) == int(JointMode.IMPEDANCE):
            modes[item.joint] = int(JointMode.IMPEDANCE)
            stiffness[item.joint] = item.stiffness
            damping[item.joint] = item.damping
    try:
        calibration.gains_raw(modes, stiffness, damping)
    except DeviceParameterError as exc:
        return f'impedance gains the device link cannot carry: {exc}'
    return None


class UdpDevice(HandDevice):
    """A hand (or the PyBullet stand-in) on the UDP device link.

    Parameters
    ----------
    config
        ``device`` gives the addresses, the rate and the calibration.

    Raises
    ------
    ParameterError
        A port outside [0, 65535].
    OSError
        The state port is in use.
    """

    kind = 'udp'

    def __init__(self, config: DamConfig) -> None:
        dev = config.device
        self.calibration = Calibration.from_config(config)
        self.n = self.calibration.n_joints
        self.link = DeviceLink(self.n, dev.host, dev.state_port, dev.command_port)
        self.period_s = 1.0 / float(dev.rate_hz)
        self.hardware_id = f'{dev.host}:{dev.command_port}'
        self._newest: StateFrame | None = None

    @property  # type: ignore[override]
    def last_sample_time(self) -> float | None:
        return self.link.last_state_time

    def receive(self, timeout_s: float) -> JointSample | None:
        frame = self.link.receive(timeout_s)
        if frame is None:
            return None
        self._newest = frame
        q, dq, tau = self.calibration.state_si(frame)
        return JointSample(seq=int(frame.seq), stamp_ns=int(frame.timestamp_ns), position=q,
                           velocity=dq, effort=tau,
                           simulated=bool(frame.status & DeviceStatus.SIMULATED),
                           watchdog_tripped=bool(frame.status & DeviceStatus.WATCHDOG_TRIPPED))

    def send(self, sample: JointSample, modes: np.ndarray, setpoints: np.ndarray,
             stiffness: np.ndarray, damping: np.ndarray) -> None:
        raw = self.calibration.setpoints_raw(modes, setpoints)
        k_raw, d_raw = self.calibration.gains_raw(modes, stiffness, damping)
        self.link.send(modes, raw, sample.seq, k_raw, d_raw)

    def command_error(self, items: Sequence[CommandItemLike]) -> str | None:
        return gains_error(items, self.calibration)

    def resend(self) -> bool:
        return self.link.resend()

    def restart_sequence(self) -> None:
        self.link.reset()

    def diagnostics(self) -> dict[str, str]:
        values = {'commands_sent': str(self.link.stats.commands_sent),
                  'send_errors': str(self.link.stats.send_errors)}
        values.update({f'frames_{k}': str(v)
                       for k, v in self.link.decoder.counters.as_dict().items()})
        return values

    @property  # type: ignore[override]
    def samples_received(self) -> int:
        return int(self.link.decoder.counters.accepted)

    def close(self) -> None:
        self.link.close()
