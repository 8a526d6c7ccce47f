"""DAM grasp experiment in lockstep: :class:`HandWorld` and the controller core, no ROS.

:func:`run_experiment` steps a :class:`~dam_sim_bridge.world.HandWorld` and a
:class:`~dam_spcm_controller.sequence.DamSequence` together at the device rate
(``device.rate_hz``): each cycle the sequence sees the joint state and its command reaches the
world ``latency_cycles`` later, its TORQUE setpoints and IMPEDANCE equilibria slew-limited as
the driver does (:class:`~dam_hand_driver.slew.CommandSlew`,
``device.torque_rate_limit_nm_per_s``). IMPEDANCE commands (the default,
``controller.impedance_on_device``) reach the world with their equilibrium and gains, and the
world runs the law at every physics step, and slews every torque, exactly as the stand-in
device does (:meth:`HandWorld.set_joint_commands`). It returns the controller's end phase, the
outcome as the controller would classify it from joint signals alone with the rise it
estimates, the ground truth (whether and when the object left the table, whether it was off it
at the end, and its rise) and, on request, the recorded signals.

Ground truth ``lifted``: the object left the table during the grasp (a lift-off, the event
eq. 18 promises), by the stand-in's table contacts sampled every device cycle
(:mod:`dam_sim_bridge.lift_off`: a contact-free run of at least 50 ms is a lift-off, its start
the lift-off time; a bounce is none; the rule begins again at the goal), for every shape: a
polygon that rolls on the table raises its centroid while it still touches, and an object off
the table may have risen by less than ``classification.lift_height_m``. Beside it
``off_table_at_end``: no table contact over the last 0.1 s of the run (an object that lifted
may have fallen back, or tipped out of the plane until one end rests on the table), and the
rises.

``dam_experiment`` (:func:`main`) runs a small ``(k_theta, delta_theta_p)`` grid at one or more
friction angles and prints a table to compare with the analysis regions (paper Fig. 7)::

    ros2 run dam_experiments dam_experiment --alpha 5deg 30deg --k-theta 0.5 2 7 15 \\
        --delta-theta-p 5deg 10deg 15deg 25deg 40deg --out results.csv
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dam_common.command_line import CommandLineParser
from dam_common.device_protocol import JointMode as WireMode
from dam_common.quantities import ANGLE, argument, in_degrees
from dam_common.words import counted
from dam_experiments.quiet_stdout import quiet_stdout
from dam_hand_driver.slew import CommandSlew
from dam_sim_bridge.world import HandWorld
from dam_spcm_controller.classification import (
    ClassifierSettings,
    HandGeometry,
    Outcome,
    classify_from_joints,
)
from dam_spcm_controller.commands import JointMode
from dam_spcm_controller.sequence import DamSequence, Phase, SequenceParams

#: Controller JointMode -> world (wire protocol) JointMode.
_TO_WORLD = {int(JointMode.HOLD): int(WireMode.HOLD),
             int(JointMode.POSITION): int(WireMode.POSITION),
             int(JointMode.TORQUE): int(WireMode.TORQUE),
             int(JointMode.IMPEDANCE): int(WireMode.IMPEDANCE)}
#: The same as a lookup table: controller mode values (0, 1, ...) index their world mode.
_TO_WORLD_TABLE = np.array([_TO_WORLD[m] for m in range(len(_TO_WORLD))], dtype=np.int64)
#: Phase -> small integer for the recorded signals.
PHASE_CODES = {phase: i for i, phase in enumerate(Phase)}


@dataclass
class ExperimentResult:
    """What one lockstep DAM grasp did.

    Attributes
    ----------
    k_theta
        Finger-1 stiffness [N*m/rad].
    delta_theta_p
        Position-joint displacement [rad].
    friction_angle
        Finger-object friction angle [rad].
    phase
        Phase the sequence ended in (DONE, FAILED, or the phase at ``max_time``).
    failure_reason
        The sequence's reason for FAILED, else ``None``.
    outcome
        Outcome the controller reports: classification of the final joint state when DONE,
        ``Outcome.FAILURE`` otherwise (as ``spcm_controller`` does).
    joint_reason
        The classifier's explanation (or the failure reason).
    lifted
        Ground truth: the object left the table during the grasp, a lift-off (the module
        docstring).
    lift_off_time
        Ground truth: simulated time of the first lift-off (off the table for at least 50
        ms), from the goal [s]; NaN when the object never left the table.
    off_table_at_end
        Ground truth: no table contact over the last 0.1 s of the run.
    estimated_rise
        The controller's estimate of the rise from the final joint angles
        (``Classification.lift_m``) [m]; NaN when the grasp was not classified (it did not
        reach DONE) or the classifier gave none.
    lift_final
        Rise of the object centre at the end [m].
    lift_max
        Largest rise during the run [m].
    lift_rolling_end
        Rise at the end of ROLLING_UP [m] (NaN if not reached).
    phase_times
        Simulated time at which each phase was entered [s].
    sim_time
        Simulated duration of the run [s].
    wall_time
        Wall-clock duration [s].
    peak_torques
        (n,) largest torque-sensor reading of every joint during the run, ``max |tau|``
        [N*m], in ``hand.joint_names`` order (empty in a result built without it).
    signals
        Recorded arrays (see :func:`run_experiment`), empty unless ``record=True``.
    """

    k_theta: float
    delta_theta_p: float
    friction_angle: float
    phase: Phase
    failure_reason: str | None
    outcome: Outcome
    joint_reason: str
    lifted: bool
    lift_final: float
    lift_max: float
    lift_rolling_end: float
    phase_times: dict[str, float]
    sim_time: float
    wall_time: float
    signals: dict[str, np.ndarray] = field(default_factory=dict)
    peak_torques: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lift_off_time: float = math.nan
    estimated_rise: float = math.nan
    off_table_at_end: bool = False

    def row(self) -> dict[str, object]:
        """One CSV row (angles in degrees, lengths in millimetres)."""
        return {
            'alpha_deg': round(math.degrees(self.friction_angle), 6),
            'k_theta_nm_per_rad': self.k_theta,
            'delta_theta_p_deg': round(math.degrees(self.delta_theta_p), 6),
            'phase': self.phase.name,
            'outcome': self.outcome.name,
            'lifted_ground_truth': int(self.lifted),
            'lift_off_time_s': round(self.lift_off_time, 3),
            'off_table_at_end': int(self.off_table_at_end),
            'lift_final_mm': round(self.lift_final * 1e3, 3),
            'lift_max_mm': round(self.lift_max * 1e3, 3),
            'lift_rolling_end_mm': round(self.lift_rolling_end * 1e3, 3),
            'estimated_rise_mm': round(self.estimated_rise * 1e3, 3),
            'sim_time_s': round(self.sim_time, 3),
            'reason': self.failure_reason or self.joint_reason,
        }


def run_experiment(config, k_theta: float, delta_theta_p: float, *,
                   friction_angle: float | None = None, world: HandWorld | None = None,
                   object_position: Sequence[float] | None = None,
                   table_friction: float | None = None,
                   latency_cycles: int = 2, max_time: float = 20.0, settle_after: float = 0.0,
                   hold_before: float = 0.0, record: bool = False, record_every: int = 5,
                   **param_overrides: float) -> ExperimentResult:
    """Run one DAM grasp ``SPCM{k_theta, delta_theta_p}`` in lockstep.

    Parameters
    ----------
    config
        ``DamConfig`` (``dam_common.config.load_config()``).
    k_theta
        Finger-1 stiffness [N*m/rad] (the others by their stiffness ratio).
    delta_theta_p
        Position-joint displacement [rad].
    friction_angle
        Finger-object friction angle [rad]; ``None``: the configured one.
    object_position
        (3,) start of the object's centre [m]; ``None``: ``object.position_m``.
    table_friction
        Table-object friction coefficient; ``None``: ``contact.table_friction_coefficient``.
    world
        A world to reuse (it is reset); by default a new one, closed at the end.
    latency_cycles
        Device cycles between a state and the command computed from it reaching the world
        (>= 1; the ROS path has about 1-3).
    max_time
        Longest simulated time [s].
    settle_after
        Keep running this long after DONE (the object must stay up) [s].
    hold_before
        Let the reset world run this long with every joint in HOLD before the goal [s], as a
        live grasp's world runs between a reset and the goal's arrival. The final seat of the
        object in the hand can depend on it even where the outcome does not
        (``docs/simulation_grasp.md``, "Simulated time").
    record
        Record ``t`` [s], ``positions`` [rad], ``velocities`` [rad/s], ``efforts`` [N*m],
        ``object_position`` [m], ``phase`` (codes of :data:`PHASE_CODES`) every
        ``record_every`` cycles.
    param_overrides
        Replace :class:`SequenceParams` attributes (e.g. ``damping=0.02``,
        ``impedance_on_device=False``, ``envelope_constant_torque=True``).

    Raises
    ------
    ValueError
        ``latency_cycles`` < 1, or a bad ``max_time`` or ``hold_before``.
    dam_spcm_controller.errors.InputError
        A bad ``k_theta``, ``delta_theta_p`` or parameter override.
    """
    if int(latency_cycles) < 1:
        raise ValueError(f'latency_cycles must be >= 1, got {latency_cycles!r}')
    if not (math.isfinite(max_time) and max_time > 0.0):
        raise ValueError(f'max_time must be positive, got {max_time!r} s')
    if not (math.isfinite(hold_before) and hold_before >= 0.0):
        raise ValueError(f'hold_before must be >= 0, got {hold_before!r} s')
    wall0 = time.monotonic()
    own_world = world is None
    w = world if world is not None else HandWorld(config)
    try:
        alpha = (float(config.contact.friction_angle_rad) if friction_angle is None
                 else float(friction_angle))
        table_mu = (float(config.contact.table_friction_coefficient) if table_friction is None
                    else float(table_friction))
        w.reset(object_position=object_position, friction_angle_rad=alpha,
                table_friction_coefficient=table_mu)
        w.step(round(hold_before / w.time_step_s))
        t_goal = w.sim_time  # the lift-off time counts from the goal
        w.lift_off.reset()  # lifted: a lift-off during the grasp
        w.lift_off.update(t_goal, w.object_table_contacts())
        params = SequenceParams.from_config(config, **param_overrides)
        seq = DamSequence(params)
        geometry = HandGeometry.from_config(config)
        settings = ClassifierSettings.from_config(config)
        dev = config.device
        dt = 1.0 / float(dev.rate_hz)
        steps = max(1, round(dt / w.time_step_s))
        z0 = float(w.object_pose().position[2])
        js = w.joint_states()
        seq.step(0.0, js.positions, js.velocities, js.torques)
        seq.start(k_theta, delta_theta_p)
        pending: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        slew = CommandSlew(w.n_joints, float(dev.torque_limit_nm),
                           float(dev.torque_rate_limit_nm_per_s), dt)
        rec: dict[str, list[np.ndarray | float]] = {
            k: [] for k in ('t', 'positions', 'velocities', 'efforts', 'object_position',
                            'phase')}
        phase_times: dict[str, float] = {}
        last_phase: Phase | None = None
        lift_max = -math.inf
        peak = np.zeros(w.n_joints)
        lift_rolling_end = math.nan
        t = 0.0
        t_done: float | None = None
        cycle = 0
        while t < max_time:
            js = w.joint_states()
            cmd = seq.step(t, js.positions, js.velocities, js.torques)
            np.maximum(peak, np.abs(js.torques), out=peak)
            if seq.phase is not last_phase:
                phase_times[seq.phase.name] = t
                if last_phase is Phase.ROLLING_UP:
                    lift_rolling_end = float(w.object_pose().position[2]) - z0
                last_phase = seq.phase
            modes = _TO_WORLD_TABLE[cmd.modes]
            setpoints = slew.step(modes, cmd.setpoints, cmd.stiffness, cmd.damping,
                                  js.positions, js.velocities, js.torques)
            pending.append((modes, setpoints, cmd.stiffness.copy(), cmd.damping.copy()))
            if len(pending) >= latency_cycles:
                w.set_joint_commands(*pending.pop(0))
            w.step(steps)
            t = round(t + dt, 9)
            pos = w.object_pose().position
            lift_max = max(lift_max, float(pos[2]) - z0)
            if record and cycle % record_every == 0:
                rec['t'].append(t)
                rec['positions'].append(js.positions)
                rec['velocities'].append(js.velocities)
                rec['efforts'].append(js.torques)
                rec['object_position'].append(pos)
                rec['phase'].append(float(PHASE_CODES[seq.phase]))
            cycle += 1
            if seq.phase is Phase.DONE and t_done is None:
                t_done = t
            if (seq.phase is Phase.DONE and t_done is not None
                    and t - t_done >= settle_after) or (seq.phase.terminal
                                                        and seq.phase is not Phase.DONE
                                                        and seq.relaxed):
                break
        js = w.joint_states()
        lift_final = float(w.object_pose().position[2]) - z0
        ground = w.lift_off.state()
        estimated_rise = math.nan
        if seq.phase is Phase.DONE:
            c = classify_from_joints(geometry, params.layout.lower, params.layout.upper,
                                     js.positions, js.torques, settings,
                                     params.layout.joint_names, history=seq.history)
            outcome, reason = c.outcome, c.reason
            estimated_rise = float(c.lift_m)
        else:
            outcome = Outcome.FAILURE
            reason = seq.failure_reason or f'still in phase {seq.phase.name} at {t:.3g} s'
        signals = {k: np.asarray(v, dtype=float) for k, v in rec.items()} if record else {}
        return ExperimentResult(
            k_theta=float(k_theta), delta_theta_p=float(delta_theta_p), friction_angle=alpha,
            phase=seq.phase, failure_reason=seq.failure_reason, outcome=outcome,
            joint_reason=reason, lifted=ground.lifted,
            lift_final=lift_final, lift_max=lift_max, lift_rolling_end=lift_rolling_end,
            phase_times=phase_times, sim_time=t, wall_time=time.monotonic() - wall0,
            signals=signals, peak_torques=peak,
            lift_off_time=ground.lift_off_time - t_goal, estimated_rise=estimated_rise,
            off_table_at_end=ground.off_table_at_end)
    finally:
        if own_world:
            w.close()


def save_signals(result: ExperimentResult, path: str | Path) -> Path:
    """Write ``result.signals`` and its parameters to a compressed ``.npz`` file."""
    if not result.signals:
        raise ValueError('the result has no recorded signals (run with record=True)')
    out = Path(path)
    np.savez_compressed(
        out, **result.signals, k_theta=result.k_theta, delta_theta_p=result.delta_theta_p,
        friction_angle=result.friction_angle, end_phase=result.phase.name,
        outcome=result.outcome.name, lifted=result.lifted, lift_final=result.lift_final,
        lift_off_time=result.lift_off_time, estimated_rise=result.estimated_rise,
        off_table_at_end=result.off_table_at_end)
    return out


# ------------------------------------------------------------------------------------------
# Command line


def _analysis_region(analyzer, k: float, dp: float, alpha: float) -> tuple[str, str]:
    """'yes'/'no' of the sufficient condition and of the CSM ('no' beyond the end of the SPCM
    path, where the analysis answers "no lift"); '-' where the analysis raises."""
    try:
        r = analyzer.check_lift([k], [dp], friction_angle=alpha)
    except Exception:  # noqa: BLE001 - the table still prints without the analysis
        return '-', '-'
    return ('yes' if r.lift_guaranteed else 'no'), ('yes' if r.csm_lift else 'no')


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    p = CommandLineParser(
        prog='dam_experiment',
        description='DAM grasps in the lockstep simulator over a (k_theta, delta_theta_p) '
                    'grid, per object and friction angle; prints the outcome, the ground '
                    'truth (lifted: the object left the table; off the table at the end) '
                    'and the rise, optionally '
                    'writes a CSV.')
    p.add_argument('--object', '--objects', dest='objects', nargs='+', default=None,
                   metavar='NAME',
                   help='objects of the configuration\'s object library (default: the '
                        'configured one)')
    p.add_argument('--alpha', type=in_degrees(argument(ANGLE)), nargs='+', default=None,
                   metavar='ANGLE',
                   help='friction angles (5deg, 0.09rad; bare: rad; default: the configured '
                        'one)')
    p.add_argument('--k-theta', type=float, nargs='+', default=[0.5, 2.0, 7.0, 15.0],
                   help='finger-1 stiffness values [N*m/rad] (default: 0.5 2 7 15)')
    p.add_argument('--delta-theta-p', type=in_degrees(argument(ANGLE)), nargs='+',
                   default=[5.0, 10.0, 25.0, 40.0], metavar='ANGLE',
                   help='position-joint displacements (10deg, 0.17rad; bare: rad; default: '
                        '5deg 10deg 25deg 40deg)')
    p.add_argument('--out', type=Path, default=None, help='CSV file to write')
    p.add_argument('--config', default=None, help='configuration file (default: DAM_CONFIG '
                   'or the installed config/dam.yaml)')
    p.add_argument('--latency-cycles', type=int, default=2,
                   help='device cycles from a state to its command (default 2)')
    p.add_argument('--max-time', type=float, default=20.0,
                   help='simulated time limit per grasp [s] (default 20)')
    p.add_argument('--fixtures', type=Path, default=None,
                   help='directory: also save every run\'s signals as .npz there')
    p.add_argument('--impedance', choices=('device', 'controller'), default=None,
                   help='where the compliant-joint impedance runs (default: '
                        'controller.impedance_on_device of the configuration)')
    p.add_argument('--envelope', choices=('impedance', 'constant-torque'), default='impedance',
                   help='ENVELOPE: keep the SPCM impedance (default) or apply the '
                        'paper\'s constant torque (Fig. 6(d))')
    return p.parse_args(argv)


class _RowSink:
    """The CSV of ``--out``, opened before the first grasp and written a row at a time (a
    grasp done is never lost to a later error or to Ctrl-C); or nothing without ``--out``."""

    def __init__(self, path: Path | None) -> None:
        self.path = path
        self.count = 0
        self._handle = None if path is None else path.open('w', newline='', encoding='utf-8')
        self._writer: csv.DictWriter | None = None

    def write(self, row: dict[str, object]) -> None:
        self.count += 1
        if self._handle is None:
            return
        if self._writer is None:
            self._writer = csv.DictWriter(self._handle, fieldnames=list(row))
            self._writer.writeheader()
        self._writer.writerow(row)
        self._handle.flush()

    def close(self) -> None:
        """Close the file; one that holds no row is removed."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
            if self._writer is None and self.path is not None:
                self.path.unlink(missing_ok=True)


def main(argv: Sequence[str] | None = None) -> int:
    """``dam_experiment``: run the grid, print a table; exit 0, 2 on bad arguments, 130 when
    interrupted (SIGINT or SIGTERM; the rows done are in ``--out``)."""
    from dam_experiments.entry_points import InterruptOnSignals  # noqa: PLC0415

    args = _parse(sys.argv[1:] if argv is None else argv)
    sink: list[_RowSink] = []
    try:
        with InterruptOnSignals():
            return _main(args, sink)
    except KeyboardInterrupt:
        done = sink[0].count if sink else 0
        kept = (f'; {counted(done, "row")} written to {args.out}' if done and args.out is not None
                else '')
        sys.stderr.write(f'dam_experiment: interrupted after {counted(done, "grasp")}{kept}\n')
        return 130
    finally:
        for each in sink:
            each.close()


def _main(args: argparse.Namespace, sink: list[_RowSink]) -> int:
    from dam_analysis.errors import DamAnalysisError  # noqa: PLC0415
    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import DamCommonError  # noqa: PLC0415

    names = args.objects or ['']
    if args.objects is not None and (len(set(names)) != len(names) or '' in names):
        sys.stderr.write(f'dam_experiment: --object: {names!r} must be distinct, non-empty '
                         f'names\n')
        return 2
    try:
        config = load_config(args.config)
        configs = [config.with_object(name) for name in names]
    except (DamAnalysisError, DamCommonError) as exc:
        sys.stderr.write(f'dam_experiment: {exc}\n')
        return 2
    dp_max = math.degrees(config.task.delta_theta_p_max_rad)
    checks = (('--k-theta', args.k_theta, 'above 0', lambda v: v > 0.0, 'N*m/rad'),
              ('--delta-theta-p', args.delta_theta_p, f'in (0, {dp_max:g}]',
               lambda v: 0.0 < v <= dp_max, 'deg'),
              ('--alpha', args.alpha or [], 'in [0, 90)', lambda v: 0.0 <= v < 90.0, 'deg'))
    for option, values, bound, inside, unit in checks:
        for v in values:
            if not (math.isfinite(v) and inside(v)):
                sys.stderr.write(f'dam_experiment: {option}: {v:g} {unit} must be {bound} '
                                 f'{unit}\n')
                return 2
    analyzers = []
    for each in configs:  # an object the analysis cannot answer for is no grasp to run
        try:
            from dam_analysis.analysis import LiftAnalyzer  # noqa: PLC0415 - slow import

            analyzers.append(LiftAnalyzer(each))
        except DamAnalysisError as exc:
            sys.stderr.write(f'dam_experiment: object {each.object.name!r} cannot be analysed '
                             f'with this hand, so no grasp of it can run: {exc}\n')
            return 2
        except Exception as exc:  # noqa: BLE001 - the experiment runs without the analysis
            sys.stderr.write(f'dam_experiment: analysis of {each.object.name} unavailable '
                             f'({exc}); columns show -\n')
            analyzers.append(None)
    alphas = ([math.radians(a) for a in args.alpha] if args.alpha
              else [float(config.contact.friction_angle_rad)])
    try:  # the outputs before the first grasp: a bad path costs no computation
        if args.fixtures is not None:
            args.fixtures.mkdir(parents=True, exist_ok=True)
        sink.append(_RowSink(args.out))
    except OSError as exc:
        sys.stderr.write(f'dam_experiment: cannot write {exc.filename}: '
                         f'{exc.strerror or exc}\n')
        return 2
    width = max(6, *(len(c.object.name) for c in configs))
    header = (f'{"object":>{width}} {"alpha":>6} {"k_theta":>8} {"dp":>6} {"phase":>8} '
              f'{"outcome":>17} {"lifted":>6} {"at end":>6} {"rise":>7} {"max":>7} '
              f'{"est":>7} {"suff":>5} {"csm":>5}  reason')
    print(header)
    # two rises of one grasp, each named (they differ: the joints' estimate is not the world)
    print('(rise, max: the stand-in\'s, at the end and highest; est: the rise estimated from '
          'the joints; -: not estimated)')
    overrides: dict[str, bool] = {
        'envelope_constant_torque': args.envelope == 'constant-torque'}
    if args.impedance is not None:
        overrides['impedance_on_device'] = args.impedance == 'device'
    for each, analyzer in zip(configs, analyzers, strict=True):
        _run_object(each, analyzer, args, alphas, overrides, width, sink[0])
    if args.out is not None:
        print(f'wrote {counted(sink[0].count, "row")} to {args.out}')
    return 0


def _run_object(config, analyzer, args: argparse.Namespace, alphas: Sequence[float],
                overrides: dict[str, bool], width: int, sink: _RowSink) -> None:
    """The grid of one object: its rows printed and written to ``sink``."""
    name = config.object.name
    with quiet_stdout():  # PyBullet's 'argv[0]=' line, amid the table
        world = HandWorld(config)
    try:
        for alpha in alphas:
            for dp in args.delta_theta_p:
                for k in args.k_theta:
                    r = run_experiment(config, k, math.radians(dp), friction_angle=alpha,
                                       world=world, latency_cycles=args.latency_cycles,
                                       max_time=args.max_time,
                                       record=args.fixtures is not None, **overrides)
                    suff, csm = (('-', '-') if analyzer is None else
                                 _analysis_region(analyzer, k, math.radians(dp), alpha))
                    row = {'object': name, **r.row()}
                    row['sufficient_region'] = suff
                    row['csm_region'] = csm
                    print(f'{name:>{width}} {math.degrees(alpha):6.1f} {k:8.3g} {dp:6.1f} '
                          f'{r.phase.name:>8} '
                          f'{r.outcome.name:>17} {"yes" if r.lifted else "no":>6} '
                          f'{"off" if r.off_table_at_end else "on":>6} '
                          f'{r.lift_final * 1e3:5.1f}mm '
                          f'{r.lift_max * 1e3:5.1f}mm '
                          + (f'{r.estimated_rise * 1e3:5.1f}mm '
                             if math.isfinite(r.estimated_rise) else f'{"-":>7} ')
                          + f'{suff:>5} {csm:>5}  '
                          f'{(r.failure_reason or r.joint_reason)[:70]}', flush=True)
                    if args.fixtures is not None:
                        stem = f'dam_{name}_a{math.degrees(alpha):g}_k{k:g}_dp{dp:g}.npz'
                        save_signals(r, args.fixtures / stem)
                    sink.write(row)
    finally:
        world.close()


if __name__ == '__main__':
    sys.exit(main())
