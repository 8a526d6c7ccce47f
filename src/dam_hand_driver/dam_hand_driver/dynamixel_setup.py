"""``dynamixel_setup``: set up a new hand of Dynamixel X servos (Protocol 2.0) for the driver.

Subcommands (each takes ``--port DEV``, default ``dynamixel.port``; ``--baud-rate B [B ...]``,
default every X-series rate of :data:`dam_common.dynamixel_config.BAUD_RATES`, the configured
one first; ``--config FILE`` and ``--overlay FILE``, the configuration to compare with)::

    dynamixel_setup scan                      # list the servos, compare with dynamixel.servos
    dynamixel_setup fix                       # Return Delay Time 0, Baud Rate as configured
    dynamixel_setup set-id --id 1 --new-id 5  # give one servo another ID
    dynamixel_setup zero -o zero.yaml         # fingers held straight: the zero offsets

``scan`` broadcast-pings at each baud rate and lists each servo that answers: ID, model
(``unknown model N: not supported`` for a model outside
:data:`dam_common.dynamixel_config.MODELS`), firmware version, Return Delay Time (address 9,
2 us units; the fix when it is not 0) and Hardware Error Status; then the USB adapter's latency
timer when above 1 ms, and what differs from the configuration's ``dynamixel.servos`` (a
servo missing, of another model, at another baud rate than ``dynamixel.baud_rate``, an ID of
no joint), each with what to change. ``fix`` writes, with torque off, Return Delay Time 0 and
(to a servo that does not answer at it) the Baud Rate of ``dynamixel.baud_rate`` (or
``--to-baud-rate``) to every servo found. ``set-id`` writes a servo's ID (address 7) with
torque off. ``zero`` reads Present Position (address 132) of every configured servo in one
sync read while a person holds the fingers straight (joint angle 0) and writes a
configuration overlay with ``dynamixel.servos.<joint>.zero_offset_counts`` (``--section``:
the whole ``dynamixel:`` section, with the port, the baud rate and the models found), after
checking that ``dam_common.config.load_config(config, [overlay])`` accepts it; the file is
written atomically and an existing one is replaced only with ``--force``.

The port is opened with :func:`dam_hand_driver.dynamixel_port.open_port`: exclusively, so that
a port another program holds (a running driver) is refused naming its PID. Torque is never
switched on: ``fix`` and ``set-id`` switch it off (the EEPROM can only be written then), ``scan``
and ``zero`` only read.

Exit status: 0 done (``scan``: the bus matches the configuration); 1 an operation failed (the
port missing, busy or gone, no servo answering, a servo missing or of an unknown or another
model, the bus not matching the configuration, the overlay ``zero`` made refused by the
loader, a file that exists): one line on stderr says why; 2 a usage error (a missing or
repeated option, no port given and ``dynamixel.port`` empty, a configuration or a given
``--overlay`` that does not load); 130 SIGINT or SIGTERM
stopped it (one line, no traceback, the port closed, no file half-written).

Modules, imports one way: this entry point catches the signals, then loads the command line,
the scan's report and the overlay (:mod:`dam_hand_driver.dynamixel_setup_cli`), which drive the
bus and its operations (:mod:`dam_hand_driver.dynamixel_setup_bus`); all three take the exit
statuses from :mod:`dam_hand_driver.dynamixel_setup_exit`.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence  # not typing: one import less before the signals are caught

from dam_common.closed_output import quiet_when_output_closed
from dam_common.shutdown import SHUTDOWN, StartupInterrupted
from dam_hand_driver.dynamixel_setup_exit import EXIT_INTERRUPTED, refuse


@quiet_when_output_closed  # `| head`: status 141, no traceback
def main(argv: Sequence[str] | None = None) -> int:
    """Run the command (module docstring); returns the exit status.

    The stop signals are caught first (:meth:`dam_common.shutdown.ShutdownRequest.interruptible`:
    the first one raises :class:`~dam_common.shutdown.StartupInterrupted` wherever the command
    is, later ones wait for the clean-up; the handlers from before come back at the end); the
    work (:mod:`dam_hand_driver.dynamixel_setup_cli`: the SDK, the configuration, numpy) is
    imported after, so that a signal at any moment from here on ends the command with one line
    and status 130.

    Parameters
    ----------
    argv
        The arguments (default: ``sys.argv[1:]``).
    """
    with SHUTDOWN.interruptible():
        try:
            from dam_hand_driver.dynamixel_setup_cli import run_command  # noqa: PLC0415

            return run_command(argv)
        except (StartupInterrupted, KeyboardInterrupt):
            pass  # a stop signal (KeyboardInterrupt: Python's own handling of SIGINT)
        except Exception:
            if not SHUTDOWN.requested:
                raise
            # the interrupt surfaced as another error (a C extension's init wraps it)
        refuse('interrupted (torque as it was; the port closed)')
        return EXIT_INTERRUPTED


if __name__ == '__main__':
    sys.exit(main())
