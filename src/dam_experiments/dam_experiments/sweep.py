"""The paper's Fig. 7 as a sweep: many lockstep DAM grasps over ``(object, alpha, k_theta,
delta_theta_p)``, each cell as a probability of lifting.

The pure core of ``ros2 run dam_experiments sweep`` (:mod:`dam_experiments.sweep_cli`): no rclpy,
no Dask. It defines a sweep (:class:`SweepSpec`: the three axes, the repeats, the seed, the
perturbations and the trial options; the objects of the configuration's library to grasp,
one by default), lists its trials (:meth:`SweepSpec.trials`), draws each
trial's perturbations from its seed (:meth:`Perturbations.draw`) and runs one trial
(:func:`run_trial`): the stand-in world and the controller core in lockstep, exactly as
``dam_experiment`` does (:func:`~dam_experiments.experiment.run_experiment`), classified as in
the paper's Fig. 7 (SUCCESS, LIFTED_DAM_FAILED, FAILURE: the controller's verdict from joint
signals alone, with the rise it estimates) together with the ground truth (``lifted``: the
object left the table during the grasp, :mod:`dam_sim_bridge.lift_off`; the lift-off time;
whether it was off the table at the end; the rise of the object) and what ``/check_lift``
answers for the pair (the sufficient condition, eq. 18, and the contact stiffness model).
:mod:`dam_experiments.sweep_table` writes the table and resumes an interrupted sweep.

Determinism: a trial's row depends only on its inputs (the cell, the sweep's perturbation
scales and trial options, the configuration) and its seed. The seed of trial ``r`` of cell
``(i, j, l)`` (indices into the friction angle, ``delta_theta_p`` and ``k_theta`` axes) is
drawn from ``numpy.random.SeedSequence(seed, spawn_key=(i, j, l, r))`` for the first object
and ``spawn_key=(i, j, l, o, r)`` for object ``o > 0`` (so that a sweep of one object draws
what it drew before objects were an axis); each trial builds a fresh world, so neither the
order of the trials nor the process that runs them matters.

Axes on the command line (:func:`dam_experiments.sweep_axes.parse_axis`) are values or ranges
``start:stop:count`` (evenly spaced, both ends included) and ``start:stop:count:log`` (evenly
spaced logarithms); angles in degrees.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dam_common.polygon_section import ConvexPolygon
from dam_experiments.errors import SweepError
from dam_experiments.quiet_stdout import quiet_stdout

#: Largest friction angle a trial may get after jitter [deg] (``tan`` stays finite).
MAX_FRICTION_ANGLE_DEG = 89.0
#: Command-line option of each sweep parameter (error messages name both).
OPTIONS = {'objects': '--objects', 'friction_angles_deg': '--friction-angles',
           'k_theta': '--k-theta',
           'delta_theta_p_deg': '--delta-theta-p', 'repeats': '--repeats', 'seed': '--seed',
           'mass_rel': '--mass-rel', 'position_sd_mm': '--position-sd',
           'table_friction_rel': '--table-friction-rel',
           'friction_angle_sd_deg': '--friction-angle-sd', 'max_time_s': '--max-time',
           'latency_cycles': '--latency-cycles',
           'trajectory_duration_s': '--trajectory-duration', 'impedance': '--impedance',
           'envelope': '--envelope'}


def _named(field_name: str) -> str:
    """``--option (field)`` for an error message."""
    return f'{OPTIONS[field_name]} ({field_name})'


# ------------------------------------------------------------------------------------------
# Perturbations and seeds


@dataclass(frozen=True)
class TrialDraw:
    """The perturbed world of one trial.

    Attributes
    ----------
    object_mass_kg
        Mass of the cylinder [kg].
    object_offset_m
        ``(dx, dy)`` start of the cylinder's centre relative to ``object.position_m`` [m]
        (x across the cylinder towards finger 1's side, y along its axis).
    table_friction
        Table-object Coulomb coefficient [-].
    friction_angle_deg
        Finger-object friction angle the world gets [deg].
    """

    object_mass_kg: float
    object_offset_m: tuple[float, float]
    table_friction: float
    friction_angle_deg: float


@dataclass(frozen=True)
class Perturbations:
    """Scales of the per-trial perturbations; all zero: every trial is the nominal world.

    Each trial draws, from ``numpy.random.default_rng(seed)`` and in this order, ``u_m ~
    U(-1, 1)``, ``(z_x, z_y) ~ N(0, 1)``, ``u_t ~ U(-1, 1)`` and ``z_a ~ N(0, 1)``, whatever
    the scales (so that turning one perturbation on leaves the others' draws as they were):

    * object mass ``m = m_B (1 + mass_rel u_m)``, ``m_B = object.mass_kg``;
    * object position offset ``(dx, dy) = position_sd_mm (z_x, z_y)`` [mm];
    * table friction ``mu_t = mu_t0 (1 + table_friction_rel u_t)``,
      ``mu_t0 = contact.table_friction_coefficient``;
    * friction angle ``alpha = alpha_cell + friction_angle_sd_deg z_a`` [deg], clipped to
      ``[0, 89] deg``.

    Attributes
    ----------
    mass_rel
        Half width of the uniform relative mass spread, in ``[0, 1)`` [-].
    position_sd_mm
        Standard deviation of each horizontal offset [mm], ``>= 0``.
    table_friction_rel
        Half width of the uniform relative table friction spread, in ``[0, 1)`` [-].
    friction_angle_sd_deg
        Standard deviation of the friction angle jitter [deg], ``>= 0``.
    """

    mass_rel: float = 0.0
    position_sd_mm: float = 0.0
    table_friction_rel: float = 0.0
    friction_angle_sd_deg: float = 0.0

    def __post_init__(self) -> None:
        for name, upper in (('mass_rel', 1.0), ('position_sd_mm', math.inf),
                            ('table_friction_rel', 1.0), ('friction_angle_sd_deg', math.inf)):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < upper
                    and math.isfinite(value)):
                bound = 'in [0, 1)' if upper == 1.0 else '>= 0 and finite'
                raise SweepError(f'{_named(name)}: {value!r} must be {bound}')

    @property
    def any(self) -> bool:
        """True when at least one scale is nonzero."""
        return any(getattr(self, f.name) != 0.0 for f in dataclasses.fields(self))

    def draw(self, seed: int, friction_angle_deg: float, mass_kg: float,
             table_friction: float) -> TrialDraw:
        """The perturbed world of a trial with ``seed`` in a cell at ``friction_angle_deg``.

        Parameters
        ----------
        seed
            The trial's seed (:func:`trial_seed`).
        friction_angle_deg
            The cell's friction angle [deg].
        mass_kg, table_friction
            Nominal object mass [kg] and table coefficient [-] (the configuration's).
        """
        rng = np.random.default_rng(seed)
        u_m = float(rng.uniform(-1.0, 1.0))
        z_x, z_y = (float(z) for z in rng.standard_normal(2))
        u_t = float(rng.uniform(-1.0, 1.0))
        z_a = float(rng.standard_normal())
        sd_m = self.position_sd_mm * 1e-3
        alpha = friction_angle_deg + self.friction_angle_sd_deg * z_a
        return TrialDraw(
            object_mass_kg=mass_kg * (1.0 + self.mass_rel * u_m),
            object_offset_m=(sd_m * z_x, sd_m * z_y),
            table_friction=table_friction * (1.0 + self.table_friction_rel * u_t),
            friction_angle_deg=min(max(alpha, 0.0), MAX_FRICTION_ANGLE_DEG))


def trial_seed(seed: int, cell: tuple[int, ...], repeat: int) -> int:
    """Seed of repeat ``repeat`` of ``cell`` (axis indices: friction angle, delta_theta_p,
    k_theta, then the object's when it is not the first): 53 bits of
    ``SeedSequence(seed, spawn_key=(*cell, repeat))``, so that it is
    exact in any CSV reader that turns numbers into doubles."""
    state = np.random.SeedSequence(int(seed), spawn_key=(*cell, int(repeat)))
    high, low = (int(v) for v in state.generate_state(2, dtype=np.uint32))
    return ((high << 32) | low) >> 11


# ------------------------------------------------------------------------------------------
# The sweep and its trials


@dataclass(frozen=True)
class TrialSpec:
    """One trial: a cell of the grid, its repeat number and its seed (angles in degrees)."""

    index: int
    friction_angle_deg: float
    k_theta: float  #: finger-1 stiffness [N*m/rad]
    delta_theta_p_deg: float
    repeat: int
    seed: int
    #: the object of the configuration's library; '': the configured default object
    object_name: str = ''


@dataclass(frozen=True)
class SweepSpec:
    """Everything that decides the rows of a sweep (not how or where it runs).

    Attributes
    ----------
    friction_angles_deg, k_theta, delta_theta_p_deg
        The axes: friction angles alpha [deg], finger-1 stiffness [N*m/rad],
        position-joint displacements [deg].
    objects
        The objects grasped, by their names in the configuration's ``object.library`` (an
        axis, outermost); empty: the configured default object alone.
    repeats
        Trials per cell (>= 1); with perturbations, each draws its own world.
    seed
        Base seed of :func:`trial_seed` (>= 0).
    perturbations
        Per-trial perturbation scales.
    max_time_s
        Simulated time limit of a trial [s]; a grasp still running then is a FAILURE
        ("still in phase ...").
    latency_cycles
        Device cycles from a state to the command computed from it (``run_experiment``).
    trajectory_duration_s
        Position-joint motion time [s]; ``None``: ``controller.trajectory_duration_s``.
    impedance
        ``'device'``, ``'controller'`` or ``None`` (``controller.impedance_on_device``).
    envelope
        ``'impedance'`` (the SPCM impedance held) or ``'constant-torque'`` (paper Fig. 6(d)).
    """

    friction_angles_deg: tuple[float, ...]
    k_theta: tuple[float, ...]
    delta_theta_p_deg: tuple[float, ...]
    repeats: int = 1
    seed: int = 0
    perturbations: Perturbations = field(default_factory=Perturbations)
    max_time_s: float = 8.0
    latency_cycles: int = 2
    trajectory_duration_s: float | None = None
    impedance: str | None = None
    envelope: str = 'impedance'
    objects: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        names = tuple(self.objects)
        if not all(isinstance(n, str) and n for n in names) or len(set(names)) != len(names):
            raise SweepError(f'{_named("objects")}: {list(names)!r} must be distinct, non-empty '
                             f'object names')
        object.__setattr__(self, 'objects', names)
        for name in ('friction_angles_deg', 'k_theta', 'delta_theta_p_deg'):
            values = tuple(float(v) for v in getattr(self, name))
            if not values:
                raise SweepError(f'{_named(name)}: no value given')
            object.__setattr__(self, name, values)
        if not all(0.0 <= a < 90.0 for a in self.friction_angles_deg):
            raise SweepError(f'{_named("friction_angles_deg")}: '
                             f'{self.friction_angles_deg!r} must lie in [0, 90) deg')
        if not all(k > 0.0 and math.isfinite(k) for k in self.k_theta):
            raise SweepError(f'{_named("k_theta")}: {self.k_theta!r} must be positive')
        if not all(d > 0.0 and math.isfinite(d) for d in self.delta_theta_p_deg):
            raise SweepError(f'{_named("delta_theta_p_deg")}: {self.delta_theta_p_deg!r} '
                             f'must be positive')
        for name, low in (('repeats', 1), ('seed', 0), ('latency_cycles', 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise SweepError(f'{_named(name)}: {value!r} must be a whole number >= {low}')
        if not (math.isfinite(self.max_time_s) and self.max_time_s > 0.0):
            raise SweepError(f'{_named("max_time_s")}: {self.max_time_s!r} must be positive')
        td = self.trajectory_duration_s
        if td is not None and not (math.isfinite(td) and td > 0.0):
            raise SweepError(f'{_named("trajectory_duration_s")}: {td!r} must be positive')
        if self.impedance not in (None, 'device', 'controller'):
            raise SweepError(f'{_named("impedance")}: {self.impedance!r} must be device or '
                             f'controller')
        if self.envelope not in ('impedance', 'constant-torque'):
            raise SweepError(f'{_named("envelope")}: {self.envelope!r} must be impedance or '
                             f'constant-torque')

    @property
    def n_trials(self) -> int:
        """Number of trials: cells times repeats."""
        return (max(len(self.objects), 1) * len(self.friction_angles_deg) * len(self.k_theta)
                * len(self.delta_theta_p_deg) * self.repeats)

    def trials(self) -> list[TrialSpec]:
        """Every trial, indexed in table order: object, friction angle, then
        ``delta_theta_p``, then ``k_theta``, then the repeat."""
        out: list[TrialSpec] = []
        for o, name in enumerate(self.objects or ('',)):
            for i, alpha in enumerate(self.friction_angles_deg):
                for j, dp in enumerate(self.delta_theta_p_deg):
                    for l_, k in enumerate(self.k_theta):
                        cell = (i, j, l_) if o == 0 else (i, j, l_, o)
                        for r in range(self.repeats):
                            out.append(TrialSpec(len(out), alpha, k, dp, r,
                                                 trial_seed(self.seed, cell, r), name))
        return out

    def sequence_overrides(self) -> dict[str, Any]:
        """``SequenceParams`` overrides of the trial options."""
        overrides: dict[str, Any] = {
            'envelope_constant_torque': self.envelope == 'constant-torque'}
        if self.impedance is not None:
            overrides['impedance_on_device'] = self.impedance == 'device'
        if self.trajectory_duration_s is not None:
            overrides['trajectory_duration'] = self.trajectory_duration_s
        return overrides

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able form (:meth:`from_dict` reads it back)."""
        data = dataclasses.asdict(self)
        for name in ('friction_angles_deg', 'k_theta', 'delta_theta_p_deg', 'objects'):
            data[name] = list(data[name])
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SweepSpec:
        """Inverse of :meth:`to_dict`.

        Raises
        ------
        SweepError
            An unknown or missing key, or a bad value.
        """
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            keys = 'key' if len(unknown) == 1 else 'keys'
            raise SweepError(f'sweep parameters: unknown {keys} {unknown}')
        values = dict(data)
        try:
            values['perturbations'] = Perturbations(**dict(values.get('perturbations', {})))
            return cls(**values)
        except TypeError as exc:
            raise SweepError(f'sweep parameters: {exc}') from None

    def check_against(self, config: Any) -> None:
        """Check the axes and the trial options against the configuration.

        Raises
        ------
        SweepError
            An object not in the configuration's library, a ``delta_theta_p`` above
            ``task.delta_theta_p_max_deg``, a ``k_theta`` whose finger stiffnesses exceed
            ``device.max_stiffness_nm_per_rad`` (the driver would refuse them), or a
            trajectory at least as long as ``controller.phase_timeout_s``.
        """
        unknown = [n for n in self.objects if n not in config.objects]
        if unknown:
            raise SweepError(f'{OPTIONS["objects"]}: {unknown[0]!r} is not in the object '
                             f'library (known: {", ".join(sorted(config.objects))})')
        dp_max = math.degrees(float(config.task.delta_theta_p_max_rad))
        for dp in self.delta_theta_p_deg:
            if dp > dp_max + 1e-9:
                raise SweepError(f'{OPTIONS["delta_theta_p_deg"]}: {dp:.4g} deg exceeds '
                                 f'task.delta_theta_p_max_deg {dp_max:.4g} deg')
        k_max = float(config.device.max_stiffness_nm_per_rad)
        ratio = float(np.max(config.hand.stiffness_ratios))
        for k in self.k_theta:
            if k * ratio > k_max * (1.0 + 1e-12):
                raise SweepError(f'{OPTIONS["k_theta"]}: {k:.4g} N*m/rad exceeds the device limit '
                                 f'{k_max:.4g} N*m/rad (device.max_stiffness_nm_per_rad)')
        td = self.trajectory_duration_s
        timeout = float(config.controller.phase_timeout_s)
        if td is not None and td >= timeout:
            raise SweepError(f'{OPTIONS["trajectory_duration_s"]}: {td:g} s must be shorter than '
                             f'controller.phase_timeout_s {timeout:g} s')


# ------------------------------------------------------------------------------------------
# One trial


def config_values(config: Any) -> Any:
    """The configuration's values as plain JSON data (dicts by field name, lists, numbers,
    strings), without the file name it came from."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        return {f.name: config_values(getattr(config, f.name))
                for f in dataclasses.fields(config) if f.name != 'source'}
    if isinstance(config, Mapping):
        return {str(k): config_values(v) for k, v in sorted(config.items())}
    if isinstance(config, ConvexPolygon):
        return {'vertices': config_values(config.vertices), 'name': config.name}
    if isinstance(config, (np.ndarray, list, tuple)):
        return [config_values(v) for v in np.asarray(config, dtype=object).tolist()]
    if isinstance(config, np.generic):
        return config.item()
    return config


def config_digest(config: Any) -> str:
    """SHA-256 of the configuration's values (not of its file name), to recognise it again."""
    text = json.dumps(config_values(config), sort_keys=True, separators=(',', ':'))
    return hashlib.sha256(text.encode('utf-8')).hexdigest()


_ANALYZERS: dict[str, Any] = {}


def analyzer_for(config: Any) -> Any:
    """The process's ``LiftAnalyzer`` of ``config`` (built once per process: a few tenths
    of a second)."""
    key = config_digest(config)
    if key not in _ANALYZERS:
        from dam_analysis.analysis import LiftAnalyzer  # noqa: PLC0415 - slow import

        _ANALYZERS[key] = LiftAnalyzer(config)
    return _ANALYZERS[key]


def _fmt(value: float, digits: int = 6) -> str:
    """A float as the table writes it: ``digits`` significant digits, ``nan``."""
    return 'nan' if math.isnan(value) else f'{value + 0.0:.{digits}g}'  # + 0.0: no '-0'


def _mm(value_m: float) -> str:
    """A length [m] in millimetres with 4 decimals (0.1 um), ``nan``."""
    return 'nan' if math.isnan(value_m) else f'{round(value_m * 1e3, 4) + 0.0:.4f}'


def _seconds(value_s: float) -> str:
    """A simulated time [s] to the millisecond, ``nan``."""
    return 'nan' if math.isnan(value_s) else f'{round(value_s, 3) + 0.0:.3f}'


def rolling_up_end(phase_times: Mapping[str, float]) -> float:
    """When ROLLING_UP ended [s from the goal]: the entry into the phase after it (the
    earliest phase entered later); NaN when it did not end (or was never entered)."""
    start = phase_times.get('ROLLING_UP')
    if start is None:
        return math.nan
    later = [t for name, t in phase_times.items() if name != 'ROLLING_UP' and t > start]
    return min(later, default=math.nan)


def input_columns(spec: TrialSpec) -> dict[str, str]:
    """The table's input columns of a trial, as written (resume compares them)."""
    return {'trial': str(spec.index), 'object': spec.object_name,
            'friction_angle_deg': f'{spec.friction_angle_deg:.12g}',
            'k_theta_nm_per_rad': f'{spec.k_theta:.12g}',
            'delta_theta_p_deg': f'{spec.delta_theta_p_deg:.12g}',
            'repeat': str(spec.repeat), 'seed': str(spec.seed)}


def table_columns(config: Any) -> list[str]:
    """Column names of the trial table for the configured hand."""
    peaks = [f'peak_tau_{f.name}_{role}_nm' for role in ('compliant', 'position')
             for f in config.hand.fingers]
    return ['trial', 'object', 'friction_angle_deg', 'k_theta_nm_per_rad', 'delta_theta_p_deg',
            'repeat', 'seed', 'object_mass_kg', 'object_offset_x_mm', 'object_offset_y_mm',
            'table_friction', 'friction_angle_sim_deg', 'phase', 'outcome', 'lifted',
            'lift_off_time_s', 'off_table_at_end', 'rolling_up_end_s', 'rise_final_mm',
            'rise_max_mm', 'rise_rolling_end_mm', 'estimated_rise_mm', *peaks,
            'check_lift_guaranteed', 'worst_case_margin_n', 'csm_lift', 'csm_margin_n',
            'csm_path_lift', 'csm_path_margin_n', 'sim_time_s', 'reason']


@dataclass(frozen=True)
class TrialResult:
    """A trial's table row (strings in :func:`table_columns` order) and its cost."""

    row: dict[str, str]
    wall_time_s: float  #: wall-clock time of the trial [s]
    cpu_time_s: float  #: CPU time of the trial in its process [s]


def run_trial(spec: TrialSpec, sweep: SweepSpec, config: Any) -> TrialResult:
    """Run one trial: draw its world, grasp in lockstep, ask the analysis.

    The world is the configured one with the trial's object and perturbations
    (:meth:`Perturbations.draw`);
    the grasp is :func:`~dam_experiments.experiment.run_experiment` of the cell's pair in a
    fresh world. The analysis columns are what ``/check_lift`` answers for the request the
    controller would send, i.e. the cell's pair at the cell's friction angle with the trial's
    object as configured: eq. (18) holds for every admissible contact force
    (``check_lift_guaranteed``, ``worst_case_margin_n = min c_z^T f_o - m_B g`` [N]) and the
    contact stiffness model's verdict and margin (``csm_lift``, ``csm_margin_n`` [N]). The
    perturbations are what the analysis does not know.

    Parameters
    ----------
    spec
        The trial.
    sweep
        The sweep it belongs to (perturbation scales and trial options).
    config
        ``DamConfig`` of the hand, the object library and the controller.

    Returns
    -------
    TrialResult
        Its row (every value formatted, so that a rerun writes the same bytes) and its cost.
    """
    from dam_analysis.errors import DamAnalysisError  # noqa: PLC0415 - imports on first use
    from dam_experiments.experiment import run_experiment  # noqa: PLC0415 - imports pybullet
    from dam_sim_bridge.world import HandWorld  # noqa: PLC0415

    config = config.with_object(spec.object_name)
    analyzer = analyzer_for(config)  # once per object and process, not the trial's cost
    wall0, cpu0 = time.monotonic(), time.process_time()
    obj = config.object
    draw = sweep.perturbations.draw(spec.seed, spec.friction_angle_deg, float(obj.mass_kg),
                                    float(config.contact.table_friction_coefficient))
    trial_config = config
    if draw.object_mass_kg != float(obj.mass_kg):
        trial_config = dataclasses.replace(
            config, object=dataclasses.replace(obj, mass_kg=draw.object_mass_kg))
    position = np.asarray(obj.position_m, dtype=float).copy()
    position[:2] += draw.object_offset_m
    dp = math.radians(spec.delta_theta_p_deg)
    with quiet_stdout():
        world = HandWorld(trial_config)
    with world:
        r = run_experiment(trial_config, spec.k_theta, dp, world=world,
                           friction_angle=math.radians(draw.friction_angle_deg),
                           object_position=position, table_friction=draw.table_friction,
                           latency_cycles=sweep.latency_cycles, max_time=sweep.max_time_s,
                           **sweep.sequence_overrides())
    reason = r.failure_reason or r.joint_reason
    classified = r.phase.name == 'DONE'  # the controller classifies a grasp that is done
    try:
        a = analyzer.check_lift([spec.k_theta], [dp],
                                friction_angle=math.radians(spec.friction_angle_deg))
        analysis = (int(a.lift_guaranteed), float(a.worst_case_margin), int(a.csm_lift),
                    float(a.csm_margin), int(a.csm_path_lift), float(a.csm_path_margin))
    except DamAnalysisError as exc:
        analysis = (0, math.nan, 0, math.nan, 0, math.nan)
        reason = f'{reason}; analysis: {exc}'
    names = list(config.hand.joint_names)
    peaks = {}
    for role in ('compliant', 'position'):
        for f in config.hand.fingers:
            j = next(i for i, n in enumerate(names) if n.startswith(f.name + '_')
                     and n.rsplit('_', 2)[-2] == role)
            peaks[f'peak_tau_{f.name}_{role}_nm'] = _fmt(float(r.peak_torques[j]))
    row = {
        **input_columns(spec),
        'object_mass_kg': _fmt(draw.object_mass_kg),
        'object_offset_x_mm': _mm(draw.object_offset_m[0]),
        'object_offset_y_mm': _mm(draw.object_offset_m[1]),
        'table_friction': _fmt(draw.table_friction),
        'friction_angle_sim_deg': _fmt(draw.friction_angle_deg),
        'phase': r.phase.name, 'outcome': r.outcome.name, 'lifted': str(int(r.lifted)),
        'lift_off_time_s': '' if math.isnan(r.lift_off_time) else _seconds(r.lift_off_time),
        'off_table_at_end': str(int(r.off_table_at_end)),
        'rolling_up_end_s': _seconds(rolling_up_end(r.phase_times)),
        'rise_final_mm': _mm(r.lift_final), 'rise_max_mm': _mm(r.lift_max),
        'rise_rolling_end_mm': _mm(r.lift_rolling_end),
        'estimated_rise_mm': _mm(r.estimated_rise) if classified else '',
        **peaks,
        'check_lift_guaranteed': str(analysis[0]), 'worst_case_margin_n': _fmt(analysis[1]),
        'csm_lift': str(analysis[2]), 'csm_margin_n': _fmt(analysis[3]),
        'csm_path_lift': str(analysis[4]), 'csm_path_margin_n': _fmt(analysis[5]),
        'sim_time_s': _fmt(r.sim_time), 'reason': ' '.join(reason.split()),
    }
    return TrialResult(row, time.monotonic() - wall0, time.process_time() - cpu0)
