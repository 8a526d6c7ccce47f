"""Which device answers on the configured device link: a real hand, a simulated one, or none.

Run with the workspace sourced (``source scripts/env.sh``)::

    python scripts/lib/probe_device.py [--timeout S]

It binds the configured state port (``device.state_port`` of the configuration that
``dam_common.config.load_config`` finds: ``DAM_CONFIG`` or the installed ``config/dam.yaml``),
listens for up to ``device.probe_timeout_s`` [s] (or ``--timeout``) for one valid state frame,
closes the port again (only one process can bind it: the driver binds it next) and prints one
line ``KIND<TAB>description`` on stdout, ``KIND`` one of

``hardware``
    a state frame without the ``SIMULATED`` status bit arrived: a real hand;
``simulated``
    a state frame with the ``SIMULATED`` bit arrived: a stand-in already runs;
``nothing``
    no valid state frame within the time.

Exit status 0 for all three; 1 (with one line on stderr) when the configuration cannot be
read or the state port cannot be bound (a driver already runs?). Sends nothing to the device.
"""

from __future__ import annotations

import argparse
import math
import sys


def main(argv: list[str] | None = None) -> int:
    """Probe the device link once; see the module docstring. Returns the exit status."""
    parser = argparse.ArgumentParser(prog='probe_device', description=__doc__.splitlines()[0])
    parser.add_argument('--timeout', type=float, metavar='S',
                        help='listen this long [s] (default: device.probe_timeout_s)')
    args = parser.parse_args(argv)

    from dam_common.config import load_config
    from dam_common.device_protocol import DeviceStatus
    from dam_common.errors import DamCommonError
    from dam_hand_driver.link import DeviceLink

    try:
        config = load_config()
    except DamCommonError as exc:
        print(f'probe_device: cannot read the configuration: {exc}', file=sys.stderr)
        return 1
    dev = config.device
    timeout_s = float(dev.probe_timeout_s) if args.timeout is None else args.timeout
    if not math.isfinite(timeout_s) or timeout_s < 0.0:
        print(f'probe_device: --timeout must be a finite number >= 0, got {timeout_s!r}',
              file=sys.stderr)
        return 1
    where = f'{dev.host}:{dev.command_port} (state frames to port {dev.state_port})'
    try:
        link = DeviceLink(len(config.hand.joint_names), dev.host, dev.state_port,
                          dev.command_port)
    except OSError as exc:
        print(f'probe_device: cannot bind the state port {dev.state_port} ({exc}): '
              'is a driver already running?', file=sys.stderr)
        return 1
    try:
        frame = link.receive(timeout_s)
    finally:
        link.close()
    if frame is None:
        print(f'nothing\tno device answered at {where} within {timeout_s:g} s')
    elif frame.status & DeviceStatus.SIMULATED:
        print(f'simulated\ta simulated device (stand-in) answers at {where}')
    else:
        print(f'hardware\ta hand answers at {where}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
