"""scripts/lib/object_summary.py, through which run.sh passes bag plot's object lines: each rise
of the grasp said once, each named (the controller's estimate from the joints in the result
line; the stand-in's measured rise under the recorded episode), nothing else lost.

run.sh printed the rise three times (the result line, dam_grasp's estimate line, and bag
plot's line of both) and, for a grasp without the controller's estimate, added that the
controller 'does not report its own estimate yet'. The object lines here are bag plot's own
(:func:`dam_recorder.object_record.object_lines`)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from dam_recorder.object_record import ObjectEstimate, ObjectTruth, object_lines

SCRIPT = Path(__file__).resolve().parents[2] / 'scripts' / 'lib' / 'object_summary.py'
_spec = importlib.util.spec_from_file_location('run_sh_object_summary', SCRIPT)
assert _spec is not None and _spec.loader is not None
object_summary = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = object_summary  # (its dataclass looks its module up)
_spec.loader.exec_module(object_summary)

#: The stand-in's ground truth of a lifted object (rises [mm]).
TRUTH = ObjectTruth(8.09, 8.21, True, True, 5.56, True)
#: What dam_grasp printed for the configured cylinder (the result line, then its own line).
CYLINDER_GRASP = (
    '[   5.11 s] phase DONE       progress 1.00  outcome SUCCESS\n'
    'result: SUCCESS (grasp done: object left the table: rise 9.75 mm (estimated from the '
    "joints); enveloped); status SUCCEEDED; duration 5.10 s on the grasp's clock (5.11 s wall)\n"
    'object rise: 9.7 mm, left the table (estimated from the joint angles)\n')
ESTIMATE_LINE = "controller's estimate (from the joints, /dam/episode)"


def _plot(estimate: ObjectEstimate | None) -> list[str]:
    """bag plot's lines of a grasp: its header, then the object's lines, indented."""
    return (['out/grasp.png: grasp: SUCCESS, cylinder', '  9 joints, 7 phase spans']
            + [f'  {line}' for line in object_lines(TRUTH, estimate)])


def _summary(grasp: str, plot: list[str]) -> list[str]:
    return object_summary.summarise(plot, object_summary.result_estimate(grasp))


def test_each_rise_once_and_named_where_the_result_line_gives_the_estimate() -> None:
    plot = _plot(ObjectEstimate(9.75, True, '0.0 deg'))
    assert '  object rise: 8.09 mm (stand-in), 9.75 mm estimated from the joints' in plot
    summary = _summary(CYLINDER_GRASP, plot)
    result_line = CYLINDER_GRASP.splitlines()[1]
    shown = '\n'.join([result_line, *summary])
    # the estimate once, in the result line, named; the stand-in's final rise once, named
    assert shown.count('9.75') == 1 and 'rise 9.75 mm (estimated from the joints)' in shown
    assert shown.count('8.09') == 1, shown
    assert ('  object rise (stand-in ground truth, /sim/object_pose, from the first pose): at '
            'the end 8.09 mm, highest 8.21 mm') in summary
    # nothing else lost: the header, the table, and what the result line does not give
    assert summary[:2] == plot[:2]
    assert ("  left the table (stand-in ground truth, /sim/object_table_contact): yes, at 5.56 s;"
            " off the table at the grasp's end: yes") in summary
    assert summary[-1] == (f'  {ESTIMATE_LINE}: recorded, as in the result line above; '
                           'orientation 0.0 deg')
    assert len(summary) == len(plot) - 1


def test_a_turn_the_result_line_gives_is_not_repeated() -> None:
    """A hexagonal bar: the result line says 'turned 5.27 deg', the episode '5.3 deg'; a rise
    of three significant digits (12.3) agrees with the bag's 12.34."""
    grasp = ('result: LIFTED_DAM_FAILED (grasp done: object left the table: rise 12.3 mm, '
             'turned 5.27 deg (estimated from the joints); object not caged by the '
             'fingertips); status ABORTED; duration 6.00 s\n')
    summary = _summary(grasp, _plot(ObjectEstimate(12.34, True, '5.3 deg')))
    assert summary[-1] == f'  {ESTIMATE_LINE}: recorded, as in the result line above'
    assert not any('12.34' in line or 'estimated from the joints' in line for line in summary)


def test_a_grasp_without_the_estimate_keeps_every_line_and_adds_none() -> None:
    """No estimate in the result line (a cancelled grasp): bag plot's lines as they are, the
    stand-in's rise named as its ground truth and the estimate as 'none recorded'; no note
    that the controller does not report one."""
    grasp = ('result: ABORTED (cancelled: torque ramped to zero); status CANCELED; duration '
             '2.00 s\n')
    for estimate in (None, ObjectEstimate(None, False, None)):
        plot = _plot(estimate)
        summary = _summary(grasp, plot)
        assert summary == plot
        assert not any('does not report' in line for line in summary)
    assert f'  {ESTIMATE_LINE}: none recorded' in _summary(grasp, _plot(None))


@pytest.mark.parametrize(('estimate', 'kept'), [
    (ObjectEstimate(8.50, True, '0.0 deg'), 'rise 8.50 mm'),  # another rise than the result's
    (ObjectEstimate(9.75, False, '0.0 deg'), 'left the table no'),  # another verdict
])
def test_lines_that_disagree_with_the_result_line_are_kept(estimate: ObjectEstimate,
                                                           kept: str) -> None:
    """The bag's estimate is the result's; should they ever differ, both are printed."""
    plot = _plot(estimate)
    summary = _summary(CYLINDER_GRASP, plot)
    assert any(line.startswith(f'  {ESTIMATE_LINE}: ') and kept in line for line in summary)


def test_the_script_as_run_sh_calls_it(tmp_path: Path) -> None:
    log = tmp_path / 'dam_grasp.log'
    log.write_text(CYLINDER_GRASP, encoding='utf-8')
    plot = '\n'.join(_plot(ObjectEstimate(9.75, True, '0.0 deg'))) + '\n'
    done = subprocess.run([sys.executable, str(SCRIPT), str(log)], input=plot,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and not done.stderr, done
    assert done.stdout.splitlines() == _summary(CYLINDER_GRASP, plot.splitlines())
    # no grasp log (the client never ran): the lines as they came
    missing = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / 'none.log')],
                             input=plot, capture_output=True, text=True, timeout=60)
    assert missing.returncode == 0 and missing.stdout == plot, missing
    usage = subprocess.run([sys.executable, str(SCRIPT)], input='', capture_output=True,
                           text=True, timeout=60)
    assert usage.returncode == 2 and 'usage: object_summary.py' in usage.stderr
