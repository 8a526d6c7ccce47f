"""Message types as rclpy knows them: the class of a type name, the QoS a publisher offers,
whether a type starts with a header (the recorder's thin ROS layer)."""

from __future__ import annotations

import importlib
import sys
from typing import Any

from dam_recorder.errors import TypeDescriptionError
from dam_recorder.qos import OfferedQos


def message_class(type_name: str) -> type:
    """The Python class of ``type_name`` (``pkg/msg/Name``, or a type derived from an action
    or a service such as ``pkg/action/Name_FeedbackMessage``).

    Raises
    ------
    TypeDescriptionError
        If the class cannot be imported (the message names the type).
    """
    try:
        package, kind, name = type_name.split('/')
        module = importlib.import_module(f'{package}.{kind}')
    except (ValueError, ImportError) as exc:
        raise TypeDescriptionError(f'cannot import the type {type_name!r}: {exc}') from None
    if hasattr(module, name):
        return getattr(module, name)
    for cut in range(len(name) - 1, 0, -1):  # Name_FeedbackMessage lives beside Name
        base = getattr(module, name[:cut], None) if name[cut] == '_' else None
        derived = getattr(sys.modules.get(getattr(base, '__module__', '')), name, None)
        if derived is not None:
            return derived
    raise TypeDescriptionError(f'cannot import the type {type_name!r}: no class {name}')


def offered_qos(info: Any) -> OfferedQos:
    """The :class:`OfferedQos` of an rclpy ``TopicEndpointInfo``."""
    qos = info.qos_profile
    return OfferedQos(
        history=qos.history.name, depth=int(qos.depth), reliability=qos.reliability.name,
        durability=qos.durability.name, deadline_ns=qos.deadline.nanoseconds,
        lifespan_ns=qos.lifespan.nanoseconds, liveliness=qos.liveliness.name,
        liveliness_lease_duration_ns=qos.liveliness_lease_duration.nanoseconds,
        avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))


def starts_with_header(cls: type) -> bool:
    """The message type ``cls`` (an rclpy message class) starts with a ``std_msgs/Header``."""
    fields = getattr(cls, 'get_fields_and_field_types', None)
    first = next(iter(fields().items()), None) if callable(fields) else None
    return first is not None and first[1] == 'std_msgs/Header'
