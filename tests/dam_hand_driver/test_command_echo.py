"""A HandCommand refused for a huge joint name quotes a short part of it (dam_common.echo)."""

from __future__ import annotations

import numpy as np
import pytest

driver_node = pytest.importorskip('dam_hand_driver.driver_node')


def test_an_unknown_joint_name_of_a_million_characters_is_quoted_briefly() -> None:
    from dam_interfaces.msg import HandCommand

    msg = HandCommand()
    msg.name = ['j' * 1_000_000]
    msg.mode = [HandCommand.MODE_TORQUE]
    msg.setpoint = [0.0]
    with pytest.raises(driver_node.CommandRejected) as caught:
        driver_node.validate_command(msg, {'a': 0}, 1.0, np.zeros(1), np.ones(1), 10.0, 1.0)
    text = str(caught.value)
    assert len(text) < 400, len(text)
    assert text.startswith("unknown joint name 'jjj") and '(1000000 characters)' in text, text
    assert "(known: ['a'])" in text
