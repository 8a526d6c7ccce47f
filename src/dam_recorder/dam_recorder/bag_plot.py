"""``bag plot``: a grasp as one picture (no rclpy; matplotlib with the Agg backend).

Per finger, the compliant and the position joint's angle [deg] and torque [N*m] from
``/joint_states``; the controller's phases from ``/dam/status`` shaded as labelled spans on
every time axis; the object's rise above its first height [mm] from ``/sim/object_pose``, with
the stretches the stand-in found it off the table (``/sim/object_table_contact``) as a bar, its
lift-off marked and the controller's estimated rise (``/dam/episode``) as a dashed line, each
labelled as what it is (:mod:`dam_recorder.object_record`); the ``/check_lift`` margins from
the episode metadata or, without it, from the last ``/dam_grasp/_action/feedback`` that carries
them. The title names the bag, the outcome
(``, INCOMPLETE episode`` after it when the bag lacks part of the episode,
:mod:`dam_recorder.completeness`), ``k_theta`` and ``delta_theta_p``. Time runs in seconds
from the bag's first message.

A bag of several grasps is shown one grasp at a time, or a time window
(:mod:`dam_recorder.bag_selection`); the title names the grasp shown and its own outcome.
Lines break where a stream pauses (:func:`with_gaps`): no straight line across a gap. The phase
labels above the top axes are stacked in rows so that none overlaps another.

What is missing (a topic, a joint, a torque, what an incomplete episode lacks) is plotted as
far as it is there and listed in the figure and in :attr:`GraspData.missing`.

:func:`read_grasp_data` collects the signals (plain numpy arrays), :func:`grasp_figure` draws
them, :func:`plot_bag` does both and saves the picture.
"""

from __future__ import annotations

import math
import os
import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dam_common.config import JOINT_ROLES
from dam_recorder.bag_info import STATUS_TOPIC, grasps_from_status
from dam_recorder.bag_reading import BagReader, read_bag_metadata
from dam_recorder.bag_selection import Selection, select
from dam_recorder.completeness import describe
from dam_recorder.episode import Episode, format_floats
from dam_recorder.errors import BagReadError
from dam_recorder.object_record import (
    OBJECT_TOPICS,
    ObjectCollector,
    ObjectEstimate,
    ObjectTruth,
    object_lines,
)

JOINT_STATES_TOPIC = '/joint_states'
OBJECT_POSE_TOPIC = '/sim/object_pose'
FEEDBACK_TOPIC = '/dam_grasp/_action/feedback'
#: The fingers drawn when the joint states name none (finger1..finger3).
DEFAULT_FINGERS: tuple[str, ...] = ('finger1', 'finger2', 'finger3')
#: The joint roles drawn per finger (the locked joint does not move).
PLOTTED_ROLES: tuple[str, ...] = tuple(r for r in JOINT_ROLES if r != 'locked')
#: Fill colour of each phase span (``IDLE`` is not shaded).
PHASE_COLOURS: dict[str, str] = {
    'APPROACH': '#9ecae1', 'ROLLING_UP': '#fdd0a2', 'ENVELOPE': '#a1d99b', 'DONE': '#d9d9d9',
    'ABORTED': '#fcbba1', 'FAILED': '#fb6a4a', 'RELEASING': '#dadaeb', 'CHECK_LIFT': '#fff7bc',
    'CLASSIFYING': '#f0f0f0', 'STOPPING': '#fdd49e'}
#: Height of the first row of phase labels, and of each further row [axes fraction].
LABEL_Y = 1.02
LABEL_ROW = 0.11
#: A pause in a stream longer than this many times its median sample interval, and than
#: :data:`GAP_MIN_S`, breaks its line.
GAP_FACTOR = 20.0
#: The shortest pause that breaks a line [s].
GAP_MIN_S = 0.5
#: Height of the bar marking the object off the table [axes fraction].
OFF_TABLE_BAR = 0.06
#: Characters per line of the text panel.
PANEL_WIDTH = 92
_JOINT_NAME = re.compile(r'^(?P<finger>.+)_(?P<role>' + '|'.join(JOINT_ROLES) + r')_joint$')


@dataclass(frozen=True)
class JointSeries:
    """One joint's samples.

    Attributes
    ----------
    time_s : ndarray
        Receive time [s since the bag's first message].
    angle_rad : ndarray
        Joint angle [rad].
    torque_nm : ndarray
        Joint torque [N*m] (``nan`` where a message carried no effort).
    """

    time_s: np.ndarray
    angle_rad: np.ndarray
    torque_nm: np.ndarray


@dataclass(frozen=True)
class PhaseSpan:
    """A phase of the controller: from its first ``/dam/status`` message to the first message
    of the next phase (the last one to the bag's last message) [s since the bag's start]."""

    phase: str
    start_s: float
    end_s: float


@dataclass(frozen=True)
class Margins:
    """The ``/check_lift`` answer shown in the plot.

    Attributes
    ----------
    source : str
        ``'episode metadata'`` or ``'action feedback'``.
    lift_guaranteed, csm_lift : bool
        Sufficient condition (eq. 18); contact stiffness model.
    worst_case_margin, csm_margin : float
        Their margins [N].
    """

    source: str
    lift_guaranteed: bool
    worst_case_margin: float
    csm_lift: bool
    csm_margin: float

    def text(self) -> str:
        """Two lines of text for the figure."""
        def margin(value: float) -> str:
            return f'{value:+.4g} N' if math.isfinite(value) else f'{value} N'

        yes = {True: 'yes', False: 'no'}
        return (f'lift guaranteed (eq. 18): {yes[self.lift_guaranteed]}, worst-case margin '
                f'{margin(self.worst_case_margin)}\ncontact stiffness model: '
                f'{yes[self.csm_lift]}, margin {margin(self.csm_margin)}  '
                f'(from the {self.source})')


@dataclass
class GraspData:
    """The signals of a grasp bag (see the module).

    Attributes
    ----------
    bag : Path
        The bag directory.
    start_ns : int
        The bag's first message [ns since the epoch]; time 0 of every series.
    end_s : float
        The bag's last message [s].
    fingers : list of str
        Finger names, in order.
    joints : dict
        Joint name -> :class:`JointSeries`, for the compliant and position joints found.
    phases : list of PhaseSpan
    height_time_s, height_rise_mm : ndarray or None
        Object pose times [s] and the rise of ``position.z`` above its first value [mm].
    margins : Margins or None
    episode : Episode or None
    outcome : str
        Outcome name from the episode metadata, else from the last grasp on ``/dam/status``,
        else ``'outcome unknown'``.
    missing : list of str
        What the picture lacks, one phrase each.
    object_truth : ObjectTruth or None
        The stand-in's ground truth of the object in the window shown (rise, left the table
        during the grasp, off the table at its end).
    object_estimate : ObjectEstimate or None
        The controller's estimate from its ENDED event, where recorded.
    """

    bag: Path
    start_ns: int
    end_s: float
    fingers: list[str]
    joints: dict[str, JointSeries]
    phases: list[PhaseSpan]
    height_time_s: np.ndarray | None
    height_rise_mm: np.ndarray | None
    margins: Margins | None
    episode: Episode | None
    outcome: str
    missing: list[str] = field(default_factory=list)
    selection: Selection | None = None
    object_truth: ObjectTruth | None = None
    object_estimate: ObjectEstimate | None = None

    @property
    def window_s(self) -> tuple[float, float]:
        """The time shown [s from the bag's first message]."""
        if self.selection is None:
            return 0.0, self.end_s
        return ((self.selection.start_ns - self.start_ns) * 1e-9,
                (self.selection.end_ns - self.start_ns) * 1e-9)

    def title(self) -> str:
        """``<bag>: <outcome>, k_theta = [...] N*m/rad, delta_theta_p = [...] deg``."""
        if self.episode is not None:
            s = self.episode.summary
            if s.k_theta or s.delta_theta_p:
                pair = (f'k_theta = {format_floats(s.k_theta)} N*m/rad, delta_theta_p = '
                        f'{format_floats(s.delta_theta_p, math.degrees(1.0))} deg')
            else:  # it never ran (refused): what was asked
                pair = (f'asked k_theta = {format_floats(s.goal_k_theta)} N*m/rad, '
                        f'delta_theta_p = {format_floats(s.goal_delta_theta_p, math.degrees(1.0))}'
                        ' deg')
            if s.object:
                pair = f'{s.object}, {pair}'
        else:
            pair = 'k_theta and delta_theta_p unknown (no episode metadata)'
        shown = ''
        if self.selection is not None and self.selection.grasp_count > 1:
            shown = (f' (grasp {self.selection.grasp} of {self.selection.grasp_count})'
                     if self.selection.grasp is not None else
                     f' ({self.selection.description})')
        return f'{self.bag.name}{shown}: {self.outcome}, {pair}'


def joint_name(finger: str, role: str) -> str:
    """``<finger>_<role>_joint``."""
    return f'{finger}_{role}_joint'


def phase_spans(status: Sequence[tuple[float, str]], end_s: float) -> list[PhaseSpan]:
    """Runs of equal phases in ``(time [s], phase)`` status samples (time order)."""
    spans: list[PhaseSpan] = []
    for time_s, phase in status:
        if spans and spans[-1].phase == phase:
            continue
        if spans:
            spans[-1] = PhaseSpan(spans[-1].phase, spans[-1].start_s, time_s)
        spans.append(PhaseSpan(phase, time_s, time_s))
    if spans:
        spans[-1] = PhaseSpan(spans[-1].phase, spans[-1].start_s, max(end_s, spans[-1].start_s))
    return spans


def _joint_series(samples: dict[str, list[tuple[float, float, float]]]
                  ) -> dict[str, JointSeries]:
    out = {}
    for name, rows in samples.items():
        data = np.asarray(rows, dtype=float).reshape(-1, 3)
        out[name] = JointSeries(data[:, 0], data[:, 1], data[:, 2])
    return out


def with_gaps(time_s: np.ndarray, *values: np.ndarray) -> tuple[np.ndarray, ...]:
    """``time_s`` and ``values`` with a NaN sample inserted in every pause longer than
    ``max(GAP_MIN_S, GAP_FACTOR x the median interval)``, so that a line breaks there."""
    t = np.asarray(time_s, dtype=float)
    if t.size < 3:
        return (t, *(np.asarray(v, dtype=float) for v in values))
    steps = np.diff(t)
    limit = max(GAP_MIN_S, GAP_FACTOR * float(np.median(steps)))
    cuts = np.flatnonzero(steps > limit) + 1
    if not cuts.size:
        return (t, *(np.asarray(v, dtype=float) for v in values))
    middle = 0.5 * (t[cuts - 1] + t[cuts])
    return (np.insert(t, cuts, middle),
            *(np.insert(np.asarray(v, dtype=float), cuts, np.nan) for v in values))


def read_selection(bag_dir: str | os.PathLike[str], *, episode: int | None = None,
                   start_s: float | None = None, end_s: float | None = None) -> Selection:
    """The part of the bag to show (:func:`dam_recorder.bag_selection.select`), from its
    ``/dam/status`` and its messages' receive times.

    Raises
    ------
    BagReadError
        The bag cannot be read, or the selection does not fit it.
    """
    meta = read_bag_metadata(bag_dir)
    status: list[tuple[int, str, int, str]] = []
    with BagReader(meta.path) as bag:
        times = bag.receive_times()
        nonempty = [t for t, v in times.items() if v.size]
        start_ns = min((int(times[t][0]) for t in nonempty), default=meta.start_ns)
        end_ns = max((int(times[t][-1]) for t in nonempty), default=start_ns)
        if STATUS_TOPIC in bag.topics:
            for item in bag.messages([STATUS_TOPIC]):
                status.append((item.time_ns, str(item.message.phase),
                               int(item.message.outcome), str(item.message.message)))
    return select(grasps_from_status(status), start_ns, end_ns, episode=episode,
                  start_s=start_s, end_s=end_s)


def read_grasp_data(bag_dir: str | os.PathLike[str],
                    selection: Selection | None = None) -> GraspData:
    """Collect the signals :func:`grasp_figure` draws from one bag, within ``selection``
    (default: the whole bag).

    Raises
    ------
    BagReadError
        If the bag cannot be read or its episode metadata is malformed.
    """
    meta = read_bag_metadata(bag_dir)
    episode = meta.episode()
    wanted = [JOINT_STATES_TOPIC, STATUS_TOPIC, OBJECT_POSE_TOPIC, FEEDBACK_TOPIC]
    samples: dict[str, list[tuple[float, float, float]]] = {}
    status: list[tuple[int, str, int, str]] = []
    heights: list[tuple[float, float]] = []
    feedback: Margins | None = None
    index_cache: dict[tuple[str, ...], dict[str, int]] = {}
    with BagReader(meta.path) as bag:
        present = bag.topics
        times = bag.receive_times()
        nonempty = [t for t, v in times.items() if v.size]
        start_ns = min((int(times[t][0]) for t in nonempty), default=meta.start_ns)
        end_ns = max((int(times[t][-1]) for t in nonempty), default=start_ns)
        objects = ObjectCollector(start_ns)
        for item in bag.messages([t for t in {*wanted, *OBJECT_TOPICS} if t in present]):
            t_s = (item.time_ns - start_ns) * 1e-9
            msg = item.message
            if selection is not None and not selection.contains(item.time_ns):
                if item.topic == STATUS_TOPIC and item.time_ns < selection.start_ns:
                    # the phase at the window's start
                    status[:] = [(selection.start_ns, str(msg.phase), int(msg.outcome),
                                  str(msg.message))]
                continue
            objects.add(item.topic, item.time_ns, msg)
            if item.topic == JOINT_STATES_TOPIC:
                names = tuple(msg.name)
                index = index_cache.setdefault(names, {n: i for i, n in enumerate(names)})
                for name, i in index.items():
                    if _JOINT_NAME.match(name) is None:
                        continue
                    angle = float(msg.position[i]) if i < len(msg.position) else math.nan
                    torque = float(msg.effort[i]) if i < len(msg.effort) else math.nan
                    samples.setdefault(name, []).append((t_s, angle, torque))
            elif item.topic == STATUS_TOPIC:
                status.append((item.time_ns, str(msg.phase), int(msg.outcome),
                               str(msg.message)))
            elif item.topic == OBJECT_POSE_TOPIC:
                heights.append((t_s, float(msg.pose.position.z)))
            elif item.topic == FEEDBACK_TOPIC and bool(msg.feedback.lift_checked):
                fb = msg.feedback
                feedback = Margins('action feedback', bool(fb.lift_guaranteed),
                                   float(fb.worst_case_margin), bool(fb.csm_lift),
                                   float(fb.csm_margin))
    end_s = (end_ns - start_ns) * 1e-9
    shown_end_s = end_s if selection is None else (selection.end_ns - start_ns) * 1e-9
    missing: list[str] = []
    for topic in wanted:
        if topic not in present:
            missing.append(f'{topic}: not in the bag')
        elif not times[topic].size:
            missing.append(f'{topic}: no messages')
    joints = _joint_series(samples)
    fingers = list(DEFAULT_FINGERS)
    for name in joints:
        finger = _JOINT_NAME.match(name)
        if finger and finger['finger'] not in fingers:
            fingers.append(finger['finger'])
    if JOINT_STATES_TOPIC in present and times[JOINT_STATES_TOPIC].size:
        for finger in fingers:
            for role in PLOTTED_ROLES:
                name = joint_name(finger, role)
                if name not in joints:
                    missing.append(f'{name}: not in {JOINT_STATES_TOPIC}')
                elif np.all(np.isnan(joints[name].torque_nm)):
                    missing.append(f'{name}: no effort (torque)')
    margins = feedback
    if episode is not None:
        check = episode.summary.check_lift
        margins = None if check is None else Margins(
            'episode metadata', check.lift_guaranteed, check.worst_case_margin,
            check.csm_lift, check.csm_margin)
    if margins is None:
        missing.append('check_lift margins: none recorded')
    several = selection is not None and selection.grasp_count > 1
    if episode is not None and not several:
        outcome = episode.summary.outcome_name
    elif selection is not None and selection.outcome is not None:
        outcome = selection.outcome  # the grasp shown, not the bag's last
    else:
        grasps = grasps_from_status(status)
        outcome = grasps[-1].outcome if grasps else 'outcome unknown'
    completeness = meta.completeness()
    if completeness is not None and not completeness.complete:
        outcome += ', INCOMPLETE episode'  # the bag lacks part of it: the picture too
        missing += [f'episode: {line}' for line in describe(completeness.missing)]
    grasp_end_ns = episode.summary.ended_ns if episode is not None and not several else (
        selection.end_ns if selection is not None else None)
    height_t = height_mm = None
    if heights:
        h = np.asarray(heights, dtype=float)
        height_t, height_mm = h[:, 0], (h[:, 1] - h[0, 1]) * 1000.0
    return GraspData(
        bag=meta.path, start_ns=start_ns, end_s=end_s, fingers=fingers, joints=joints,
        phases=phase_spans([((t - start_ns) * 1e-9, p) for t, p, _, _ in status],
                           shown_end_s),
        height_time_s=height_t, height_rise_mm=height_mm, margins=margins, episode=episode,
        outcome=outcome, missing=missing, selection=selection,
        object_truth=objects.truth(grasp_end_ns), object_estimate=objects.estimate())


def _shade_phases(ax: Any, phases: Sequence[PhaseSpan], label: bool) -> None:
    for span in phases:
        if span.phase == 'IDLE':
            continue
        ax.axvspan(span.start_s, span.end_s, color=PHASE_COLOURS.get(span.phase, '#eeeeee'),
                   alpha=0.6, lw=0, label=f'phase {span.phase}', gid='phase', zorder=0)
        if label:  # stacked in rows by _stack_labels once the figure is laid out
            ax.text((span.start_s + span.end_s) / 2, LABEL_Y, span.phase, ha='center',
                    va='bottom', fontsize=7, transform=ax.get_xaxis_transform(),
                    gid='phase_label', clip_on=False)


def _stack_labels(fig: Any) -> None:
    """Move the phase labels of each axes into rows above it so that no two overlap: each
    label takes the lowest row where it clears the labels already there (measured with the
    figure's renderer); a label whose span lies outside the axes is hidden."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        labels = [t for t in ax.texts if t.get_gid() == 'phase_label']
        if not labels:
            continue
        low, high = ax.get_xlim()
        rows: list[float] = []  # the right edge of the last label in each row [px]
        for text in sorted(labels, key=lambda t: t.get_position()[0]):
            x = text.get_position()[0]
            if not low <= x <= high:
                text.set_visible(False)
                continue
            box = text.get_window_extent(renderer)
            pad = 0.3 * box.height
            row = next((i for i, right in enumerate(rows) if box.x0 > right + pad), len(rows))
            if row == len(rows):
                rows.append(-math.inf)
            rows[row] = box.x1
            text.set_y(LABEL_Y + row * LABEL_ROW)


def _legend(ax: Any) -> None:
    """A legend of the lines only (the phases are labelled above the top axes), by role."""
    lines = ax.get_lines()
    if lines:
        names = [_JOINT_NAME.match(str(line.get_label())) for line in lines]
        ax.legend(lines, [m['role'] if m else line.get_label()
                          for m, line in zip(names, lines, strict=True)],
                  loc='upper left', fontsize=7)


def _say_missing(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, text, ha='center', va='center', transform=ax.transAxes, color='0.4',
            gid='missing')


def grasp_figure(data: GraspData) -> Any:
    """Draw ``data`` into a new matplotlib Figure (Agg canvas) and return it.

    Every line carries its joint name (or ``object rise (stand-in)``, ``lift-off (stand-in)``,
    ``controller's estimate``) as label: angle axes in deg,
    torque axes in N*m, the height axis in mm. Phase spans are patches with ``gid='phase'``
    and ``label='phase <NAME>'``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = len(data.fingers) + 1
    fig = Figure(figsize=(13, 2.6 * rows + 0.8), layout='constrained')
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 2, sharex=True, squeeze=False)
    fig.suptitle(data.title(), fontsize=11)
    for row, finger in enumerate(data.fingers):
        angle_ax, torque_ax = axes[row]
        angle_ax.set_ylabel(f'{finger}\nangle [deg]')
        torque_ax.set_ylabel('torque [N*m]')
        drawn = False
        for role in PLOTTED_ROLES:
            name = joint_name(finger, role)
            series = data.joints.get(name)
            if series is None:
                continue
            drawn = True
            t, angle, torque = with_gaps(series.time_s, np.degrees(series.angle_rad),
                                         series.torque_nm)
            angle_ax.plot(t, angle, label=name, lw=1.2)
            if not np.all(np.isnan(series.torque_nm)):
                torque_ax.plot(t, torque, label=name, lw=1.2)
        for ax in (angle_ax, torque_ax):
            _shade_phases(ax, data.phases, label=row == 0)
            if drawn:
                _legend(ax)
            else:
                _say_missing(ax, f'no {finger} joints in {JOINT_STATES_TOPIC}')
            ax.grid(True, lw=0.3)
    height_ax, text_ax = axes[-1]
    height_ax.set_ylabel('object rise [mm]')
    height_ax.set_xlabel('time [s] from the bag start')
    _shade_phases(height_ax, data.phases, label=False)
    truth, estimate = data.object_truth, data.object_estimate
    for i, (start, end) in enumerate(truth.off_table_s if truth is not None else ()):
        # a bar along the bottom of the axes, apart from the phase shading
        height_ax.axvspan(start, end, ymin=0.0, ymax=OFF_TABLE_BAR, color='k', alpha=0.55,
                          lw=0, gid='off_table',
                          label='off the table (stand-in)' if i == 0 else None, zorder=1)
    if truth is not None and truth.lift_off_s is not None:
        height_ax.axvline(truth.lift_off_s, color='k', lw=1.0, ls=':', gid='lift_off',
                          label='lift-off (stand-in)')
    if data.height_time_s is not None and data.height_rise_mm is not None:
        height_ax.plot(*with_gaps(data.height_time_s, data.height_rise_mm),
                       label='object rise (stand-in)', color='k', lw=1.2)
        if estimate is not None and estimate.rise_mm is not None:
            height_ax.axhline(estimate.rise_mm, color='tab:red', lw=1.0, ls='--',
                              label='controller\'s estimate', gid='estimated_rise')
        spans = [p for p in height_ax.patches if p.get_gid() == 'off_table'][:1]
        height_ax.legend([*height_ax.get_lines(), *spans],
                         [h.get_label() for h in [*height_ax.get_lines(), *spans]],
                         loc='upper left', fontsize=7)
        # Millimetres as they are (no offset), at least 1 mm of axis: a still object's
        # micrometre noise must not look like a lift.
        height_ax.ticklabel_format(axis='y', useOffset=False, style='plain')
        finite = data.height_rise_mm[np.isfinite(data.height_rise_mm)]
        if finite.size and float(finite.max() - finite.min()) < 1.0:
            middle = 0.5 * float(finite.max() + finite.min())
            height_ax.set_ylim(middle - 0.5, middle + 0.5)
    else:
        _say_missing(height_ax, f'no {OBJECT_POSE_TOPIC} in the bag')
    height_ax.grid(True, lw=0.3)
    axes[-2][1].tick_params(labelbottom=True)  # the text panel below has no time axis
    axes[-2][1].set_xlabel('time [s] from the bag start')
    text_ax.axis('off')
    lines = ['check_lift:', data.margins.text() if data.margins else 'no margins recorded']
    if truth is not None:
        lines += ['', *(textwrap.fill(line, PANEL_WIDTH, subsequent_indent='  ')
                        for line in object_lines(truth, estimate))]
    if data.episode is not None and data.episode.summary.message:
        lines += ['', f'{data.episode.summary.outcome_name}: {data.episode.summary.message}']
    if data.missing:
        lines += ['', 'missing:', *data.missing]
    if data.selection is not None and data.selection.notes:
        lines += ['', *data.selection.notes]
    text_ax.text(0.0, 1.0, '\n'.join(lines), ha='left', va='top', fontsize=8,
                 family='monospace', transform=text_ax.transAxes, gid='margins', wrap=True)
    low, high = data.window_s
    if high > low:
        axes[0][0].set_xlim(low, high)
    _stack_labels(fig)
    return fig


@dataclass(frozen=True)
class PlotResult:
    """What :func:`plot_bag` made: the figure and the data it shows."""

    figure: Any
    data: GraspData


def plot_bag(bag_dir: str | os.PathLike[str],
             output: str | os.PathLike[str] | None = None, dpi: int = 110, *,
             episode: int | None = None, start_s: float | None = None,
             end_s: float | None = None) -> PlotResult:
    """Read ``bag_dir``, draw one grasp (``episode``, 1-based; default: the only one, or the
    last of several) or the window ``start_s`` to ``end_s`` [s from the bag's first message],
    and save it to ``output`` (PNG, PDF, SVG by its suffix) when given.

    Raises
    ------
    BagReadError
        If the bag cannot be read, the selection does not fit it, or the picture cannot be
        written (naming the file).
    """
    selection = read_selection(bag_dir, episode=episode, start_s=start_s, end_s=end_s)
    data = read_grasp_data(bag_dir, selection)
    figure = grasp_figure(data)
    if output is not None:
        path = Path(output)
        try:
            figure.savefig(path, dpi=dpi)
        except (OSError, ValueError) as exc:
            raise BagReadError(f'{path}: cannot write the picture: '
                               f'{" ".join(str(exc).split())}') from None
    return PlotResult(figure, data)
