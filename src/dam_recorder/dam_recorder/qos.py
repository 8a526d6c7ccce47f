"""Quality of service: what the recorder asks for, and what the bag says was offered.

A subscription receives from a publisher only when their profiles are compatible, and a
latched topic delivers its last message to a late subscriber only when both sides are
``transient_local``. So the recorder asks for what the publishers it found offer, as
``ros2 bag record`` does:

- ``reliable`` when every publisher offers ``reliable``, otherwise ``best_effort`` (a reliable
  request would not match a best-effort publisher);
- ``transient_local`` when every publisher offers it (latched topics such as
  ``/robot_description``), otherwise ``volatile``;
- history ``keep_last`` with a deep queue, so that a busy executor does not overwrite messages
  in the reader's cache; deadline, lifespan and liveliness left at their defaults (compatible
  with every offer).

The bag stores each topic's offered profiles (``offered_qos_profiles``) in the form
``metadata.yaml`` version 9 uses: a list of mappings with policy names as strings
(``reliable``, ``transient_local``, ``keep_last``, ``automatic``) and durations as
``{sec, nsec}``; an infinite duration is ``{sec: 9223372036, nsec: 854775807}``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2.metadata import dump_qos_v9

from dam_recorder.errors import ConfigurationError

#: The longest duration a profile can hold [ns] (``RMW_DURATION_INFINITE``).
INFINITE_NS = 2**63 - 1


@dataclass(frozen=True)
class OfferedQos:
    """A publisher's QoS profile, with policies by name (as rclpy's enum names, any case).

    Attributes
    ----------
    history, reliability, durability, liveliness : str
        Policy names, e.g. ``'KEEP_LAST'``, ``'RELIABLE'``, ``'TRANSIENT_LOCAL'``,
        ``'AUTOMATIC'``; a name not known is stored as ``unknown``.
    depth : int
        History depth [messages] (0 where the middleware does not report it).
    deadline_ns, lifespan_ns, liveliness_lease_duration_ns : int
        Durations [ns]; :data:`INFINITE_NS` for infinite.
    avoid_ros_namespace_conventions : bool
        As offered.
    """

    history: str
    depth: int
    reliability: str
    durability: str
    deadline_ns: int
    lifespan_ns: int
    liveliness: str
    liveliness_lease_duration_ns: int
    avoid_ros_namespace_conventions: bool = False


@dataclass(frozen=True)
class RequestedQos:
    """What the recorder's subscription asks for (history ``keep_last``).

    Attributes
    ----------
    reliable : bool
        ``reliable`` if true, else ``best_effort``.
    transient_local : bool
        ``transient_local`` if true, else ``volatile``.
    depth : int
        Depth of the reader's queue [messages].
    warnings : tuple[str, ...]
        Why a weaker policy was chosen (publishers that disagree), for the log.
    """

    reliable: bool
    transient_local: bool
    depth: int
    warnings: tuple[str, ...] = ()


def request_for_offers(topic: str, offers: Sequence[OfferedQos], depth: int) -> RequestedQos:
    """The subscription profile that receives from every publisher in ``offers``.

    Parameters
    ----------
    topic : str
        Topic name, for the warnings.
    offers : sequence of OfferedQos
        The profiles of the publishers found on ``topic``; empty means none found yet
        (then ``reliable``, ``volatile``).
    depth : int
        Queue depth [messages], at least 1.

    Raises
    ------
    ConfigurationError
        If ``depth`` is below 1.
    """
    if depth < 1:
        raise ConfigurationError(f'queue depth must be at least 1 message, got {depth!r}')
    if not offers:
        return RequestedQos(True, False, depth)
    reliable = [o.reliability.upper() == 'RELIABLE' for o in offers]
    latched = [o.durability.upper() == 'TRANSIENT_LOCAL' for o in offers]
    warnings = []
    if any(reliable) and not all(reliable):
        warnings.append(f'{topic}: some publishers offer reliable, some not: subscribing '
                        'best_effort (messages of the reliable ones may be lost)')
    if any(latched) and not all(latched):
        warnings.append(f'{topic}: some publishers offer transient_local, some not: subscribing '
                        'volatile (messages published before the subscription are not received)')
    return RequestedQos(all(reliable), all(latched), depth, tuple(warnings))


def _time(ns: int) -> QosTime:
    ns = min(max(int(ns), 0), INFINITE_NS)
    sec, nsec = divmod(ns, 1_000_000_000)
    return QosTime(sec, nsec)


def _member(enum: type, name: str):  # noqa: ANN202 - returns a member of ``enum``
    return enum.__members__.get(name.upper(), enum.__members__['UNKNOWN'])


def to_rosbags_qos(offer: OfferedQos) -> Qos:
    """``offer`` as the ``rosbags`` profile written into the bag."""
    return Qos(
        history=_member(QosHistory, offer.history),
        depth=int(offer.depth),
        reliability=_member(QosReliability, offer.reliability),
        durability=_member(QosDurability, offer.durability),
        deadline=_time(offer.deadline_ns),
        lifespan=_time(offer.lifespan_ns),
        liveliness=_member(QosLiveliness, offer.liveliness),
        liveliness_lease_duration=_time(offer.liveliness_lease_duration_ns),
        avoid_ros_namespace_conventions=bool(offer.avoid_ros_namespace_conventions),
    )


def metadata_profiles(profiles: Sequence[Qos]) -> list[dict]:
    """The ``offered_qos_profiles`` entry of ``metadata.yaml`` version 9 for ``profiles``."""
    return [dict(p) for p in dump_qos_v9(list(profiles))]
