"""The object's lines run.sh prints under the recorded episode: each rise once, each named.

    bag plot EPISODE -o PICTURE | python scripts/lib/object_summary.py GRASP_LOG

``GRASP_LOG`` is what ``dam_grasp`` printed. Its result line carries the controller's estimate
in the grasp's message (``result: SUCCESS (grasp done: object left the table: rise 9.75 mm
(estimated from the joints); enveloped); ...``), so where ``bag plot``'s lines (standard
input) repeat that estimate, they are reduced to what the result line does not say:

- ``object rise: 9.80 mm (stand-in), 9.75 mm estimated from the joints`` is left out: the
  estimate is in the result line, the stand-in's rise in the next line
  (``object rise (stand-in ground truth, /sim/object_pose, ...): at the end 9.80 mm, ...``);
- ``controller's estimate (from the joints, /dam/episode): rise 9.75 mm, left the table yes,
  orientation 0.0 deg`` becomes ``controller's estimate (from the joints, /dam/episode):
  recorded, as in the result line above; orientation 0.0 deg`` (the orientation stays unless
  the result line gives it, ``turned 5.27 deg``).

A line is reduced only where its figures agree with the result line's (to the digits both
print); every other line, and every line of a grasp whose result line carries no estimate, is
printed as it came. Exit status 0, except 2 for a call without exactly one argument. Pure
Python (the standard library only).
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

#: The controller's estimate in the result line's message (dam_spcm_controller.classification).
_RESULT_ESTIMATE = re.compile(
    r'object (?P<where>left the table|on the table): rise (?P<rise>[-+0-9.eE]+) mm'
    r'(?:, turned (?P<turned>[-+0-9.eE]+) deg)? \(estimated from the joints\)')
#: bag plot's line of both rises (dam_recorder.object_record.object_lines).
_BOTH = re.compile(r'^\s*object rise: [-+0-9.eE]+ mm \(stand-in\), (?P<rise>[-+0-9.eE]+) mm '
                   r'estimated from the joints$')
#: bag plot's line of the controller's estimate as the episode recorded it.
_ESTIMATE = re.compile(
    r"^(?P<label>\s*controller's estimate \(from the joints, /dam/episode\)): "
    r'rise (?P<rise>[-+0-9.eE]+) mm(?:, left the table (?P<left>yes|no))?'
    r'(?:, orientation (?P<orientation>.+))?$')


@dataclass(frozen=True)
class ResultEstimate:
    """The controller's estimate as the result line prints it.

    Attributes
    ----------
    rise : the rise as printed [mm] (three significant digits).
    left_table : whether the object left the table.
    turned : the orientation as printed [deg]; None where the line gives none.
    """

    rise: str
    left_table: bool
    turned: str | None


def result_estimate(grasp_output: str) -> ResultEstimate | None:
    """The estimate in the last ``result: ...`` line of ``grasp_output``; None without one."""
    results = [line for line in grasp_output.splitlines() if line.startswith('result: ')]
    if not results:
        return None
    found = _RESULT_ESTIMATE.search(results[-1])
    if found is None:
        return None
    return ResultEstimate(found['rise'], found['where'] == 'left the table', found['turned'])


def _half_step(text: str) -> float:
    """Half a unit of the last digit ``text`` prints (``'9.75'``: 0.005; ``'123'``: 0.5)."""
    mantissa, _, exponent = text.lower().partition('e')
    return 0.5 * 10.0 ** (int(exponent or 0) - len(mantissa.partition('.')[2]))


def _same(printed: str, other: str) -> bool:
    """Whether two printings of one number agree to the digits both give."""
    try:
        a, b = float(printed), float(other)
        tolerance = _half_step(printed) + _half_step(other)
    except ValueError:
        return False
    return math.isfinite(a) and math.isfinite(b) and abs(a - b) <= tolerance * (1 + 1e-9)


def summarise(plot_lines: list[str], estimate: ResultEstimate | None) -> list[str]:
    """``plot_lines`` without the figures ``estimate`` (the result line's) already gives: see
    the module docstring. Without an estimate, the lines as they are."""
    if estimate is None:
        return list(plot_lines)
    out = []
    for line in plot_lines:
        both = _BOTH.match(line)
        if both is not None and _same(estimate.rise, both['rise']):
            continue  # the estimate: the result line; the stand-in's rise: its own line
        recorded = _ESTIMATE.match(line)
        if recorded is not None and _same(estimate.rise, recorded['rise']) and (
                recorded['left'] is None
                or (recorded['left'] == 'yes') == estimate.left_table):
            orientation = recorded['orientation']
            if orientation is not None and estimate.turned is not None:
                angle = orientation.removesuffix(' deg')
                if orientation.endswith(' deg') and _same(estimate.turned, angle):
                    orientation = None  # the result line's 'turned ... deg'
            line = f'{recorded["label"]}: recorded, as in the result line above'
            if orientation is not None:
                line += f'; orientation {orientation}'
        out.append(line)
    return out


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print('usage: object_summary.py GRASP_LOG < bag-plot-output', file=sys.stderr)
        return 2
    try:
        grasp_output = Path(argv[0]).read_text(encoding='utf-8', errors='replace')
    except OSError:
        grasp_output = ''  # no grasp output: bag plot's lines as they are
    lines = sys.stdin.read().splitlines()
    for line in summarise(lines, result_estimate(grasp_output)):
        print(line)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
