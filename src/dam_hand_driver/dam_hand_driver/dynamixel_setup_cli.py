"""The command line of ``dynamixel_setup``, the scan's report and the zero offsets' overlay.

:mod:`dam_hand_driver.dynamixel_setup` (which catches the stop signals before this module and
its imports load) calls :func:`run_command`: it parses the command line, loads the
configuration and the SDK, opens the bus and runs the subcommand. ``scan`` and ``zero`` are
here (what the scan found against ``dynamixel.servos``, the overlay file); the bus and what
``fix``, ``set-id`` and ``zero`` do on it are in :mod:`dam_hand_driver.dynamixel_setup_bus`.
No rclpy.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import tempfile
import textwrap
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from dam_common.command_line import CommandLineParser
from dam_common.config import default_config_path, load_config
from dam_common.dynamixel_config import POSITION_RAD_PER_COUNT
from dam_common.errors import ConfigError
from dam_common.shutdown import SHUTDOWN
from dam_common.words import counted
from dam_hand_driver import dynamixel_port
from dam_hand_driver.dynamixel_setup_bus import (
    BAUD_RATE_CODES,
    MAX_ID,
    RETURN_DELAY_UNIT_S,
    ZERO_HELP,
    Bus,
    Context,
    FoundServo,
    ScanResult,
    SetupError,
    baud_rate_order,
    id_ranges,
    model_name,
    model_text,
    no_servo_message,
    read_zero,
    run_fix,
    run_set_id,
    scan_bus,
    servo_label,
    supported_models,
)
from dam_hand_driver.dynamixel_setup_exit import EXIT_FAILED, EXIT_OK, EXIT_USAGE, PROG, refuse
from dam_hand_driver.dynamixel_table import hardware_error_names
from dam_hand_driver.errors import HandDriverError

if TYPE_CHECKING:
    from dam_common.dynamixel_config import DynamixelConfig


class UsageError(Exception):
    """A usage error found after parsing (exit status 2); the message is the line printed."""


# -------------------------------------------------------------------------------------------
# The scan's report


def compare(result: ScanResult, dxl: DynamixelConfig, port: str) -> list[str]:
    """What differs between the servos found and ``dynamixel.servos``, each with its fix.

    Parameters
    ----------
    result
        The scan.
    dxl
        The configuration's ``dynamixel:`` section.
    port
        The port scanned (for the commands suggested).

    Returns
    -------
    list of str
        One line per problem (empty: the bus matches).
    """
    by_id: dict[int, list[FoundServo]] = {}
    for servo in result.servos:
        by_id.setdefault(servo.servo_id, []).append(servo)
    tried = ', '.join(str(r) for r in result.baud_rates)
    configured_tried = dxl.baud_rate in result.baud_rates
    problems: list[str] = []
    elsewhere: dict[tuple[int, ...], list[tuple[int, str]]] = {}  # rates -> (ID, joint)
    for cfg in dxl.servos:
        label = servo_label(cfg.servo_id, cfg.joint)
        entries = by_id.get(cfg.servo_id, [])
        if not entries:
            problems.append(
                f'{label} does not answer at any baud rate tried ({tried} bit/s): check its '
                f'cable and supply, or give the servo of that joint ID {cfg.servo_id} '
                f'({PROG} set-id)')
            continue
        if len(entries) > 1:
            models = ' and '.join(model_text(e.model_number) for e in entries)
            problems.append(f'{label}: two servos answer as ID {cfg.servo_id} ({models}): give '
                            f'each servo its own ID ({PROG} set-id, one servo on the bus)')
            continue
        found = entries[0]
        name = model_name(found.model_number)
        if name is None:
            problems.append(f'{label} is {model_text(found.model_number)} (supported: '
                            f'{supported_models()})')
        elif name != cfg.model:
            problems.append(
                f'{label} is {model_text(found.model_number)}, the configuration says '
                f'{cfg.model} ({cfg.spec.model_number}): set dynamixel.servos.{cfg.joint}.model '
                f'to {name} (and check its current_limit_a and torque_constant_nm_per_a), or '
                f'fit a {cfg.model}')
        if configured_tried and dxl.baud_rate not in found.baud_rates:
            elsewhere.setdefault(found.baud_rates, []).append((cfg.servo_id, cfg.joint))
    for rates, servos in elsewhere.items():
        at = ', '.join(str(r) for r in rates)
        who = (f'{servo_label(*servos[0])} answers' if len(servos) == 1 else
               f'servos ID {id_ranges([i for i, _ in servos])} answer')
        problems.append(
            f'{who} at {at} bit/s, not at dynamixel.baud_rate {dxl.baud_rate}: {PROG} fix '
            f'--port {port} writes the Baud Rate (address 8) '
            f'{BAUD_RATE_CODES.get(dxl.baud_rate, "?")} with torque off (or set '
            f'dynamixel.baud_rate to the rate every servo answers at)')
    configured = {cfg.servo_id for cfg in dxl.servos}
    for servo_id, entries in sorted(by_id.items()):
        if servo_id in configured:
            continue
        models = ' and '.join(model_text(e.model_number) for e in entries)
        problems.append(
            f'{servo_label(servo_id, None)} ({models}) is no joint\'s servo in '
            f'dynamixel.servos: give it the ID of its joint ({PROG} set-id --id {servo_id} '
            f'--new-id N) or add it to the configuration')
    return problems


def rate_notes(result: ScanResult, port: str, timer_ms: int | None,
               latency_fix: str) -> list[str]:
    """The settings that slow the bus down, each with its fix (empty: none).

    Parameters
    ----------
    result
        The scan.
    port
        The port scanned.
    timer_ms
        The USB adapter's latency timer [ms] (``None``: not a USB adapter, or unknown).
    latency_fix
        The command that sets it to 1 ms.
    """
    notes: list[str] = []
    slow = [s for s in result.servos if s.return_delay_raw]
    if slow:
        delays = {s.return_delay_raw or 0 for s in slow}
        each = (f'{delays.pop() * RETURN_DELAY_UNIT_S * 1e6:g} us each' if len(delays) == 1
                else 'up to ' + f'{max(delays) * RETURN_DELAY_UNIT_S * 1e6:g} us')
        total_ms = sum(s.return_delay_raw or 0 for s in slow) * RETURN_DELAY_UNIT_S * 1e3
        notes.append(
            f'Return Delay Time (address 9) is not 0 on ID '
            f'{id_ranges([s.servo_id for s in slow])} ({each}): a sync read of them waits '
            f'{total_ms:.2f} ms for it; fix: write 0 to address 9 with torque off: {PROG} fix '
            f'--port {port}')
    if timer_ms is not None and timer_ms > 1:
        notes.append(f'the USB adapter\'s latency timer of {port} is {timer_ms} ms: each '
                     f'transaction may wait that long; fix: {latency_fix}')
    return notes


def servo_table(servos: Sequence[FoundServo], joints: Mapping[int, str]) -> list[str]:
    """The scan's list: one line per servo under a header, in aligned columns."""
    rows = [('ID', 'model', 'firmware', 'bit/s', 'Return Delay', 'HW error', 'joint')]
    for servo in servos:
        name = model_name(servo.model_number)
        model = (f'{name} ({servo.model_number})' if name is not None
                 else model_text(servo.model_number))
        delay = '-'
        if servo.return_delay_raw is not None:
            us = servo.return_delay_raw * RETURN_DELAY_UNIT_S * 1e6
            delay = f'{us:g} us ({servo.return_delay_raw})'
        error = '-' if servo.hardware_error is None else str(servo.hardware_error)
        if servo.hardware_error:
            error += f' ({hardware_error_names(servo.hardware_error)})'
        rows.append((str(servo.servo_id), model, str(servo.firmware_version),
                     ', '.join(str(r) for r in servo.baud_rates), delay, error,
                     joints.get(servo.servo_id, 'no joint')))
    widths = [max(len(row[k]) for row in rows) for k in range(len(rows[0]))]
    return ['  ' + '  '.join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
            for row in rows]


# -------------------------------------------------------------------------------------------
# scan and zero


def run_scan(ctx: Context, bus: Bus) -> int:
    """``scan``: list the servos and compare them with the configuration."""
    ctx.say(f'scanning {ctx.port} at ' + ', '.join(str(r) for r in ctx.baud_rates)
            + f' bit/s (configuration {ctx.config.source}: dynamixel.baud_rate '
            f'{ctx.dxl.baud_rate})')
    result = scan_bus(bus, ctx.baud_rates, ctx.say)
    if not result.servos:
        raise SetupError(no_servo_message(ctx.port, ctx.baud_rates))
    if any(len(servo.baud_rates) > 1 for servo in result.servos):
        ctx.say('note: an ID answered at several baud rates: a real servo answers at its own '
                'only, so several servos share that ID, or this port ignores the baud rate (a '
                'pseudo-terminal)')
    ctx.say(f'{counted(len(result.servos), "servo")}:')
    for line in servo_table(result.servos, ctx.joints()):
        ctx.say(line)
    notes = rate_notes(result, ctx.port, dynamixel_port.usb_latency_timer_ms(ctx.port),
                       dynamixel_port.latency_timer_fix(ctx.port))
    for note in notes:
        ctx.say(f'to do: {note}')
    problems = compare(result, ctx.dxl, ctx.port)
    if ctx.dxl.baud_rate not in result.baud_rates:
        ctx.say(f'note: dynamixel.baud_rate {ctx.dxl.baud_rate} was not tried (--baud-rate)')
    if not problems:
        ctx.say(f'the bus matches dynamixel.servos of {ctx.config.source} '
                f'({len(ctx.dxl.servos)} servos at {ctx.dxl.baud_rate} bit/s)')
        return EXIT_OK
    ctx.say(f'the bus does not match dynamixel.servos of {ctx.config.source}:')
    for problem in problems:
        ctx.say(f'  - {problem}')
    raise SetupError(problems[0] if len(problems) == 1
                     else f'{len(problems)} differences from dynamixel.servos (listed above), '
                     f'the first: {problems[0]}')


def run_zero(ctx: Context, bus: Bus, output: Path, section: bool, force: bool) -> int:
    """``zero``: read Present Position of every configured servo and write the overlay."""
    check_output(output, ctx.config_path, force)
    rate, models, positions = read_zero(ctx, bus, section)
    data = overlay_data(ctx.dxl, positions, section=section, port=ctx.port, baud_rate=rate,
                        models=models)
    text = overlay_text(data, ctx, rate, output)
    write_overlay(output, text, ctx.config_path, ctx.overlays, force)

    for cfg in ctx.dxl.servos:
        counts = positions[cfg.servo_id]
        moved = math.degrees((counts - cfg.zero_offset_counts) * POSITION_RAD_PER_COUNT)
        ctx.say(f'  {cfg.joint}: zero_offset_counts {counts} (configured '
                f'{cfg.zero_offset_counts}: {moved:+.1f} deg from it)')
    ctx.say(f'wrote {output}; use it: {driver_command(ctx, output, section=section)}')
    return EXIT_OK


# -------------------------------------------------------------------------------------------
# The overlay


def overlay_data(dxl: DynamixelConfig, positions: Mapping[int, int], *, section: bool,
                 port: str, baud_rate: int, models: Mapping[int, str]) -> dict[str, Any]:
    """The overlay's mapping.

    Parameters
    ----------
    dxl
        The configuration's ``dynamixel:`` section.
    positions
        ID -> Present Position read [counts].
    section
        Write the whole section: ``port``, ``baud_rate`` [bit/s] and ``models`` (ID -> the
        model found) as given, the other keys from ``dxl``; else the zero offsets only.
    port, baud_rate, models
        See ``section``.
    """
    servos: dict[str, dict[str, Any]] = {}
    for cfg in dxl.servos:
        if section:
            servos[cfg.joint] = {
                'id': cfg.servo_id, 'model': models.get(cfg.servo_id, cfg.model),
                'direction': cfg.direction, 'zero_offset_counts': positions[cfg.servo_id],
                'torque_constant_nm_per_a': cfg.torque_constant_nm_per_a,
                'current_limit_a': cfg.current_limit_a}
        else:
            servos[cfg.joint] = {'zero_offset_counts': positions[cfg.servo_id]}
    if not section:
        return {'dynamixel': {'servos': servos}}
    return {'dynamixel': {
        'port': port, 'baud_rate': int(baud_rate), 'rate_hz': dxl.rate_hz,
        'bus_watchdog_s': dxl.bus_watchdog_s,
        'hold_stiffness_nm_per_rad': dxl.hold_stiffness_nm_per_rad,
        'hold_damping_nms_per_rad': dxl.hold_damping_nms_per_rad, 'servos': servos}}


def driver_command(ctx: Context, output: Path, *, section: bool) -> str:
    """The driver's command line with the overlay (and the port, unless the overlay or the
    configuration holds it)."""
    port = '' if section or ctx.dxl.port == ctx.port else f' -p port:={ctx.port}'
    # Absolute: a driver started from another directory (a launch file, a service) finds it.
    return (f'hand_driver --ros-args -p backend:=dynamixel -p config_overlay:='
            f'{output.absolute()}{port}')


def overlay_text(data: Mapping[str, Any], ctx: Context, baud_rate: int, output: Path) -> str:
    """The overlay file: comment lines saying what it is and how to use it, then the YAML.

    Parameters
    ----------
    data
        The overlay's mapping (:func:`overlay_data`).
    ctx
        The command's context (port, configuration, the overlays below this one).
    baud_rate
        Where the servos were read [bit/s].
    output
        The file's path, as the user gave it (for the usage lines).
    """
    stamp = time.strftime('%Y-%m-%d %H:%M:%S %z')
    header = [
        f'Zero offsets of a Dynamixel hand, by `{PROG} zero` on {stamp}:',
        'Present Position (address 132) of each joint\'s servo with every finger held',
        f'straight (joint angle 0), read on {ctx.port} at {baud_rate} bit/s.',
        f'A configuration overlay of {ctx.config.source}:',
        'it replaces the keys below and keeps every other one. Use it:',
        f'  {driver_command(ctx, output, section="port" in data["dynamixel"])}',
        f'  dam_common.config.load_config(path, [\'{output.absolute()}\'])  (Python)',
        f'Check the hand against it: {PROG} scan --port {ctx.port} --overlay {output}',
    ]
    if ctx.overlays:
        below = ', '.join(str(o) for o in ctx.overlays)
        which = 'overlay' if len(ctx.overlays) == 1 else 'overlays'
        header.append(f'Made on top of the {which} {below}: give them first, this one last.')
    body = yaml.safe_dump(dict(data), sort_keys=False, default_flow_style=False)
    return ''.join(f'# {line}\n' for line in header) + body


def check_output(output: Path, config_path: Path, force: bool) -> None:
    """Refuse an output that exists (without ``force``) or is the configuration file.

    Raises
    ------
    SetupError
        Said why.
    """
    with contextlib.suppress(OSError):
        if output.resolve() == config_path.resolve():
            raise SetupError(f'{output} is the configuration file itself: write the overlay '
                             f'to a file of its own')
    if output.exists() and not force:
        raise SetupError(f'{output} exists: give --force to replace it')
    if output.is_dir():
        raise SetupError(f'{output} is a directory: give a file name (-o zero.yaml)')


def write_overlay(output: Path, text: str, config_path: Path, overlays: Sequence[Path],
                  force: bool) -> None:
    """Write ``text`` to ``output`` atomically, after ``load_config(config_path, [*overlays,
    output])`` accepted it: a temporary file beside ``output`` is checked, then renamed
    (``force``) or linked (never over an existing file).

    Raises
    ------
    SetupError
        The loader refuses it (its message), the file exists (without ``force``), or it
        cannot be written.
    """
    check_output(output, config_path, force)
    directory = output.parent
    try:
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=f'.{output.name}.', suffix='.tmp')
    except OSError as exc:
        raise SetupError(f'cannot write {output}: {exc.strerror or exc}') from exc
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        try:
            load_config(config_path, [*overlays, tmp])
        except ConfigError as exc:
            message = ' '.join(str(exc).replace(tmp, str(output)).split())
            raise SetupError(f'the overlay would not load, {output} not written: '
                             f'{message}') from exc
        SHUTDOWN.raise_if_requested()
        umask = os.umask(0o022)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        if force:
            os.replace(tmp, output)
        else:
            try:
                os.link(tmp, output)  # fails, atomically, if output exists
            except FileExistsError as exc:
                raise SetupError(f'{output} exists: give --force to replace it') from exc
            except OSError:  # a file system without hard links
                if output.exists():
                    raise SetupError(f'{output} exists: give --force to replace it') from None
                os.replace(tmp, output)
    except OSError as exc:
        raise SetupError(f'cannot write {output}: {exc.strerror or exc}') from exc
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)


# -------------------------------------------------------------------------------------------
# Command line


def _baud_rate(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value not in BAUD_RATE_CODES:
        raise argparse.ArgumentTypeError(
            f'{text!r} is not a baud rate of the X series the SDK can set '
            f'({", ".join(str(r) for r in BAUD_RATE_CODES)})')
    return value


def _servo_id(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_ID:
        raise argparse.ArgumentTypeError(f'{text!r} is not a servo ID (0..{MAX_ID})')
    return value


EXIT_HELP = """\
exit status: 0 done (scan: the bus matches the configuration); 1 an operation failed (port
missing, busy or gone, no servo answering, a servo missing or of an unknown or another model,
the bus not matching the configuration, the overlay zero made refused by the loader, a file
that exists); 2 a usage error (no port given and dynamixel.port empty, an option given twice,
a configuration or a given --overlay that does not load); 130 SIGINT or SIGTERM. Torque is
never switched on."""


def _wrap(text: str) -> str:
    """A help paragraph wrapped at 79 columns (the help keeps the epilog's own lines)."""
    return textwrap.fill(' '.join(text.split()), width=79)


def build_parser() -> CommandLineParser:
    """The command line (subcommands scan, fix, set-id, zero)."""
    common = CommandLineParser(add_help=False)
    common.add_argument('--port', metavar='DEV',
                        help='the serial device (default: dynamixel.port of the configuration)')
    common.add_argument('--baud-rate', type=_baud_rate, nargs='+', metavar='B',
                        help='baud rates to try [bit/s], in order (default: '
                        'dynamixel.baud_rate, then the others of 57600 .. 4000000)')
    common.add_argument('--config', type=Path, metavar='FILE',
                        help='the configuration (default: the suite\'s dam.yaml)')
    common.add_argument('--overlay', type=Path, action='append', default=[], metavar='FILE',
                        help='a configuration overlay on top of it (repeatable)')
    formatter = argparse.RawDescriptionHelpFormatter
    parser = CommandLineParser(
        prog=PROG, formatter_class=formatter, epilog=EXIT_HELP,
        description=_wrap('Set up a new hand of Dynamixel X servos (Protocol 2.0) for the driver '
        '(docs/dynamixel.md): find the servos, fix what slows the bus, set IDs, read the zero '
        'offsets.'))
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    sub.add_parser(
        'scan', parents=[common], formatter_class=formatter, epilog=EXIT_HELP,
        help='list the servos at each baud rate and compare them with the configuration',
        description=_wrap('Broadcast-ping at each baud rate; list ID, model, firmware, Return '
        'Delay Time and hardware errors of each servo found, the USB latency timer, and what '
        'differs from dynamixel.servos (with what to change). Reads only.'))
    fix = sub.add_parser(
        'fix', parents=[common], formatter_class=formatter, epilog=EXIT_HELP,
        help='torque off, Return Delay Time 0 and the configured Baud Rate on every servo',
        description=_wrap('Scan, then write to every servo found (torque off first: the '
        'fingers go limp): Return Delay Time 0, and Baud Rate = dynamixel.baud_rate (or '
        '--to-baud-rate) to a servo that does not answer at it. The USB latency timer needs '
        'root: scan prints the command.'))
    fix.add_argument('--to-baud-rate', type=_baud_rate, metavar='B',
                     help='the baud rate to set [bit/s] (default: dynamixel.baud_rate)')
    set_id = sub.add_parser(
        'set-id', parents=[common], formatter_class=formatter, epilog=EXIT_HELP,
        help='give one servo another ID (torque off)',
        description=_wrap('Find servo --id at the baud rates tried, switch its torque off and '
        'write ID --new-id (address 7). New servos all come as ID 1 at 57600 bit/s: connect them '
        'one at a time.'))
    set_id.add_argument('--id', type=_servo_id, required=True, metavar='OLD', dest='old_id')
    set_id.add_argument('--new-id', type=_servo_id, required=True, metavar='NEW')
    zero = sub.add_parser(
        'zero', parents=[common], formatter_class=formatter, epilog=EXIT_HELP,
        help='fingers held straight: write the zero offsets as a configuration overlay',
        description=_wrap(f'{ZERO_HELP}. Reads Present Position (address 132) of every configured '
        'servo in one sync read and writes a configuration overlay with dynamixel.servos.'
        '<joint>.zero_offset_counts, after checking that the configuration with it loads '
        '(joint limits inside the encoder\'s 0..4095 counts). Use it: hand_driver --ros-args '
        '-p backend:=dynamixel -p config_overlay:=FILE. Reads only.'))
    zero.add_argument('-o', '--output', type=Path, required=True, metavar='FILE',
                      help='the overlay to write (YAML)')
    zero.add_argument('--section', action='store_true',
                      help='write the whole dynamixel: section: the port, the baud rate and '
                      'the models found, the other keys from the configuration')
    zero.add_argument('--force', action='store_true', help='replace FILE if it exists')
    return parser


def _context(args: argparse.Namespace, say: Callable[[str], None]) -> Context:
    """Load the configuration and the SDK; resolve the port and the baud rates.

    Raises
    ------
    UsageError
        The configuration does not load or has no ``dynamixel:`` section; no port.
    SetupError
        The SDK is missing.
    """
    try:
        config_path = Path(args.config) if args.config else default_config_path()
        config = load_config(config_path, args.overlay)
    except ConfigError as exc:
        raise UsageError(' '.join(str(exc).split())) from exc
    dxl = config.dynamixel
    if dxl is None:
        raise UsageError(f'the configuration {config.source} has no dynamixel: section '
                         f'(docs/dynamixel.md)')
    port = args.port or dxl.port
    if not port:
        raise UsageError(f'no port: give --port DEV (dynamixel.port is empty in '
                         f'{config.source}; ls /dev/serial/by-id/ /dev/ttyUSB*)')
    try:
        import dynamixel_sdk  # noqa: PLC0415
    except ImportError as exc:
        raise SetupError(f'needs the dynamixel-sdk package (pip install dynamixel-sdk): '
                         f'{exc}') from exc
    return Context(sdk=dynamixel_sdk, config=config, dxl=dxl, config_path=config_path,
                   overlays=tuple(Path(p) for p in args.overlay), port=str(port),
                   baud_rates=baud_rate_order(dxl.baud_rate, args.baud_rate), say=say)


def _say(line: str) -> None:
    print(line, flush=True)


def _run(args: argparse.Namespace) -> int:
    ctx = _context(args, _say)
    if args.command == 'set-id' and args.old_id == args.new_id:
        raise UsageError(f'--id and --new-id are both {args.old_id}')
    bus = ctx.open()
    try:
        if args.command == 'scan':
            return run_scan(ctx, bus)
        if args.command == 'fix':
            return run_fix(ctx, bus, args.to_baud_rate or ctx.dxl.baud_rate)
        if args.command == 'set-id':
            return run_set_id(ctx, bus, args.old_id, args.new_id)
        return run_zero(ctx, bus, args.output, args.section, args.force)
    finally:
        bus.close()


def run_command(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` and run the subcommand.

    :class:`~dam_common.shutdown.StartupInterrupted` (a stop signal) goes through to
    :func:`dam_hand_driver.dynamixel_setup.main`, the port closed and no temporary file left.

    Parameters
    ----------
    argv
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status (:mod:`dam_hand_driver.dynamixel_setup`).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_USAGE
    try:
        return _run(args)
    except UsageError as exc:
        refuse(f'{args.command}: {exc}')
        return EXIT_USAGE
    except (HandDriverError, OSError) as exc:  # SetupError, PortBusyError, pyserial's
        refuse(f'{args.command}: {exc}')
        return EXIT_FAILED
