"""The episode's copy of a /check_lift answer holds every field the message has."""

from __future__ import annotations

import math

from dam_interfaces.msg import LiftAnswer
from dam_interfaces.srv import CheckLift
from dam_spcm_controller.episode import lift_answer


def test_every_field_of_the_answer_message_is_the_responses() -> None:
    response = CheckLift.Response()
    fields = LiftAnswer.get_fields_and_field_types()
    assert {'rolling_checked', 'rolling_margin', 'csm_path_lift', 'csm_path_margin'} <= set(fields)
    values = {}
    for i, (name, kind) in enumerate(fields.items()):  # a distinct value in every field
        if kind == 'boolean':
            value = i % 2 == 0
        elif kind == 'string':
            value = f'text {i}'
        elif kind == 'double':
            value = 0.5 + i
        else:
            assert kind == 'sequence<double>', (name, kind)
            value = [float(i), -float(i)]
        setattr(response, name, value)
        values[name] = value
    response.rolling_margin = -math.inf
    values['rolling_margin'] = -math.inf
    answer = lift_answer(response)
    for name, value in values.items():
        got = getattr(answer, name)
        assert (list(got) if isinstance(value, list) else got) == value, name
