"""The object in a bag: ``bag info`` and ``bag plot`` show the stand-in's ground truth (rise,
left the table during the grasp, off the table at its end) and the controller's estimate, each
labelled as such, against the values the bags were written with
(tests/dam_recorder/grasp_bags.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import grasp_bags as gb
import pytest

from dam_recorder.bag_cli import main as bag_main
from dam_recorder.bag_info import bag_info
from dam_recorder.bag_info_text import bag_info_json, format_bag_info
from dam_recorder.bag_plot import plot_bag
from dam_recorder.object_record import (
    EPISODE_TOPIC,
    TABLE_CONTACT_TOPIC,
    ObjectCollector,
    ObjectTruth,
    object_lines,
)
from dam_recorder.selection import DEFAULT_TOPICS

ALL = ('/joint_states', '/dam/status', '/sim/object_pose', '/dam_grasp/_action/feedback',
       TABLE_CONTACT_TOPIC, EPISODE_TOPIC)
#: When the bag shows the lift-off: the receive time of contact message LIFT_FROM [s].
LIFT_OFF_S = (gb.POSE_OFFSET_NS + gb.LIFT_FROM * gb.POSE_STEP_NS) * 1e-9
#: Contact message at which the object of the fell-back bag is on the table again (1.502 s).
FALL_AT = gb.LIFT_FROM + 10


@pytest.fixture(scope='module')
def lifted_bag(tmp_path_factory, typestore, prefixes) -> gb.GraspBag:
    """An episode bag with the contact topic and an ENDED event that holds the estimate."""
    return gb.write_grasp_bag(tmp_path_factory.mktemp('object') / 'grasp', typestore, prefixes,
                              topics=ALL, episode=gb.summary(), estimate=gb.ESTIMATE)


def test_the_default_recording_takes_the_contact_topic() -> None:
    assert TABLE_CONTACT_TOPIC in DEFAULT_TOPICS and '/sim/object_pose' in DEFAULT_TOPICS


def _contact(on: bool, off: float, lifted: bool) -> SimpleNamespace:
    """A contact message: on the table, off it for ``off`` [s], lifted (the latch)."""
    return SimpleNamespace(on_table=on, off_table_s=off, lifted=lifted,
                           off_table_at_end=off >= 0.1 - 1e-9)


def test_the_collector_reads_lift_off_without_the_bounce() -> None:
    """Contacts every 10 ms: a bounce at 0.10-0.12 s (not a lift-off), off from 0.30 s to
    0.44 s, back on the table from 0.45 s; the stand-in says lifted from 50 ms into the lift
    on, and off the table at the end from 100 ms into it until it lands."""
    collector = ObjectCollector(start_ns=0)
    for k in range(60):
        t = k * 0.01
        on = not (0.10 <= t < 0.125 or 0.295 <= t < 0.445)
        start = 0.10 if t < 0.2 else 0.30
        off = 0.0 if on else t - start
        collector.add(TABLE_CONTACT_TOPIC, round(t * 1e9),
                      _contact(on, off, t >= 0.35 - 1e-9))
    truth = collector.truth()
    assert truth.lifted and truth.lift_off_s == pytest.approx(0.30)
    assert truth.off_table_at_end is False and truth.rise_final_mm is None
    assert [list(span) for span in truth.off_table_s] == [
        pytest.approx([0.10, 0.12]), pytest.approx([0.30, 0.44])]
    # read at 0.34 s: off for 40 ms, no lift-off yet; at 0.35 s: lifted, not yet off at the
    # end; at 0.42 s: both
    early = collector.truth(end_ns=340_000_000)
    assert early.lifted is False and early.lift_off_s is None
    assert collector.truth(end_ns=350_000_000).lifted is True
    assert collector.truth(end_ns=350_000_000).off_table_at_end is False
    assert collector.truth(end_ns=420_000_000).off_table_at_end is True
    assert collector.estimate() is None  # no ENDED event
    assert object_lines(truth, None)[1] == (
        'left the table (stand-in ground truth, /sim/object_table_contact): yes, at 0.30 s; '
        'off the table at the grasp\'s end: no')


def test_a_lift_off_between_two_messages_or_before_the_first_is_still_a_lift_off() -> None:
    """Messages 100 ms apart: the object off the table from 0.12 to 0.19 s is never seen off
    it, but the next message says lifted: the lift-off is placed at the message before. A
    record that begins lifted has a lift-off without a time."""
    collector = ObjectCollector(start_ns=0)
    for k, lifted in enumerate((False, False, True, True)):
        collector.add(TABLE_CONTACT_TOPIC, k * 100_000_000, _contact(True, 0.0, lifted))
    truth = collector.truth()
    assert truth.lifted and truth.lift_off_s == pytest.approx(0.1) and not truth.off_table_s
    late = ObjectCollector(start_ns=0)
    for k in range(3):
        late.add(TABLE_CONTACT_TOPIC, k * 100_000_000, _contact(False, 0.5 + 0.1 * k, True))
    truth = late.truth()
    assert truth.lifted and truth.lift_off_s is None and truth.off_table_at_end
    assert object_lines(truth, None)[1].endswith(
        ': yes, before the first message read; off the table at the grasp\'s end: yes')


def test_the_first_form_of_the_message_is_read_too() -> None:
    """A message of before the rename: lifted_off (off for 50 ms now) and lifted (off for
    0.1 s now); read as the lift-off and off the table at the end."""
    collector = ObjectCollector(start_ns=0)
    for k in range(30):
        t = k * 0.01
        on = t < 0.095
        off = 0.0 if on else t - 0.10
        collector.add(TABLE_CONTACT_TOPIC, round(t * 1e9), SimpleNamespace(
            on_table=on, lifted_off=off >= 0.05 - 1e-9, lifted=off >= 0.1 - 1e-9))
    truth = collector.truth()
    assert truth.lifted and truth.lift_off_s == pytest.approx(0.10)
    assert truth.off_table_at_end is True
    assert collector.truth(end_ns=170_000_000).off_table_at_end is False


def test_the_estimate_is_taken_where_the_message_has_it() -> None:
    collector = ObjectCollector(0)
    collector.add(EPISODE_TOPIC, 1, SimpleNamespace(event=0, object_rise=9.0))  # STARTED
    assert collector.estimate() is None
    collector.add(EPISODE_TOPIC, 2, SimpleNamespace(event=1))  # an older message: no fields
    assert collector.estimate() is None
    # a grasp that was not classified: NaN rise, placeholders in the other fields
    collector.add(EPISODE_TOPIC, 3, SimpleNamespace(event=1, object_rise=math.nan,
                                                    object_left_table=False,
                                                    object_orientation=math.nan))
    assert collector.estimate() is None
    collector.add(EPISODE_TOPIC, 4, SimpleNamespace(
        event=1, object_rise=0.0042, object_left_table=False,
        object_orientation=SimpleNamespace(x=0.0, y=0.1, z=0.0, w=0.995)))
    estimate = collector.estimate()
    assert estimate.rise_mm == pytest.approx(4.2) and estimate.left_table is False
    assert estimate.orientation == 'quaternion (x 0, y 0.1, z 0, w 0.995)'
    lines = object_lines(ObjectTruth(1.0, 2.0, False, None, None, None), estimate)
    assert lines == [
        'object rise: 1.00 mm (stand-in), 4.20 mm estimated from the joints',  # both, named
        'object rise (stand-in ground truth, /sim/object_pose, from the first pose): at the '
        'end 1.00 mm, highest 2.00 mm',
        'left the table (stand-in ground truth, /sim/object_table_contact): not recorded',
        'controller\'s estimate (from the joints, /dam/episode): rise 4.20 mm, left the table '
        'no, orientation quaternion (x 0, y 0.1, z 0, w 0.995)']


def test_bag_info_shows_the_ground_truth_and_the_estimate(lifted_bag: gb.GraspBag) -> None:
    info = bag_info(lifted_bag.path)
    truth, estimate = info.object_truth, info.object_estimate
    rise_end = (gb.pose_z(gb.POSE_COUNT - 1) - gb.Z0) * 1e3
    assert truth.rise_final_mm == pytest.approx(rise_end) and truth.rise_max_mm == \
        pytest.approx(rise_end)
    assert truth.lifted and truth.lift_off_s == pytest.approx(LIFT_OFF_S, abs=1e-9)
    # read at the goal's end (1.8 s): off the table since 1.302 s
    last_before_end = max(k for k in range(gb.POSE_COUNT)
                          if gb.T0 + gb.POSE_OFFSET_NS + k * gb.POSE_STEP_NS <= gb.ENDED_NS)
    assert truth.off_table_at_end is gb.contact_state(last_before_end)[3] is True
    bounce = ((gb.POSE_OFFSET_NS + gb.BOUNCE[0] * gb.POSE_STEP_NS) * 1e-9,
              (gb.POSE_OFFSET_NS + (gb.BOUNCE[1] - 1) * gb.POSE_STEP_NS) * 1e-9)
    assert truth.off_table_s[0] == pytest.approx(bounce)
    assert estimate.rise_mm == pytest.approx(gb.ESTIMATE['object_rise'] * 1e3)
    assert estimate.left_table is True and estimate.orientation == '11.5 deg'
    text = format_bag_info(info)
    assert (f'left the table (stand-in ground truth, /sim/object_table_contact): yes, at '
            f'{LIFT_OFF_S:.2f} s; off the table at the grasp\'s end: yes') in text
    assert f'at the end {rise_end:.2f} mm' in text
    assert ('controller\'s estimate (from the joints, /dam/episode): rise 6.10 mm, left the '
            'table yes, orientation 11.5 deg') in text
    data = bag_info_json(info)
    assert data['object_truth']['lift_off_s'] == pytest.approx(LIFT_OFF_S)
    assert data['object_truth']['lifted'] is True
    assert data['object_truth']['off_table_at_end'] is True


def test_an_object_that_fell_back_left_the_table_and_is_not_off_it_at_the_end(
        tmp_path, typestore, prefixes) -> None:
    """The object off the table from 1.302 s, back on it at 1.502 s, before the goal's end:
    it left the table (lifted), and was not off it at the grasp's end."""
    bag = gb.write_grasp_bag(tmp_path / 'fell', typestore, prefixes, topics=ALL,
                             episode=gb.summary(), fall_at=FALL_AT)
    truth = bag_info(bag.path).object_truth
    assert truth.lifted and truth.lift_off_s == pytest.approx(LIFT_OFF_S, abs=1e-9)
    assert truth.off_table_at_end is False
    back = (gb.POSE_OFFSET_NS + (FALL_AT - 1) * gb.POSE_STEP_NS) * 1e-9
    assert truth.off_table_s[-1] == pytest.approx((LIFT_OFF_S, back))
    assert (f'left the table (stand-in ground truth, /sim/object_table_contact): yes, at '
            f'{LIFT_OFF_S:.2f} s; off the table at the grasp\'s end: no'
            ) in format_bag_info(bag_info(bag.path))


def test_a_bag_without_the_contact_topic_says_not_recorded(tmp_path, typestore,
                                                           prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'old', typestore, prefixes, episode=gb.summary())
    info = bag_info(bag.path)
    assert info.object_truth is not None and not info.object_truth.contact_recorded
    assert info.object_estimate is None
    text = format_bag_info(info)
    assert ('left the table (stand-in ground truth, /sim/object_table_contact): not recorded'
            in text)
    assert 'controller\'s estimate (from the joints, /dam/episode): none recorded' in text
    # an ENDED event of a controller that does not estimate: still none
    bag = gb.write_grasp_bag(tmp_path / 'plain', typestore, prefixes,
                             topics=ALL, episode=gb.summary())
    assert bag_info(bag.path).object_estimate is None


def test_bag_plot_marks_lift_off_and_the_estimate(lifted_bag: gb.GraspBag,
                                                  tmp_path, capsys) -> None:
    result = plot_bag(lifted_bag.path)
    height_ax = result.figure.axes[6]
    spans = [p for p in height_ax.patches if p.get_gid() == 'off_table']
    assert len(spans) == 2  # the bounce and the lift
    x0 = spans[1].get_x()
    assert x0 == pytest.approx(LIFT_OFF_S, abs=1e-9)
    lines = {line.get_label(): line for line in height_ax.get_lines()}
    assert list(lines['lift-off (stand-in)'].get_xdata()) == pytest.approx([LIFT_OFF_S] * 2)
    assert list(lines['controller\'s estimate'].get_ydata()) == pytest.approx(
        [gb.ESTIMATE['object_rise'] * 1e3] * 2)
    legend = [t.get_text() for t in height_ax.get_legend().get_texts()]
    assert 'off the table (stand-in)' in legend and 'object rise (stand-in)' in legend
    out = tmp_path / 'grasp.png'
    assert bag_main(['plot', str(lifted_bag.path), '-o', str(out)]) == 0
    printed = capsys.readouterr().out
    assert (f'  left the table (stand-in ground truth, /sim/object_table_contact): yes, at '
            f'{LIFT_OFF_S:.2f} s; off the table at the grasp\'s end: yes') in printed
    assert '  controller\'s estimate (from the joints, /dam/episode): rise 6.10 mm' in printed
    assert '  object rise (stand-in ground truth, /sim/object_pose' in printed
