"""``--help`` and ``-h`` on a node executable: its usage, parameters and topics, and exit.

A node executable has no argument parser of its own: everything after ``--ros-args`` is
rcl's. Without this, ``check_lift_server --help`` brought up a second server and
``spcm_controller --help`` a second controller with the same name. :func:`answer_help` runs
before anything of ROS is imported: the text is the node module's docstring (its sections
*Parameters*, *Topics*, *Services*), read from the source without importing it, with the reST
markup removed. No rclpy (the entry point calls it first).
"""

from __future__ import annotations

import ast
import importlib.util
import os
import re
import sys
from collections.abc import Sequence

from dam_common.ros_args import strip_ros_args

#: The words that ask for help (outside ``--ros-args ... --``).
HELP_FLAGS = ('-h', '--help')

_ROLE = re.compile(r':[a-z]+:`~?([^`]+)`')


def wants_help(argv: Sequence[str]) -> bool:
    """Whether ``argv`` (without the program name) asks for help outside its ROS arguments."""
    return any(arg in HELP_FLAGS for arg in strip_ros_args(argv))


def module_docstring(module: str) -> str:
    """The docstring of ``module``, read from its source file (the module is not imported).

    Raises
    ------
    ModuleNotFoundError
        No such module.
    """
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(module)
    with open(spec.origin, encoding='utf-8') as stream:
        return ast.get_docstring(ast.parse(stream.read())) or ''


def plain_text(rest: str) -> str:
    """reST of a docstring as plain text: roles (``:mod:`~a.b```) become their target's last
    name, double back-quotes go."""
    text = _ROLE.sub(lambda m: m.group(1).rsplit('.', 1)[-1] if m.group(0).find('~') > 0
                     else m.group(1), rest)
    return text.replace('``', '')


def help_text(module: str, executable: str) -> str:
    """The help of the node executable ``executable`` whose node lives in ``module``."""
    package = module.split('.', 1)[0]
    node_name = executable
    return (
        f'usage: ros2 run {package} {executable} [-h] [--ros-args [-p NAME:=VALUE] '
        f'[--params-file FILE] [-r FROM:=TO] [--log-level LEVEL] --]\n\n'
        f'{plain_text(module_docstring(module))}\n\n'
        'ROS arguments (after --ros-args): -p NAME:=VALUE sets a parameter, --params-file FILE\n'
        'sets many (keyed by node name, or /** for all), -r __node:=NAME renames the node,\n'
        '-r FROM:=TO remaps a topic or service. On a running node:\n'
        f'  ros2 param list /{node_name}        ros2 param describe /{node_name} NAME\n'
        f'  ros2 node info /{node_name}\n')


def answer_help(module: str, argv: Sequence[str] | None = None,
                executable: str | None = None) -> bool:
    """If the command line asks for help, print it to standard output and return True.

    Parameters
    ----------
    module : the module of the node (``dam_analysis.check_lift_server``).
    argv : the arguments without the program name (default: ``sys.argv[1:]``).
    executable : the executable's name (default: the base name of ``sys.argv[0]``).
    """
    args = sys.argv[1:] if argv is None else argv
    if not wants_help(args):
        return False
    name = executable or os.path.basename(sys.argv[0]) or module.rsplit('.', 1)[-1]
    sys.stdout.write(help_text(module, name))
    sys.stdout.flush()
    return True
