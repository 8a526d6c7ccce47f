"""The episode metadata parser: a valid summary round-trips, non-finite strings become floats,
every malformed value is refused naming the key and the value."""

from __future__ import annotations

import json
import math
from datetime import datetime

import pytest
from grasp_bags import CHECK_LIFT, GOAL_ID, summary

from dam_recorder.episode import (
    CONFIG_KEY,
    SUMMARY_KEY,
    VERSION_KEY,
    episode_from_custom_data,
    parse_episode_name,
    parse_summary,
)
from dam_recorder.errors import EpisodeError


def test_a_valid_summary_is_read_field_by_field() -> None:
    s = parse_summary(json.dumps(summary()))
    assert s.goal_id == GOAL_ID
    assert (s.accepted_ns, s.ended_ns) == (1_750_000_000_250_000_000, 1_750_000_001_800_000_000)
    assert s.goal_k_theta == (10.0,) and s.goal_delta_theta_p == ()
    assert s.k_theta == (10.0, 5.0, 5.0)
    assert s.delta_theta_p == (0.17453292519943295,) * 3
    assert s.friction_angle == 0.08726646259971647
    assert (s.outcome, s.outcome_name, s.message) == (1, 'SUCCESS', 'grasp done: enveloped')
    assert (s.duration_s, s.pre_roll_s, s.post_roll_s) == (1.55, 0.25, 0.2)
    c = s.check_lift
    assert c is not None
    assert (c.ok, c.message, c.lift_guaranteed, c.csm_lift) == (True, 'lift guaranteed', True,
                                                                True)
    assert (c.worst_case_margin, c.csm_margin) == (0.04001, 1.337)
    assert c.delta_theta_s == (-0.0477,) * 3 and c.compliant_torque == (0.334, 0.167, 0.167)


def test_non_finite_strings_become_floats_and_check_lift_may_be_null() -> None:
    check = dict(CHECK_LIFT, worst_case_margin='-inf', csm_margin='nan',
                 delta_theta_s=['nan', 0.5, 'inf'])
    s = parse_summary(json.dumps(summary(check_lift=check, friction_angle='nan')))
    assert s.check_lift is not None
    assert s.check_lift.worst_case_margin == -math.inf
    assert math.isnan(s.check_lift.csm_margin) and math.isnan(s.friction_angle)
    assert math.isnan(s.check_lift.delta_theta_s[0])
    assert s.check_lift.delta_theta_s[1:] == (0.5, math.inf)
    assert parse_summary(json.dumps(summary(check_lift=None))).check_lift is None
    rejected = parse_summary(json.dumps(summary(outcome=5, outcome_name='REJECTED', k_theta=[],
                                                delta_theta_p=[])))
    assert rejected.k_theta == () and rejected.outcome_name == 'REJECTED'


@pytest.mark.parametrize('changes, message', [
    ({'k_theta': 'abc'}, "dam_episode.summary.k_theta: expected a list of numbers, got 'abc'"),
    ({'k_theta': [1.0, 'soft']}, "dam_episode.summary.k_theta[1]: expected a number"),
    ({'k_theta': [1.0, True]}, "dam_episode.summary.k_theta[1]: expected a number, got True"),
    ({'goal_id': 'xyz'}, "dam_episode.summary.goal_id: expected 32 lower-case hex digits, "
                         "got 'xyz'"),
    ({'accepted_ns': 1.5}, 'dam_episode.summary.accepted_ns: expected an integer, got 1.5'),
    ({'outcome': 9}, 'dam_episode.summary.outcome: expected 0..5, got 9'),
    ({'outcome_name': 'FAILURE'}, "dam_episode.summary.outcome_name: expected 'SUCCESS' for "
                                  "outcome 1, got 'FAILURE'"),
    ({'check_lift': [1]}, 'dam_episode.summary.check_lift: expected an object or null, got [1]'),
    ({'check_lift': dict(CHECK_LIFT, csm_lift='yes')},
     "dam_episode.summary.check_lift.csm_lift: expected true or false, got 'yes'"),
    ({'goal': {'k_theta': []}}, "dam_episode.summary.goal: missing key 'delta_theta_p'"),
    ({'duration_s': 'long'}, "dam_episode.summary.duration_s: expected a number (or \"nan\", "
                             "\"inf\", \"-inf\"), got 'long'"),
    ({'object': 7}, "dam_episode.summary.object: expected a string, got 7"),
])
def test_malformed_values_are_named_with_their_key(changes, message) -> None:
    with pytest.raises(EpisodeError) as info:
        parse_summary(json.dumps(summary(**changes)))
    assert message in str(info.value)


def test_the_object_is_read_and_a_bag_without_it_still_parses() -> None:
    """The grasped object's name (newer bags); a bag of a version without it: empty."""
    assert parse_summary(json.dumps(summary(object='hex_bar'))).object == 'hex_bar'
    assert parse_summary(json.dumps(summary())).object == ''


def test_missing_keys_and_text_that_is_no_json_object_are_refused() -> None:
    data = summary()
    del data['message']
    with pytest.raises(EpisodeError, match="dam_episode.summary: missing key 'message'"):
        parse_summary(json.dumps(data))
    with pytest.raises(EpisodeError, match=r"dam_episode.summary: not valid JSON .*'\{oops'"):
        parse_summary('{oops')
    with pytest.raises(EpisodeError, match=r'dam_episode.summary: expected a JSON object, '
                                           r'got \[1, 2\]'):
        parse_summary('[1, 2]')


def test_custom_data_without_a_summary_has_no_episode() -> None:
    assert episode_from_custom_data({'dam_recorder.lost_messages': '{}'}) is None
    episode = episode_from_custom_data({SUMMARY_KEY: json.dumps(summary()),
                                        CONFIG_KEY: 'task:\n  a: 1\n', VERSION_KEY: '0.2'})
    assert episode is not None and episode.version == '0.2'
    assert episode.config() == {'task': {'a': 1}}
    broken = episode_from_custom_data({SUMMARY_KEY: json.dumps(summary()),
                                       CONFIG_KEY: 'task: [1'})
    assert broken is not None
    with pytest.raises(EpisodeError, match='dam_episode.config: not valid YAML'):
        broken.config()


def test_episode_directory_names() -> None:
    assert parse_episode_name('2026_11_29-18_05_12_success') == \
        (datetime(2026, 11, 29, 18, 5, 12), 'success')
    assert parse_episode_name('2026_11_29-18_05_12_lifted_dam_failed')[1] == \
        'lifted_dam_failed'
    assert parse_episode_name('2026_13_29-18_05_12_success') is None  # no 13th month
    assert parse_episode_name('rosbag2_2026_11_29-18_05_12') is None
