"""Which topics the recorder records: a list, a regular expression, an exclusion.

A topic is recorded when it is in the list or the regular expression matches it (anywhere in
the name, as ``re.search`` and ``ros2 bag record --regex`` do), and the exclusion does not match
it. Names are absolute: a name given without a leading ``/`` is taken relative to ``/``. An
empty name is ignored, so that a list of one empty name (``['']``, which ROS parameters can
hold where they cannot hold an empty string array) selects by the regular expression only.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field

from dam_recorder.errors import ConfigurationError

#: The hand's state and commands, the grasp's status, the action's status and feedback, the
#: driver's diagnostics, the robot model (latched), the hand's and the object's frames
#: (``/tf``, and ``/tf_static`` latched: RViz and Foxglove draw the episode in 3D from them)
#: and the stand-in's ground truth (the object's pose and whether it is on the table).
DEFAULT_TOPICS: tuple[str, ...] = (
    '/joint_states',
    '/hand/command',
    '/dam/status',
    '/dam/episode',
    '/dam_grasp/_action/status',
    '/dam_grasp/_action/feedback',
    '/diagnostics',
    '/robot_description',
    '/tf',
    '/tf_static',
    '/sim/object_pose',
    '/sim/object_table_contact',
)

_TOPIC_NAME = re.compile(r'^(/[A-Za-z_~][A-Za-z0-9_]*)+$')


def absolute_topic_name(name: str) -> str:
    """``name`` with a leading ``/`` (``'joint_states'`` -> ``'/joint_states'``).

    Raises
    ------
    ConfigurationError
        If ``name`` is not a valid ROS 2 topic name (the message quotes it).
    """
    text = name.strip()
    absolute = text if text.startswith('/') else '/' + text
    if not _TOPIC_NAME.match(absolute) or '//' in absolute:
        raise ConfigurationError(
            f'{name!r} is not a topic name (letters, digits, _ and / only, e.g. /joint_states)')
    return absolute


def _compile(option: str, pattern: str) -> re.Pattern[str] | None:
    if not pattern:
        return None
    try:
        return re.compile(pattern)
    except re.error as exc:
        raise ConfigurationError(f'{option}: {pattern!r} is not a regular expression: {exc}'
                                 ) from None


@dataclass(frozen=True)
class TopicSelection:
    """The recorder's choice of topics.

    Parameters
    ----------
    topics : iterable of str
        Topics recorded by name (empty names are ignored).
    regex : str
        Topics matching this regular expression are recorded too; ``''`` matches none.
    exclude : str
        Topics matching this regular expression are never recorded; ``''`` excludes none.

    Raises
    ------
    ConfigurationError
        For a malformed topic name or regular expression (the message quotes it), or a
        selection that can select nothing (no topic and no regular expression).
    """

    topics: Iterable[str] = DEFAULT_TOPICS
    regex: str = ''
    exclude: str = ''
    _regex: re.Pattern[str] | None = field(init=False, repr=False, compare=False)
    _exclude: re.Pattern[str] | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = tuple(dict.fromkeys(absolute_topic_name(t) for t in self.topics if t.strip()))
        object.__setattr__(self, 'topics', names)
        object.__setattr__(self, '_regex', _compile('regex', self.regex))
        object.__setattr__(self, '_exclude', _compile('exclude', self.exclude))
        if not names and self._regex is None:
            raise ConfigurationError('no topic to record: give topic names or a regex')

    def selects(self, topic: str) -> bool:
        """Whether ``topic`` (an absolute name) is recorded."""
        if self._exclude is not None and self._exclude.search(topic):
            return False
        return topic in self.topics or (self._regex is not None
                                        and self._regex.search(topic) is not None)

    def excluded(self, topic: str) -> bool:
        """Whether ``topic`` is listed by name but excluded (worth a warning)."""
        return topic in self.topics and self._exclude is not None \
            and self._exclude.search(topic) is not None
