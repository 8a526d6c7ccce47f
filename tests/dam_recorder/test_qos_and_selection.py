"""The subscription's QoS from the publishers' offers, and the choice of topics."""

from __future__ import annotations

import pytest
from rosbags.interfaces import QosDurability, QosReliability

from dam_recorder.errors import ConfigurationError
from dam_recorder.qos import (
    INFINITE_NS,
    OfferedQos,
    metadata_profiles,
    request_for_offers,
    to_rosbags_qos,
)
from dam_recorder.selection import DEFAULT_TOPICS, TopicSelection, absolute_topic_name


def offer(reliability: str = 'RELIABLE', durability: str = 'VOLATILE') -> OfferedQos:
    return OfferedQos('KEEP_LAST', 10, reliability, durability, INFINITE_NS, INFINITE_NS,
                      'AUTOMATIC', INFINITE_NS)


@pytest.mark.parametrize('reliabilities, durabilities, reliable, latched, warnings', [
    (['RELIABLE'], ['VOLATILE'], True, False, 0),
    (['BEST_EFFORT'], ['VOLATILE'], False, False, 0),
    (['RELIABLE', 'RELIABLE'], ['TRANSIENT_LOCAL', 'TRANSIENT_LOCAL'], True, True, 0),
    (['RELIABLE', 'BEST_EFFORT'], ['VOLATILE', 'VOLATILE'], False, False, 1),
    (['RELIABLE', 'RELIABLE'], ['TRANSIENT_LOCAL', 'VOLATILE'], True, False, 1),
    (['RELIABLE', 'BEST_EFFORT'], ['TRANSIENT_LOCAL', 'VOLATILE'], False, False, 2),
])
def test_request_is_what_every_publisher_offers(reliabilities, durabilities, reliable, latched,
                                                 warnings) -> None:
    offers = [offer(r, d) for r, d in zip(reliabilities, durabilities, strict=True)]
    request = request_for_offers('/t', offers, 1000)
    assert (request.reliable, request.transient_local, request.depth) == \
        (reliable, latched, 1000)
    assert len(request.warnings) == warnings
    assert all('/t' in w for w in request.warnings)


def test_no_offer_yet_asks_reliable_volatile_and_depth_is_checked() -> None:
    request = request_for_offers('/t', [], 5)
    assert (request.reliable, request.transient_local) == (True, False)
    with pytest.raises(ConfigurationError, match='0'):
        request_for_offers('/t', [offer()], 0)


def test_offered_profile_in_metadata_version_9_form() -> None:
    qos = to_rosbags_qos(OfferedQos('KEEP_LAST', 1, 'reliable', 'TRANSIENT_LOCAL', 1_500_000_000,
                                    INFINITE_NS, 'AUTOMATIC', 0, True))
    assert qos.reliability == QosReliability.RELIABLE
    assert qos.durability == QosDurability.TRANSIENT_LOCAL
    assert metadata_profiles([qos]) == [{
        'history': 'keep_last', 'depth': 1, 'reliability': 'reliable',
        'durability': 'transient_local', 'deadline': {'sec': 1, 'nsec': 500_000_000},
        'lifespan': {'sec': 9223372036, 'nsec': 854775807}, 'liveliness': 'automatic',
        'liveliness_lease_duration': {'sec': 0, 'nsec': 0},
        'avoid_ros_namespace_conventions': True}]
    odd = to_rosbags_qos(OfferedQos('NOT_A_POLICY', 0, 'x', 'y', 0, 0, 'z', 0))
    assert metadata_profiles([odd])[0]['reliability'] == 'unknown'


def test_default_selection_is_the_hand_topics() -> None:
    selection = TopicSelection()
    for topic in DEFAULT_TOPICS:
        assert selection.selects(topic)
    assert '/robot_description' in DEFAULT_TOPICS
    assert '/dam_grasp/_action/feedback' in DEFAULT_TOPICS
    assert not selection.selects('/rosout')
    assert not selection.selects('/joint_states_extra')


def test_list_regex_and_exclusion() -> None:
    selection = TopicSelection(['joint_states'], regex='^/dam/', exclude='debug')
    assert selection.topics == ('/joint_states',)
    assert selection.selects('/joint_states')
    assert selection.selects('/dam/status')
    assert not selection.selects('/dam/debug')
    assert not selection.selects('/hand/command')
    assert TopicSelection([], regex='status').selects('/dam_grasp/_action/status')  # search
    excluding = TopicSelection(['/a', '/b'], exclude='^/b$')
    assert excluding.excluded('/b') and not excluding.selects('/b')
    assert not excluding.excluded('/a')


@pytest.mark.parametrize('kwargs, quoted', [
    ({'topics': ['/bad name']}, "'/bad name'"),
    ({'topics': ['/a//b']}, "'/a//b'"),
    ({'topics': ['/1abc']}, "'/1abc'"),
    ({'regex': '(unclosed'}, "'(unclosed'"),
    ({'exclude': '[z-a]'}, "'[z-a]'"),
])
def test_bad_selection_names_the_value(kwargs, quoted) -> None:
    with pytest.raises(ConfigurationError) as info:
        TopicSelection(**kwargs)
    assert quoted in str(info.value)


def test_nothing_selected_is_refused() -> None:
    with pytest.raises(ConfigurationError, match='no topic'):
        TopicSelection([])
    with pytest.raises(ConfigurationError, match='no topic'):
        TopicSelection([''])
    assert TopicSelection([''], regex='x').topics == ()
    assert absolute_topic_name(' /x ') == '/x'
