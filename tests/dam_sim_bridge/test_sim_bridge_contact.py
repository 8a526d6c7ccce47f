"""``/sim/object_table_contact``: over DDS, from the real sim_bridge process, beside every pose
on ``/sim/object_pose`` (the same stamp), the stand-in's table contacts and its lift-off rule,
the object at rest lying on the table, not lifted, as PyBullet's contact points read here say;
and the message the node builds from the world's lift-off rule, for an object that left the
table and lies on it again (lifted, not off the table at the end) and one held off it (both),
against the contact points of a world stepped here. (The rule itself:
tests/dam_sim_bridge/test_lift_off.py.)"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from ros_testing import RosClient, config_with_free_ports, installed_executable, node_process

pytestmark = pytest.mark.xdist_group('dds')  # DDS in the test process: one worker
POSE, CONTACT = '/contact_sim/pose', '/contact_sim/table_contact'
TOUCH_M = 1e-4  # the documented touch distance, written out here


def _touching(world) -> int:
    """Object-table contact points closer than 0.1 mm, read from PyBullet here."""
    points = world.client.getContactPoints(world.object_id, world.table_id)
    return sum(p[8] < TOUCH_M for p in points)


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
    from dam_sim_bridge.world import HandWorld

    poses, contacts, config = received
    # the pose says it rests where it was put: its centroid at the configured resting height
    resting_z = float(load_config(config).object.position_m[2])
    assert all(abs(p.pose.position.z - resting_z) < 2e-4 for p in poses)
    # the same world stepped here, every device cycle for as long: the contact points it has
    with HandWorld(load_config(config)) as world:
        counts = set()
        for _ in range(len(contacts)):
            world.step(2)
            counts.add(_touching(world))
    assert min(counts) > 0
    # (How many points PyBullet reports for a cylinder at rest, 1 to 4, depends on how long
    # the world has been stepped: the node's has been stepped longer than this one.)
    for c in contacts:
        assert c.on_table and 1 <= c.table_contacts <= 4, (c, counts)
        assert c.off_table_s == 0.0 and not c.lifted and not c.off_table_at_end


def test_the_message_says_lifted_after_a_lift_off_and_off_the_table_at_the_end_apart(
        ) -> None:
    """Two worlds stepped here every device cycle, the node's message built from each world's
    rule, against PyBullet's contact points: the object dropped from 20 mm (off the table
    about 64 ms: a lift-off) lies on the table again, lifted and not off it at the end; the
    object 1 mm up without gravity stays off it, lifted and off it at the end."""
    from std_msgs.msg import Header

    from dam_common.config import load_config
    from dam_sim_bridge.sim_bridge_node import table_contact_message
    from dam_sim_bridge.world import HandWorld

    config = load_config()
    header = Header(frame_id='world')
    with HandWorld(config) as world:
        start = np.asarray(world.object_pose().position, dtype=float)
        world.reset(object_position=start + [0.0, 0.0, 0.02])
        clear = []  # simulated times at which no contact point touches
        for _ in range(150):  # 0.3 s
            world.step(2)
            if not _touching(world):
                clear.append(world.sim_time)
        fell = table_contact_message(world.lift_off.state(), header)
        touching = _touching(world)
    assert clear[0] == pytest.approx(0.002) and max(clear) >= 0.05  # off 50 ms from the reset
    assert touching > 0 and fell.table_contacts == touching and fell.on_table
    assert fell.lifted and not fell.off_table_at_end and fell.off_table_s == 0.0
    assert fell.header.frame_id == 'world'
    with HandWorld(config) as world:
        world.set_gravity((0.0, 0.0, 0.0))
        start = np.asarray(world.object_pose().position, dtype=float)
        world.reset(object_position=start + [0.0, 0.0, 0.001])
        touched = 0
        for _ in range(100):  # 0.2 s
            world.step(2)
            touched += _touching(world)
        held = table_contact_message(world.lift_off.state(), header)
    assert touched == 0 and held.table_contacts == 0 and not held.on_table
    assert held.lifted and held.off_table_at_end
    assert held.off_table_s == pytest.approx(0.2, abs=1e-6)
