"""The controller's parameter table and the checks of a ``ros2 param set`` (pure, no ROS)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from dam_common.config import load_config
from dam_spcm_controller.controller_parameters import (
    BOOL_PARAMETERS,
    DOUBLE_PARAMETERS,
    READ_ONLY,
    changed_values,
    sequence_overrides,
)
from dam_spcm_controller.errors import InputError
from dam_spcm_controller.sequence import SequenceParams

VALUES = {'damping': 0.01, 'state_timeout': 0.1, 'status_rate': 20.0}
FLAGS = {'require_lift_guarantee': False, 'impedance_on_device': True,
         'envelope_constant_torque': False}


def test_every_number_parameter_names_a_sequence_field_or_none_and_a_range() -> None:
    fields = {f.name for f in dataclasses.fields(SequenceParams)}
    for name, (attr, description, lo, hi) in DOUBLE_PARAMETERS.items():
        assert attr is None or attr in fields, name
        assert description and '[' in description, name  # the unit is given
        assert lo < hi, name
    assert READ_ONLY <= set(DOUBLE_PARAMETERS)
    assert {'impedance_on_device', 'envelope_constant_torque'} <= fields
    assert set(BOOL_PARAMETERS) == set(FLAGS)


def test_a_change_is_applied_to_copies() -> None:
    values, flags = changed_values(VALUES, FLAGS, [('damping', 1), ('use_sim_time', True),
                                                   ('impedance_on_device', False)])
    assert values['damping'] == 1.0 and isinstance(values['damping'], float)
    assert flags['impedance_on_device'] is False
    assert VALUES['damping'] == 0.01 and FLAGS['impedance_on_device'] is True
    assert 'use_sim_time' not in values and 'use_sim_time' not in flags


@pytest.mark.parametrize(('name', 'value', 'words'), [
    ('damping', math.nan, 'damping must be a finite number, got nan'),
    ('damping', math.inf, 'damping must be a finite number, got inf'),
    ('damping', True, 'damping must be a finite number, got True'),
    ('damping', 'soft', "damping must be a finite number, got 'soft'"),
    ('impedance_on_device', 1, 'impedance_on_device must be a bool, got 1'),
    ('require_lift_guarantee', 'yes', "require_lift_guarantee must be a bool, got 'yes'"),
])
def test_a_value_of_the_wrong_type_is_refused_by_name(name: str, value: object,
                                                      words: str) -> None:
    with pytest.raises(InputError) as info:
        changed_values(VALUES, FLAGS, [(name, value)])
    assert str(info.value) == words


def test_the_overrides_build_the_sequence_parameters() -> None:
    base = SequenceParams.from_config(load_config())
    values = {name: float(getattr(base, attr)) if attr else 1.0
              for name, (attr, *_rest) in DOUBLE_PARAMETERS.items()}
    values['damping'] = 0.0123
    params = dataclasses.replace(base, **sequence_overrides(
        values, dict(FLAGS, envelope_constant_torque=True)))
    assert params.damping == 0.0123
    assert params.envelope_constant_torque is True and params.impedance_on_device is True
