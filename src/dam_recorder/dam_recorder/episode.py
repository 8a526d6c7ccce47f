"""Per-grasp episode metadata stored in a bag's ``custom_data`` (no rclpy).

An episode bag is a normal bag directory named ``<YYYY_MM_DD-HH_MM_SS>_<outcome lower-case>``
(``2026_11_29-18_05_12_success``). Its ``metadata.yaml`` holds, in
``rosbag2_bagfile_information.custom_data`` (string -> string):

``dam_episode.summary``
    JSON text of one object: the goal id (32 hex digits), when the goal was accepted and when
    it ended [ns since the epoch], the goal as the client sent it, the ``k_theta`` [N*m/rad],
    ``delta_theta_p`` [rad] and ``friction_angle`` [rad] as run, the ``/check_lift`` answer (or
    ``null``), the outcome (code and name), the result message and the durations [s].
    Non-finite floats are written as the strings ``"nan"``, ``"inf"`` and ``"-inf"``.
``dam_episode.config``
    YAML text of the configuration file the grasp ran with.
``dam_episode.version``
    Version text.

:func:`episode_from_custom_data` validates all of it and raises :class:`EpisodeError` naming
the key and the value when something is malformed.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import yaml

from dam_recorder.errors import EpisodeError

SUMMARY_KEY = 'dam_episode.summary'
CONFIG_KEY = 'dam_episode.config'
VERSION_KEY = 'dam_episode.version'

#: Outcome names by their code (``DamGrasp.Result.OUTCOME_*``).
OUTCOME_NAMES: tuple[str, ...] = (
    'UNKNOWN', 'SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE', 'ABORTED', 'REJECTED')
#: The order outcomes are listed in (totals, tables): best first.
OUTCOME_ORDER: tuple[str, ...] = (
    'SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE', 'ABORTED', 'REJECTED', 'UNKNOWN')

_NON_FINITE = {'nan': math.nan, 'inf': math.inf, '-inf': -math.inf}
_GOAL_ID = re.compile(r'^[0-9a-f]{32}$')
_EPISODE_NAME = re.compile(
    r'^(\d{4})_(\d{2})_(\d{2})-(\d{2})_(\d{2})_(\d{2})_([a-z][a-z_]*)$')


@dataclass(frozen=True)
class CheckLiftRecord:
    """The ``/check_lift`` answer an episode ran with.

    Attributes
    ----------
    ok : bool
        Whether the request was well formed.
    message : str
        The server's message.
    lift_guaranteed : bool
        The sufficient condition (eq. 18) holds.
    worst_case_margin : float
        Margin of the sufficient condition [N] (``-inf``: any internal force admissible;
        ``nan``: no contact).
    csm_lift : bool
        The contact stiffness model predicts a lift.
    csm_margin : float
        Margin of the contact stiffness model [N] (``nan`` when a contact would open).
    delta_theta_s : tuple of float
        Compliant-joint displacement per finger [rad].
    compliant_torque : tuple of float
        Compliant-joint torque per finger [N*m].
    """

    ok: bool
    message: str
    lift_guaranteed: bool
    worst_case_margin: float
    csm_lift: bool
    csm_margin: float
    delta_theta_s: tuple[float, ...]
    compliant_torque: tuple[float, ...]


@dataclass(frozen=True)
class EpisodeSummary:
    """The content of ``dam_episode.summary``.

    Attributes
    ----------
    goal_id : str
        The goal's UUID as 32 lower-case hex digits.
    accepted_ns, ended_ns : int
        When the goal was accepted and when it ended [ns since the epoch].
    goal_k_theta, goal_delta_theta_p : tuple of float
        The goal as the client sent it [N*m/rad], [rad] (empty: the configured values).
    k_theta : tuple of float
        Compliant-joint stiffness per finger as run [N*m/rad].
    delta_theta_p : tuple of float
        Position-joint displacement per finger as run [rad].
    friction_angle : float
        Friction angle as run [rad].
    check_lift : CheckLiftRecord or None
        The ``/check_lift`` answer, ``None`` when there was none.
    outcome : int
        ``DamGrasp.Result.OUTCOME_*`` code.
    outcome_name : str
        Its name (``SUCCESS``, ``LIFTED_DAM_FAILED``, ...).
    message : str
        Why the grasp ended this way.
    duration_s : float
        From goal acceptance to the end [s], on the grasp's clock when ``wall_duration_s`` is
        there (simulated time with ``use_sim_time``), else on the wall clock (a controller
        that reported only that).
    pre_roll_s, post_roll_s : float
        Recorded before acceptance and after the end [s].
    object : str
        The column object of the configuration's library the grasp was for (empty in a bag
        of a version that did not record it).
    wall_duration_s : float or None
        From goal acceptance to the end on the wall (steady) clock [s]; ``None`` in a bag of
        a controller that did not report it (its ``duration_s`` is that).
    """

    goal_id: str
    accepted_ns: int
    ended_ns: int
    goal_k_theta: tuple[float, ...]
    goal_delta_theta_p: tuple[float, ...]
    k_theta: tuple[float, ...]
    delta_theta_p: tuple[float, ...]
    friction_angle: float
    check_lift: CheckLiftRecord | None
    outcome: int
    outcome_name: str
    message: str
    duration_s: float
    pre_roll_s: float
    post_roll_s: float
    object: str = ''
    wall_duration_s: float | None = None


@dataclass(frozen=True)
class Episode:
    """The episode metadata of one bag.

    Attributes
    ----------
    summary : EpisodeSummary
        The parsed ``dam_episode.summary``.
    config_text : str or None
        ``dam_episode.config`` (YAML text), ``None`` when absent.
    version : str or None
        ``dam_episode.version``, ``None`` when absent.
    """

    summary: EpisodeSummary
    config_text: str | None
    version: str | None

    def config(self) -> dict[str, Any] | None:
        """``dam_episode.config`` parsed, ``None`` when absent.

        Raises
        ------
        EpisodeError
            If the text is not YAML of a mapping.
        """
        if self.config_text is None:
            return None
        try:
            data = yaml.safe_load(self.config_text)
        except yaml.YAMLError as exc:
            raise EpisodeError(f'{CONFIG_KEY}: not valid YAML: {_one_line(str(exc))}') from None
        if not isinstance(data, dict):
            raise EpisodeError(f'{CONFIG_KEY}: expected a YAML mapping, got '
                               f'{_short(self.config_text)}')
        return data


def _one_line(text: str) -> str:
    return ' '.join(text.split())


def _short(value: Any, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + '...'


def _require(data: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in data:
        raise EpisodeError(f'{where}: missing key {key!r}')
    return data[key]


def _float(value: Any, where: str) -> float:
    """A JSON number, or one of the strings ``nan``, ``inf``, ``-inf``, as a float."""
    if isinstance(value, bool):
        raise EpisodeError(f'{where}: expected a number, got {_short(value)}')
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, str) and value.strip().lower() in _NON_FINITE:
        return _NON_FINITE[value.strip().lower()]
    raise EpisodeError(f'{where}: expected a number (or "nan", "inf", "-inf"), got '
                       f'{_short(value)}')


def _floats(value: Any, where: str) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise EpisodeError(f'{where}: expected a list of numbers, got {_short(value)}')
    return tuple(_float(v, f'{where}[{i}]') for i, v in enumerate(value))


def _int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise EpisodeError(f'{where}: expected an integer, got {_short(value)}')
    return value


def _bool(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise EpisodeError(f'{where}: expected true or false, got {_short(value)}')
    return value


def _str(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise EpisodeError(f'{where}: expected a string, got {_short(value)}')
    return value


def _check_lift(value: Any, where: str) -> CheckLiftRecord | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise EpisodeError(f'{where}: expected an object or null, got {_short(value)}')

    def key(name: str) -> tuple[Any, str]:
        return _require(value, name, where), f'{where}.{name}'

    return CheckLiftRecord(
        ok=_bool(*key('ok')),
        message=_str(*key('message')),
        lift_guaranteed=_bool(*key('lift_guaranteed')),
        worst_case_margin=_float(*key('worst_case_margin')),
        csm_lift=_bool(*key('csm_lift')),
        csm_margin=_float(*key('csm_margin')),
        delta_theta_s=_floats(*key('delta_theta_s')),
        compliant_torque=_floats(*key('compliant_torque')),
    )


def parse_summary(text: str) -> EpisodeSummary:
    """Parse and validate the JSON text of ``dam_episode.summary``.

    Parameters
    ----------
    text : str
        The value of ``custom_data['dam_episode.summary']``.

    Returns
    -------
    EpisodeSummary

    Raises
    ------
    EpisodeError
        If the text is not JSON of an object, a key is missing or a value has the wrong type
        or range; the message names the key (``dam_episode.summary.k_theta[1]``) and the value.
    """
    where = SUMMARY_KEY
    try:
        data = json.loads(text)
    except (TypeError, ValueError) as exc:
        raise EpisodeError(f'{where}: not valid JSON ({exc}): {_short(text)}') from None
    if not isinstance(data, dict):
        raise EpisodeError(f'{where}: expected a JSON object, got {_short(data)}')

    def key(name: str) -> tuple[Any, str]:
        return _require(data, name, where), f'{where}.{name}'

    goal_id = _str(*key('goal_id'))
    if not _GOAL_ID.match(goal_id):
        raise EpisodeError(f'{where}.goal_id: expected 32 lower-case hex digits, got '
                           f'{_short(goal_id)}')
    goal = _require(data, 'goal', where)
    if not isinstance(goal, dict):
        raise EpisodeError(f'{where}.goal: expected an object, got {_short(goal)}')
    outcome = _int(*key('outcome'))
    if not 0 <= outcome < len(OUTCOME_NAMES):
        raise EpisodeError(f'{where}.outcome: expected 0..{len(OUTCOME_NAMES) - 1}, got '
                           f'{outcome}')
    outcome_name = _str(*key('outcome_name'))
    if outcome_name != OUTCOME_NAMES[outcome]:
        raise EpisodeError(
            f'{where}.outcome_name: expected {OUTCOME_NAMES[outcome]!r} for outcome {outcome}, '
            f'got {_short(outcome_name)}')
    return EpisodeSummary(
        goal_id=goal_id,
        accepted_ns=_int(*key('accepted_ns')),
        ended_ns=_int(*key('ended_ns')),
        goal_k_theta=_floats(_require(goal, 'k_theta', f'{where}.goal'),
                             f'{where}.goal.k_theta'),
        goal_delta_theta_p=_floats(_require(goal, 'delta_theta_p', f'{where}.goal'),
                                   f'{where}.goal.delta_theta_p'),
        k_theta=_floats(*key('k_theta')),
        delta_theta_p=_floats(*key('delta_theta_p')),
        friction_angle=_float(*key('friction_angle')),
        check_lift=_check_lift(*key('check_lift')),
        outcome=outcome,
        outcome_name=outcome_name,
        message=_str(*key('message')),
        duration_s=_float(*key('duration_s')),
        pre_roll_s=_float(*key('pre_roll_s')),
        post_roll_s=_float(*key('post_roll_s')),
        object=_str(data['object'], f'{where}.object') if 'object' in data else '',
        wall_duration_s=(_float(data['wall_duration_s'], f'{where}.wall_duration_s')
                         if 'wall_duration_s' in data else None),
    )


def episode_from_custom_data(custom_data: Mapping[str, Any]) -> Episode | None:
    """The episode metadata in a bag's ``custom_data``, ``None`` when it has none.

    Raises
    ------
    EpisodeError
        If ``dam_episode.summary`` is malformed, or ``dam_episode.config`` or
        ``dam_episode.version`` is not a string.
    """
    if SUMMARY_KEY not in custom_data:
        return None
    text = custom_data[SUMMARY_KEY]
    if not isinstance(text, str):
        raise EpisodeError(f'{SUMMARY_KEY}: expected JSON text, got {_short(text)}')
    optional: dict[str, str | None] = {}
    for name in (CONFIG_KEY, VERSION_KEY):
        value = custom_data.get(name)
        if value is not None and not isinstance(value, str):
            raise EpisodeError(f'{name}: expected text, got {_short(value)}')
        optional[name] = value
    return Episode(parse_summary(text), optional[CONFIG_KEY], optional[VERSION_KEY])


def parse_episode_name(name: str) -> tuple[datetime, str] | None:
    """(local time of the name, outcome in lower case) of an episode bag's directory name
    ``<YYYY_MM_DD-HH_MM_SS>_<outcome>``, ``None`` for any other name."""
    match = _EPISODE_NAME.match(name)
    if match is None:
        return None
    try:
        when = datetime(*(int(v) for v in match.groups()[:6]))
    except ValueError:
        return None
    return when, match.group(7)


def format_floats(values: Sequence[float], scale: float = 1.0, digits: int = 4) -> str:
    """``[a, b, c]`` of ``values * scale`` with ``digits`` significant digits (``-`` when
    empty)."""
    if not values:
        return '-'
    return '[' + ', '.join(f'{v * scale:.{digits}g}' for v in values) + ']'
