"""``bag info`` in words and as JSON: :class:`~dam_recorder.bag_info.BagInfo` and
:class:`~dam_recorder.bag_info.EpisodesInfo` as the text and the ``--json`` data the command
prints (no rclpy, no I/O)."""

from __future__ import annotations

import dataclasses
import math
from datetime import datetime
from pathlib import Path
from typing import Any

from dam_common.words import counted
from dam_recorder.bag_info import OPEN_HINT, STATUS_TOPIC, BagInfo, EpisodesInfo, is_open
from dam_recorder.completeness import Completeness, describe
from dam_recorder.episode import Episode, format_floats
from dam_recorder.object_record import ObjectTruth, object_lines

# -- text ------------------------------------------------------------------------------------

#: Stamps before 2000-01-01 [ns] are no dates: a simulated clock (``use_sim_time``, the
#: stand-in's ``/clock``) counts from 0 at its start.
DATE_FROM_NS = 946_684_800 * 1_000_000_000


def simulated(time_ns: int | None) -> bool:
    """The stamp ``time_ns`` [ns] is on a simulated clock (before 2000: no date)."""
    return time_ns is not None and time_ns < DATE_FROM_NS


def local_time(time_ns: int | None) -> str:
    """``YYYY-MM-DD HH:MM:SS.mmm`` in local time (``-`` for ``None``); a stamp of a simulated
    clock (:func:`simulated`) as ``sim 12.345 s``, never a date in 1970."""
    if time_ns is None:
        return '-'
    if simulated(time_ns):
        return f'sim {time_ns * 1e-9:.3f} s'
    return datetime.fromtimestamp(time_ns * 1e-9).strftime('%Y-%m-%d %H:%M:%S.%f')[:-3]


def clock_name(time_ns: int | None) -> str:
    """Which clock the bag's times are on, judged by its first stamp ``time_ns`` [ns]."""
    return 'simulated time' if simulated(time_ns) else 'wall-clock time'


def grasp_time(s: Any, bag_start_ns: int | None) -> str:
    """The grasp's duration with its clock: the summary's ``duration_s`` is on the grasp's
    clock (simulated time in a bag on simulated time) when the controller also reported
    ``wall_duration_s``; a controller that did not measured it on the wall clock."""
    wall = getattr(s, 'wall_duration_s', None)
    if wall is None or not math.isfinite(wall):
        return f'{s.duration_s:.3f} s wall-clock'
    clock = 'simulated' if simulated(bag_start_ns) else 'steady-clock'
    return f'{s.duration_s:.3f} s {clock} ({wall:.3f} s wall-clock)'


def _num(value: float | None, spec: str) -> str:
    """``value`` in ``spec``; '-' when it is unknown (None or NaN: an episode cut short)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return '-'
    return format(value, spec)


def _margin(value: float) -> str:
    return f'{value:+.4g} N' if math.isfinite(value) else f'{value} N'


def _yes(value: bool | None) -> str:
    return '-' if value is None else ('yes' if value else 'no')


def _table(header: list[str], rows: list[list[str]], right: set[int]) -> list[str]:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = []
    for row in [header, *rows]:
        cells = [c.rjust(w) if i in right else c.ljust(w)
                 for i, (c, w) in enumerate(zip(row, widths, strict=True))]
        lines.append('  '.join(cells).rstrip())
    return lines


def episode_lines(episode: Episode, bag_start_ns: int | None = None) -> list[str]:
    """The episode metadata as text lines (``bag_start_ns`` [ns]: the bag's first stamp,
    which tells its clock)."""
    s = episode.summary
    lines = [f'episode:    {s.outcome_name} ({s.message})',
             f'  goal id {s.goal_id}, grasp {grasp_time(s, bag_start_ns)}, pre-roll '
             f'{s.pre_roll_s:g} s, post-roll {s.post_roll_s:g} s (bag time), object '
             f'{s.object or "not recorded"}',
             f'  k_theta [N*m/rad] {format_floats(s.k_theta)}   delta_theta_p [deg] '
             f'{format_floats(s.delta_theta_p, math.degrees(1.0))}   friction angle '
             f'{math.degrees(s.friction_angle):.4g} deg',
             f'  goal as sent: k_theta [N*m/rad] {format_floats(s.goal_k_theta)}   '
             f'delta_theta_p [deg] {format_floats(s.goal_delta_theta_p, math.degrees(1.0))}'
             ' (empty: the configured value)']
    c = s.check_lift
    if c is None:
        lines.append('  check_lift: none')
    else:
        lines.append(f'  check_lift: lift guaranteed {_yes(c.lift_guaranteed)} '
                     f'(worst-case margin {_margin(c.worst_case_margin)}), contact stiffness '
                     f'model {_yes(c.csm_lift)} (margin {_margin(c.csm_margin)})')
    config = 'none' if episode.config_text is None else \
        counted(len(episode.config_text.splitlines()), 'line')
    lines.append(f'  config: {config}; version: {episode.version or "none"}')
    return lines


def completeness_lines(completeness: Completeness | None) -> list[str]:
    """Whether the episode bag is complete, and what it lacks, as text lines."""
    if completeness is None:
        return []
    if completeness.complete:
        return ['complete:   yes']
    lines = ['complete:   NO, INCOMPLETE: the bag lacks',
             *(f'  {line}' for line in describe(completeness.missing))]
    if is_open(completeness):
        lines.append(f'  ({OPEN_HINT})')
    return lines


def format_bag_info(info: BagInfo) -> str:
    """``info`` as the text ``bag info`` prints."""
    start = info.start_ns
    if simulated(start):
        started = (f'{local_time(start)} (simulated time: the stand-in\'s /clock counts from '
                   '0 at its start, so no date)')
    else:
        started = local_time(start) + ('' if start is None else ' (wall-clock time)')
    lines = [f'bag:        {info.path}',
             f'storage:    {info.storage} ({len(info.files)} file'
             f'{"" if len(info.files) == 1 else "s"}: {", ".join(info.files)})',
             f'start:      {started}',
             f'duration:   {info.duration_ns * 1e-9:.3f} s {clock_name(start)}',
             f'messages:   {info.message_count}']
    rows = []
    for t in info.topics:
        gap = '-' if t.max_gap_ns is None or start is None or t.max_gap_at_ns is None else \
            f'{t.max_gap_ns * 1e-9:.3f} at {(t.max_gap_at_ns - start) * 1e-9:.3f}'
        rows.append([t.name, t.type, str(t.count), _num(t.rate_hz, '.2f'), gap,
                     str(t.lost), str(t.dropped), str(t.paused), str(t.trimmed)])
    header = ['topic', 'type', 'count', 'rate [Hz]', 'largest gap [s] at [s]', 'lost',
              'dropped', 'paused', 'trimmed']
    lines += ['', *_table(header, rows, {2, 3, 4, 5, 6, 7, 8})]
    others = sorted({*info.lost, *info.dropped, *info.paused, *info.trimmed}
                    - {t.name for t in info.topics})
    for name in others:
        lines.append(f'(not in the bag) {name}: lost {info.lost.get(name, 0)}, dropped '
                     f'{info.dropped.get(name, 0)}, paused {info.paused.get(name, 0)}, '
                     f'trimmed {info.trimmed.get(name, 0)}')
    if info.backlog is not None:
        lines.append(f'backlog:    max {info.backlog["max_s"]:.3f} s, mean '
                     f'{info.backlog["mean_s"]:.3f} s over '
                     f'{counted(info.backlog["messages"], "message")} '
                     '(from receipt to the bag)')
    lines.append('')
    lines += episode_lines(info.episode, start) if info.episode else ['episode:    none']
    lines += completeness_lines(info.completeness)
    if info.grasps:
        lines.append(f'grasps on {STATUS_TOPIC} (bag time from the start):')
        for i, g in enumerate(info.grasps, 1):
            t0 = (g.start_ns - start) * 1e-9 if start is not None else 0.0
            t1 = '-' if g.end_ns is None or start is None else f'{(g.end_ns - start) * 1e-9:.3f}'
            lines.append(f'  {i}: {t0:.3f} s to {t1} s: {g.end_phase}, outcome {g.outcome}'
                         + (f' ({g.message})' if g.message else ''))
    else:
        lines.append(f'grasps on {STATUS_TOPIC}: none')
    if info.object_truth is not None or info.object_estimate is not None:
        truth = info.object_truth or ObjectTruth(None, None, False, None, None, None)
        lines += object_lines(truth, info.object_estimate)
    return '\n'.join(lines)


def format_episodes(info: EpisodesInfo) -> str:
    """``info`` as the tables ``bag info`` prints for a directory of bags: the episodes with
    their outcomes and totals, then the ordinary bags with their sizes."""
    episodes, bags = info.episodes, info.bags
    counted = [f'{len(episodes)} episode{"" if len(episodes) == 1 else "s"}']
    if bags:
        counted.append(f'{len(bags)} other bag{"" if len(bags) == 1 else "s"} (not episodes)')
    lines = [f'{info.path}: {", ".join(counted)}']
    if episodes:
        rows = []
        for r in episodes:
            # a grasp without its wall time reported was timed on the wall clock
            grasp, wall = ((r.grasp_duration_s, r.grasp_wall_s) if r.grasp_wall_s is not None
                           else (None, r.grasp_duration_s))
            rows.append([r.name, local_time(r.start_ns), _num(r.bag_duration_s, '.3f'),
                         _num(grasp, '.3f'), _num(wall, '.3f'), r.outcome,
                         '-' if r.complete is None else ('yes' if r.complete else 'NO'),
                         format_floats(r.k_theta),
                         format_floats(r.delta_theta_p, math.degrees(1.0)),
                         _yes(r.lift_guaranteed)])
        header = ['episode', 'start', 'bag [s]', 'grasp [s]', 'grasp wall [s]', 'outcome',
                  'complete', 'k_theta [N*m/rad]', 'delta_theta_p [deg]', 'lift guaranteed']
        lines += ['', *_table(header, rows, {2, 3, 4})]
        lines.append(_TIMES_NOTE)
        incomplete = [r for r in episodes if r.complete is False]
        if incomplete:
            lines += ['', 'incomplete (the bag lacks part of the episode):']
            for r in incomplete:
                lines.append(f'  {r.name}:')
                lines += [f'    {line}' for line in r.missing] or ['    (not recorded)']
        lines += ['', 'totals (every episode by its outcome):']
        incomplete = info.incomplete_totals
        for outcome, count in info.totals.items():
            cut = incomplete.get(outcome, 0)
            lines.append(f'  {outcome:<18} {count}' + (
                f'  ({"it is" if count == 1 else f"{cut} of them"} INCOMPLETE)' if cut else ''))
        if incomplete:
            lines.append(f'  {"INCOMPLETE":<18} {sum(incomplete.values())}  (counted above by '
                         'their outcome)')
    if bags:
        rows = [[r.name, local_time(r.start_ns), _num(r.bag_duration_s, '.3f'),
                 _num(r.message_count, 'd'), _num(r.topic_count, 'd')] for r in bags]
        lines += ['', 'bags (no episode metadata: bag info BAG describes one, its grasps '
                      'included):',
                  *_table(['bag', 'start', 'duration [s]', 'messages', 'topics'], rows,
                          {2, 3, 4}),
                  '(start and duration on the bag\'s clock: "sim" is simulated time)']
    return '\n'.join(lines)


#: What the episode table's times are.
_TIMES_NOTE = ('(start, bag [s] and grasp [s] on the bag\'s clock, "sim": simulated time, '
               'the stand-in\'s; grasp wall [s] on the wall clock)')


# -- JSON ------------------------------------------------------------------------------------

def jsonable(value: Any) -> Any:
    """``value`` (dataclasses, paths, tuples, floats) as JSON-ready Python; non-finite floats
    become the strings ``"nan"``, ``"inf"``, ``"-inf"``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return 'nan' if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value


def bag_info_json(info: BagInfo) -> dict[str, Any]:
    """``info`` for ``--json``: every field, plus ``duration_ns``."""
    data = jsonable(info)
    data['duration_ns'] = info.duration_ns
    return data


def episodes_json(info: EpisodesInfo) -> dict[str, Any]:
    """``info`` for ``--json``: the rows, the totals per outcome (every episode) and the
    incomplete episodes per outcome."""
    return {'path': str(info.path), 'episodes': jsonable(info.episodes),
            'bags': jsonable(info.bags), 'totals': info.totals,
            'incomplete': info.incomplete_totals}
