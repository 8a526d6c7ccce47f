"""``/sim/object_table_contact`` over DDS, from the real sim_bridge process: beside every pose
on ``/sim/object_pose`` (the same stamp), the stand-in's table contacts and its lift-off rule;
the object at rest lies on the table. (What the rule says off the table is tested on the world
itself: tests/dam_sim_bridge/test_lift_off.py.)"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from ros_testing import RosClient, config_with_free_ports, installed_executable, node_process

pytestmark = pytest.mark.xdist_group('dds')  # DDS in the test process: one worker
POSE, CONTACT = '/contact_sim/pose', '/contact_sim/table_contact'


@pytest.fixture(scope='module')
def received(tmp_path_factory: pytest.TempPathFactory
             ) -> Iterator[tuple[list, list, Path]]:
    from geometry_msgs.msg import PoseStamped

    from dam_interfaces.msg import ObjectTableContact

    config = config_with_free_ports(tmp_path_factory.mktemp('contact'))
    command = [installed_executable('dam_sim_bridge', 'sim_bridge'), '--ros-args',
               '-r', '__node:=contact_sim', '-r', f'/sim/object_pose:={POSE}',
               '-r', f'/sim/object_table_contact:={CONTACT}']
    poses: list = []
    contacts: list = []
    with node_process(command, env={'DAM_CONFIG': str(config)}) as proc:
        client = RosClient()
        try:
            client.node.create_subscription(PoseStamped, POSE, poses.append, 100)
            client.node.create_subscription(ObjectTableContact, CONTACT, contacts.append, 100)
            assert client.spin_until(lambda: len(contacts) >= 30 and len(poses) >= 30, 60.0), \
                proc.output()
            yield poses, contacts, config
        finally:
            client.close()
        assert proc.alive(), proc.output()


def test_the_contact_topic_comes_beside_the_pose(received: tuple[list, list, Path]) -> None:
    poses, contacts, _ = received
    stamps = {(p.header.stamp.sec, p.header.stamp.nanosec) for p in poses}
    paired = [c for c in contacts if (c.header.stamp.sec, c.header.stamp.nanosec) in stamps]
    assert len(paired) >= len(contacts) - 2  # the first and last may miss their pose
    assert all(c.header.frame_id == 'world' for c in contacts)


def test_an_object_at_rest_lies_on_the_table(received: tuple[list, list, Path]) -> None:
    from dam_common.config import load_config

    poses, contacts, config = received
    # the pose says it rests where it was put: its centroid at the configured resting height
    resting_z = float(load_config(config).object.position_m[2])
    assert all(abs(p.pose.position.z - resting_z) < 2e-4 for p in poses)
    for c in contacts:
        assert c.on_table and c.table_contacts > 0, c
        assert c.off_table_s == 0.0 and not c.lifted_off and not c.lifted
