"""Tests of the PyBullet world against closed-form mechanics (no ROS, no network)."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_common.device_protocol import Calibration, DeviceWatchdog, JointFault, JointMode
from dam_sim_bridge.errors import CommandError, SimulationError, WorldConfigError
from dam_sim_bridge.world import HandWorld
from dam_sim_bridge.world_options import WorldOptions

T, P, H = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMP = int(JointMode.IMPEDANCE)


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


@pytest.fixture
def world(cfg: DamConfig) -> Iterator[HandWorld]:
    """The bare fingers (no drive inertia, no palm): the tests check the links' own dynamics."""
    w = HandWorld(cfg, WorldOptions.from_config(cfg, compliant_rotor_inertia_kg_m2=0.0,
                                                palm_thickness_m=0.0))
    yield w
    w.close()


def _finger_plane_points(cfg: DamConfig, angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Joint positions and link centres of one finger in its plane: (inward, up) per point.

    A link at cumulative angle phi points along (sin phi, -cos phi): straight down at 0,
    inward for positive phi.
    """
    lengths = cfg.hand.link_lengths_m
    joints = [np.zeros(2)]
    centres = []
    phi = 0.0
    for i in range(3):
        phi += angles[i]
        d = np.array([math.sin(phi), -math.cos(phi)])
        centres.append(joints[-1] + 0.5 * lengths[i] * d)
        joints.append(joints[-1] + lengths[i] * d)
    return np.array(joints), np.array(centres)


def _to_world(cfg: DamConfig, finger: int, planar: np.ndarray) -> np.ndarray:
    f = cfg.hand.fingers[finger]
    return f.base_position_m + planar[0] * f.inward_direction + planar[1] * np.array([0, 0, 1.0])


def _servo(world: HandWorld, angles: np.ndarray, seconds: float = 0.5) -> None:
    world.set_joint_commands([P] * world.n_joints, angles)
    world.step(int(round(seconds / world.time_step_s)))


# --------------------------------------------------------------------------------------------
# Geometry


def test_joint_order_and_limits_follow_the_config(world: HandWorld, cfg: DamConfig) -> None:
    assert world.joint_names == cfg.hand.joint_names
    for i, name in enumerate(world.joint_names):
        role = name.split('_')[1]
        lo, hi = cfg.hand.joint_limits_rad[role]
        info = world.client.getJointInfo(world.hand_id, world.joint_indices[i])
        assert info[1].decode() == name
        assert (info[8], info[9]) == pytest.approx((lo, hi))
        axis_world = np.array(world.client.getLinkState(
            world.hand_id, world.joint_indices[i], computeForwardKinematics=True)[5])
        rot = np.array(world.client.getMatrixFromQuaternion(axis_world)).reshape(3, 3)
        finger = cfg.hand.fingers[i // 3]
        np.testing.assert_allclose(rot @ np.array(info[13]), finger.joint_axis, atol=1e-9)


def test_the_stand_in_loads_the_kinematic_tree_the_driver_publishes(world: HandWorld,
                                                                    cfg: DamConfig) -> None:
    """Every joint of the driver's /robot_description (the standard URDF) is in the loaded
    PyBullet model with the same parent, origin, axis and limits, and every link with the same
    mass and inertia: one model, two readers."""
    from xml.etree import ElementTree as ET

    from dam_common.hand_urdf import BASE_LINK, hand_urdf

    robot = ET.fromstring(hand_urdf(cfg))
    links = {link.get('name'): link for link in robot.findall('link')}
    pb = world.client
    loaded = {pb.getJointInfo(world.hand_id, j)[1].decode(): j
              for j in range(pb.getNumJoints(world.hand_id))}
    revolute = [j for j in robot.findall('joint') if j.get('type') == 'revolute']
    assert sorted(j.get('name') for j in revolute) == sorted(loaded)
    index_of_link = {pb.getJointInfo(world.hand_id, j)[12].decode(): j for j in loaded.values()}
    for joint in revolute:
        info = pb.getJointInfo(world.hand_id, loaded[joint.get('name')])
        parent = joint.find('parent').get('link')
        assert info[16] == (-1 if parent == BASE_LINK else index_of_link[parent])
        assert info[12].decode() == joint.find('child').get('link')
        limit = joint.find('limit')
        assert (info[8], info[9]) == (float(limit.get('lower')), float(limit.get('upper')))
        np.testing.assert_allclose(info[13], [float(v) for v in
                                              joint.find('axis').get('xyz').split()])
        # the joint frame's position in the parent link frame: PyBullet states it from the
        # parent's centre of mass, so add that back to compare with the URDF origin
        xyz = np.array([float(v) for v in joint.find('origin').get('xyz').split()])
        parent_com = (np.zeros(3) if info[16] == -1 else
                      np.array(pb.getDynamicsInfo(world.hand_id, info[16])[3]))
        np.testing.assert_allclose(np.array(info[14]) + parent_com, xyz, atol=1e-12)
        link = links[joint.find('child').get('link')]
        dynamics = pb.getDynamicsInfo(world.hand_id, loaded[joint.get('name')])
        assert dynamics[0] == pytest.approx(float(link.find('inertial/mass').get('value')))
        inertia = link.find('inertial/inertia')
        expected = [float(inertia.get(k)) for k in ('ixx', 'iyy', 'izz')]
        if joint.get('name').endswith('_compliant_joint'):  # plus the rotor about y
            rotor = world.options.compliant_rotor_inertia_kg_m2
            expected = [expected[0] + rotor / 2.0, expected[1] + rotor, expected[2] + rotor / 2.0]
        np.testing.assert_allclose(dynamics[2], expected, rtol=1e-12)


def test_fingertips_follow_planar_forward_kinematics(world: HandWorld, cfg: DamConfig) -> None:
    angles = np.array([0.3, -0.1, 0.8])
    world.set_gravity((0.0, 0.0, 0.0))
    _servo(world, np.tile(angles, 3), 1.0)
    q = world.joint_states().positions
    tips = world.fingertip_positions()
    for f in range(cfg.hand.n_fingers):
        joints, _ = _finger_plane_points(cfg, q[3 * f:3 * f + 3])
        np.testing.assert_allclose(tips[f], _to_world(cfg, f, joints[-1]), atol=1e-9)
    np.testing.assert_allclose(q, np.tile(angles, 3), atol=2e-3)


def test_capsules_span_joint_to_joint_with_the_link_radius(world: HandWorld,
                                                           cfg: DamConfig) -> None:
    """Rays hit a horizontal distal link at its end cap (tip + r) and its top (axis + r)."""
    world.set_gravity((0.0, 0.0, 0.0))
    angles = np.array([0.0, 0.0, math.radians(90.0)])
    _servo(world, np.tile(angles, 3), 1.0)
    q = world.joint_states().positions
    np.testing.assert_allclose(q, np.tile(angles, 3), atol=1e-4)
    lengths, r = cfg.hand.link_lengths_m, cfg.hand.link_radius_m
    f = cfg.hand.fingers[1]
    inward = f.inward_direction
    joint3 = f.base_position_m - np.array([0.0, 0.0, lengths[0] + lengths[1]])
    tip = joint3 + lengths[2] * inward
    start = tip + 0.05 * inward
    hit = world.client.rayTest(start.tolist(), (tip - 0.01 * inward).tolist())[0]
    assert hit[0] == world.hand_id
    np.testing.assert_allclose(hit[3], tip + r * inward, atol=1e-4)
    middle = joint3 + 0.5 * lengths[2] * inward
    hit = world.client.rayTest((middle + [0, 0, 0.02]).tolist(), middle.tolist())[0]
    assert hit[0] == world.hand_id
    np.testing.assert_allclose(hit[3], middle + [0, 0, r], atol=1e-4)


def test_initial_posture_does_not_touch_object_or_table(world: HandWorld,
                                                        cfg: DamConfig) -> None:
    q = world.joint_states().positions
    expected = {'compliant': world.options.initial_compliant_angle_rad,
                'locked': cfg.hand.initial_locked_angle_rad,
                'position': cfg.hand.initial_position_angle_rad}
    for name, angle in zip(world.joint_names, q, strict=True):
        assert angle == pytest.approx(expected[name.split('_')[1]], abs=1e-12)
    assert world.joint_modes().tolist() == [H] * world.n_joints
    for other in (world.object_id, world.table_id):
        closest = world.client.getClosestPoints(world.hand_id, other, 0.002)
        assert len(closest) == 0 or min(c[8] for c in closest) > 0.0
    world.step(1000)
    assert world.hand_object_contacts() == []
    pose = world.object_pose()
    np.testing.assert_allclose(pose.position, cfg.object.position_m, atol=1e-4)
    assert world.object_table_contacts() > 0
    assert pose.sim_time == pytest.approx(1.0)


def test_object_axis_lies_along_the_configured_axis(world: HandWorld, cfg: DamConfig) -> None:
    quat = world.object_pose().quaternion
    rot = np.array(world.client.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)
    np.testing.assert_allclose(rot[:, 2], cfg.object.axis, atol=1e-9)


# --------------------------------------------------------------------------------------------
# Torque control and the torque sensor


def _finger_inertia(cfg: DamConfig, world: HandWorld, angles: np.ndarray) -> float:
    """Inertia of a rigid finger about its compliant joint axis [kg m^2] (parallel axes)."""
    _, centres = _finger_plane_points(cfg, angles)
    r = cfg.hand.link_radius_m
    total = 0.0
    for m, length, c in zip(world.link_masses_kg, cfg.hand.link_lengths_m, centres, strict=True):
        total += m * (3 * r**2 + length**2) / 12.0 + m * float(c @ c)
    return total


def _displacement(alpha: float, steps: int, dt: float) -> float:
    """Angle travelled from rest under constant angular acceleration ``alpha`` [rad/s^2].

    Bullet integrates semi-implicitly (velocity first, then position), so after n steps the
    angle is alpha dt^2 n (n + 1) / 2, not alpha t^2 / 2.
    """
    return alpha * dt**2 * steps * (steps + 1) / 2.0


def _gravity_torque(cfg: DamConfig, world: HandWorld, angles: np.ndarray) -> float:
    """Torque the compliant joint must apply to hold the finger against gravity [N m]."""
    _, centres = _finger_plane_points(cfg, angles)
    g = cfg.task.gravity_m_per_s2
    return float(sum(m * g * c[0] for m, c in zip(world.link_masses_kg, centres, strict=True)))


@pytest.mark.parametrize('sign', [1.0, -1.0])
def test_torque_accelerates_compliant_joint_by_tau_over_inertia(
        world: HandWorld, cfg: DamConfig, sign: float) -> None:
    world.set_gravity((0.0, 0.0, 0.0))
    q0 = world.joint_states().positions
    tips0 = world.fingertip_positions()
    tau = sign * 0.004
    modes = [H] * world.n_joints
    setpoints = [math.nan] * world.n_joints
    for f in range(3):
        modes[3 * f] = T
        setpoints[3 * f] = tau
    world.set_joint_commands(modes, setpoints)
    steps = 20
    world.step(steps)
    q = world.joint_states().positions
    for f in range(3):
        inertia = _finger_inertia(cfg, world, q0[3 * f:3 * f + 3])
        expected = _displacement(tau / inertia, steps, world.time_step_s)
        assert q[3 * f] - q0[3 * f] == pytest.approx(expected, rel=0.01)
        # Positive torque flexes inward: the tip moves towards the object.
        inward = cfg.hand.fingers[f].inward_direction
        assert sign * float((world.fingertip_positions()[f] - tips0[f]) @ inward) > 0.0
    # The other joints were held.
    held = [i for i in range(world.n_joints) if i % 3]
    np.testing.assert_allclose(q[held], q0[held], atol=1e-3)


def test_servo_torque_reading_equals_gravity_torque_of_a_tilted_finger(
        world: HandWorld, cfg: DamConfig) -> None:
    angles = np.array([math.radians(45.0), 0.0, 0.0])
    _servo(world, np.tile(angles, 3), 1.0)
    states = world.joint_states()
    # Closed form: g sin(45 deg) (m1 L1/2 + m2 (L1 + L2/2) + m3 (L1 + L2 + L3/2)).
    m, (l1, l2, l3) = world.link_masses_kg, cfg.hand.link_lengths_m
    g = cfg.task.gravity_m_per_s2
    closed = g * math.sin(math.radians(45.0)) * (
        m[0] * l1 / 2 + m[1] * (l1 + l2 / 2) + m[2] * (l1 + l2 + l3 / 2))
    for f in range(3):
        assert states.torques[3 * f] == pytest.approx(closed, rel=0.01)
        assert abs(states.velocities[3 * f]) < 1e-3


def test_horizontal_distal_link_loads_joints_with_m_g_half_length(
        world: HandWorld, cfg: DamConfig) -> None:
    _servo(world, np.tile([0.0, 0.0, math.radians(90.0)], 3), 1.0)
    states = world.joint_states()
    closed = world.link_masses_kg[2] * cfg.task.gravity_m_per_s2 * cfg.hand.link_lengths_m[2] / 2
    for f in range(3):
        # Links 1 and 2 hang vertically: every joint carries only the distal link's moment.
        for j in range(3):
            assert states.torques[3 * f + j] == pytest.approx(closed, rel=0.01)


def test_gravity_compensating_torque_holds_finger_still(world: HandWorld,
                                                        cfg: DamConfig) -> None:
    angles = np.array([math.radians(30.0), 0.0, math.radians(15.0)])
    _servo(world, np.tile(angles, 3), 1.0)
    q0 = world.joint_states().positions
    tau_g = _gravity_torque(cfg, world, q0[:3])
    assert tau_g > 0.0
    inertia = _finger_inertia(cfg, world, q0[:3])
    modes = [T, H, H] * 3
    world.set_joint_commands(modes, [tau_g, 0, 0, 0.0, 0, 0, 0.5 * tau_g, 0, 0])
    steps = 20
    world.step(steps)
    q = world.joint_states().positions
    fall = _displacement(-tau_g / inertia, steps, world.time_step_s)
    assert abs(q[0] - q0[0]) < 0.01 * abs(fall)  # finger 1: balanced
    # Finger 2: no torque, falls back with alpha = -tau_g / I; finger 3: half of that.
    assert q[3] - q0[3] == pytest.approx(fall, rel=0.02)
    assert q[6] - q0[6] == pytest.approx(0.5 * fall, rel=0.02)


def test_torque_mode_reports_applied_clipped_torque(world: HandWorld) -> None:
    limit = world.options.torque_limit_nm
    world.set_gravity((0.0, 0.0, 0.0))
    modes = [T, H, H] * 3
    world.set_joint_commands(modes, [0.002, 0, 0, 5.0 * limit, 0, 0, -5.0 * limit, 0, 0])
    assert world.joint_states().torques.tolist() == [0.0] * world.n_joints  # before a step
    # past the slew from zero to the limit
    world.step(math.ceil(limit / world.options.torque_rate_limit_nm_per_s
                         / world.time_step_s) + 1)
    torques = world.joint_states().torques
    assert torques[0] == pytest.approx(0.002)
    assert torques[3] == pytest.approx(limit) and torques[6] == pytest.approx(-limit)
    faults = world.joint_faults()
    assert faults[0] & JointFault.SATURATED == 0
    assert faults[3] & JointFault.SATURATED and faults[6] & JointFault.SATURATED


def test_limit_fault_flags_joints_at_their_limits(world: HandWorld) -> None:
    assert not np.any(world.joint_faults() & JointFault.LIMIT)  # initial posture is inside
    upper = world.joint_upper_limits
    world.reset(joint_positions=np.where(np.arange(world.n_joints) % 3 == 2, upper,
                                         world.initial_positions()))
    limited = (world.joint_faults() & JointFault.LIMIT) != 0
    assert limited.tolist() == [False, False, True] * 3


# --------------------------------------------------------------------------------------------
# Modes


def test_rotor_inertia_adds_to_the_compliant_joint(cfg: DamConfig) -> None:
    """The drive inertia J slows a torque-driven compliant joint to tau / (I_finger + J)."""
    rotor = 5e-4
    with HandWorld(cfg, WorldOptions.from_config(
            cfg, compliant_rotor_inertia_kg_m2=rotor)) as w:
        w.set_gravity((0.0, 0.0, 0.0))
        q0 = w.joint_states().positions
        tau = 0.004
        w.set_joint_commands([T, H, H] * 3, [tau, math.nan, math.nan] * 3)
        steps = 20
        w.step(steps)
        q = w.joint_states().positions
        inertia = _finger_inertia(cfg, w, q0[0:3]) + rotor
        expected = _displacement(tau / inertia, steps, w.time_step_s)
        assert q[0] - q0[0] == pytest.approx(expected, rel=0.01)
        # more than 4 times slower than the bare finger (~1.1e-4 kg*m^2)
        assert expected < _displacement(tau / (inertia - rotor), steps, w.time_step_s) / 4.0


def test_palm_stops_the_object_above_the_fingers(cfg: DamConfig) -> None:
    """The palm's underside is the base plane; an object pushed up stops there, and the
    palm does not touch the fingers at any joint angle."""
    with HandWorld(cfg) as w:
        assert w.palm_id is not None
        base_z = max(float(f.base_position_m[2]) for f in cfg.hand.fingers)
        r = cfg.object.radius_m
        w.reset(object_position=[0.0, 0.0, base_z - r - 0.001])
        w.set_gravity((0.0, 0.0, 9.81))  # "falls" upwards onto the palm
        w.step(500)
        z = float(w.object_pose().position[2])
        assert z == pytest.approx(base_z - r, abs=1e-3)
        hand = w.client.getContactPoints(w.palm_id, w.hand_id)
        assert hand == ()
    with HandWorld(cfg, WorldOptions.from_config(cfg, palm_thickness_m=0.0)) as w:
        assert w.palm_id is None


def test_hold_keeps_the_angle_at_the_switch(world: HandWorld) -> None:
    world.set_gravity((0.0, 0.0, 0.0))
    world.set_joint_commands([T, H, H] * 3, [0.003, 0, 0] * 3)
    world.step(30)
    q_switch = world.joint_states().positions
    assert q_switch[0] > world.initial_positions()[0] + 0.01
    world.set_joint_commands([H] * world.n_joints, [math.nan] * world.n_joints)
    world.step(500)
    q = world.joint_states().positions
    # Held within the overshoot of stopping a moving joint.
    assert q[0] == pytest.approx(q_switch[0], abs=0.01)
    assert abs(world.joint_states().velocities[0]) < 1e-3
    # A repeated HOLD does not re-capture.
    world.set_joint_commands([H] * world.n_joints, [0.0] * world.n_joints)
    world.step(10)
    assert world.joint_states().positions[0] == pytest.approx(q[0], abs=1e-4)


def test_position_setpoints_are_clipped_to_joint_limits(world: HandWorld) -> None:
    world.set_gravity((0.0, 0.0, 0.0))
    upper = world.joint_upper_limits
    _servo(world, upper + 1.0, 1.0)
    np.testing.assert_allclose(world.joint_states().positions, upper, atol=5e-3)


@pytest.mark.parametrize('modes, setpoints, word', [
    ([T] * 8, [0.0] * 8, 'shape'),
    ([7] + [H] * 8, [0.0] * 9, 'modes'),
    ([T] + [H] * 8, [math.nan] + [0.0] * 8, 'finger1_compliant_joint'),
    ([H, P] + [H] * 7, [0.0, math.inf] + [0.0] * 7, 'finger1_locked_joint'),
])
def test_bad_commands_are_refused_with_the_joint_named(world: HandWorld, modes: list,
                                                       setpoints: list, word: str) -> None:
    with pytest.raises(CommandError, match=word):
        world.set_joint_commands(modes, setpoints)


def test_bad_options_are_refused() -> None:
    with pytest.raises(WorldConfigError, match='time_step_s'):
        WorldOptions(time_step_s=0.0)
    with pytest.raises(WorldConfigError, match='link_masses_kg'):
        WorldOptions(link_masses_kg=(0.01, -0.01, 0.01))
    with pytest.raises(WorldConfigError, match='initial_compliant_angle_rad'):
        HandWorld(load_config(), WorldOptions(initial_compliant_angle_rad=-2.0))


def test_gui_without_a_display_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv('DISPLAY', raising=False)
    monkeypatch.delenv('WAYLAND_DISPLAY', raising=False)
    with pytest.raises(SimulationError, match='DISPLAY'):
        HandWorld(load_config(), WorldOptions(gui=True))


def test_reset_refuses_postures_outside_the_limits(world: HandWorld) -> None:
    q = world.initial_positions()
    q[4] = world.joint_upper_limits[4] + 0.1
    with pytest.raises(WorldConfigError, match='finger2_locked_joint'):
        world.reset(joint_positions=q)
    with pytest.raises(WorldConfigError, match='finite'):
        world.reset(joint_positions=[math.nan] * world.n_joints)


def test_reset_restores_posture_and_object(world: HandWorld, cfg: DamConfig) -> None:
    world.set_joint_commands([T] * world.n_joints, [0.01] * world.n_joints)
    world.step(200)
    world.reset(object_position=[0.0, 0.005, 0.012])
    assert world.sim_time == 0.0
    np.testing.assert_allclose(world.joint_states().positions, world.initial_positions())
    np.testing.assert_allclose(world.object_pose().position, [0.0, 0.005, 0.012])
    world.reset()
    np.testing.assert_allclose(world.object_pose().position, cfg.object.position_m)


def test_reset_clears_contacts_of_the_previous_run(world: HandWorld) -> None:
    world.set_joint_commands([T, H, H] * 3, [0.01, 0, 0] * 3)
    world.step(500)
    assert len(world.hand_object_contacts()) > 0  # the fingers closed on the object
    world.reset()
    assert world.hand_object_contacts() == []


def test_identical_runs_are_bitwise_identical(cfg: DamConfig) -> None:
    def run() -> tuple[np.ndarray, np.ndarray]:
        with HandWorld(cfg) as w:
            w.set_joint_commands([T, H, P] * 3, [0.01, 0.0, 0.6] * 3)
            w.step(800)
            return w.joint_states().positions, w.object_pose().position

    (q1, o1), (q2, o2) = run(), run()
    assert q1.tolist() == q2.tolist() and o1.tolist() == o2.tolist()


# --------------------------------------------------------------------------------------------
# Friction


def test_pair_friction_coefficients_are_exact(world: HandWorld, cfg: DamConfig) -> None:
    mu_table = cfg.contact.table_friction_coefficient
    alpha = cfg.contact.friction_angle_rad
    pairs = world.pair_friction()
    assert pairs['finger_object'] == pytest.approx(math.tan(alpha), rel=1e-6)
    assert pairs['table_object'] == pytest.approx(mu_table, rel=1e-6)
    for alpha_deg in (0.0, 1.0, 30.0):
        world.set_friction_angle(math.radians(alpha_deg))
        pairs = world.pair_friction()
        assert pairs['finger_object'] == pytest.approx(math.tan(math.radians(alpha_deg)),
                                                       abs=1e-7)
        assert pairs['table_object'] == pytest.approx(mu_table, rel=1e-6)
    world.reset(table_friction_coefficient=0.3, friction_angle_rad=math.radians(5.0))
    pairs = world.pair_friction()
    assert pairs['table_object'] == pytest.approx(0.3, rel=1e-6)
    assert pairs['finger_object'] == pytest.approx(math.tan(math.radians(5.0)), rel=1e-6)
    # Every link of every finger carries the same coefficient.
    for j in world.joint_indices:
        mu_link = world.client.getDynamicsInfo(world.hand_id, j)[1]
        assert mu_link == pytest.approx(math.tan(math.radians(5.0)), rel=1e-6)
    with pytest.raises(WorldConfigError, match='friction angle'):
        world.set_friction_angle(math.pi / 2)


@pytest.mark.parametrize('mu', [0.5, 0.2])
def test_object_on_tilted_table_sticks_below_and_slides_above_atan_mu(
        world: HandWorld, cfg: DamConfig, mu: float) -> None:
    """Gravity tilted by beta along the cylinder's axis is an incline the cylinder cannot roll
    down: it sticks for tan(beta) < mu and slides with a = g (sin beta - mu cos beta)."""
    g = cfg.task.gravity_m_per_s2
    axis = cfg.object.axis
    world.reset(table_friction_coefficient=mu)
    for beta_deg, slides in ((math.degrees(math.atan(mu)) - 5.0, False),
                             (math.degrees(math.atan(mu)) + 10.0, True)):
        world.reset()
        beta = math.radians(beta_deg)
        world.set_gravity(g * math.sin(beta) * axis + np.array([0, 0, -g * math.cos(beta)]))
        start = world.object_pose().position
        steps = 200
        world.step(steps)
        t = steps * world.time_step_s
        travelled = float((world.object_pose().position - start) @ axis)
        if slides:
            expected = 0.5 * g * (math.sin(beta) - mu * math.cos(beta)) * t**2
            assert travelled == pytest.approx(expected, rel=0.05)
        else:
            assert abs(travelled) < 1e-4


@pytest.mark.parametrize('alpha_deg, margin_deg', [(5.0, -2.0), (5.0, 10.0), (30.0, -2.0),
                                                    (30.0, 10.0), (0.0, 5.0)])
def test_object_on_horizontal_fingers_sticks_below_and_slides_above_alpha(
        world: HandWorld, cfg: DamConfig, alpha_deg: float, margin_deg: float) -> None:
    """The cylinder rests across the horizontal distal links of fingers 2 and 3 (off the
    table); gravity tilted by beta along its axis makes it stick for beta < alpha and slide with
    a = g (sin beta - tan(alpha) cos beta) above: the finger-object coefficient is tan(alpha)."""
    g = cfg.task.gravity_m_per_s2
    lengths, r = cfg.hand.link_lengths_m, cfg.hand.link_radius_m
    f2 = cfg.hand.fingers[1]
    distal_z = f2.base_position_m[2] - lengths[0] - lengths[1]
    centre = (f2.base_position_m[0] + 0.8 * lengths[2], 0.0, distal_z + r + cfg.object.radius_m)
    world.reset(friction_angle_rad=math.radians(alpha_deg), object_position=centre,
                joint_positions=[0.0, 0.0, math.radians(90.0)] * 3)
    beta = math.radians(alpha_deg + margin_deg)
    axis = cfg.object.axis
    world.set_gravity(g * math.sin(beta) * axis + np.array([0.0, 0.0, -g * math.cos(beta)]))
    steps = 100
    world.step(steps)
    travelled = float((world.object_pose().position - np.array(centre)) @ axis)
    assert world.object_table_contacts() == 0
    touching = {name.split('_')[0] for name, _ in world.hand_object_contacts()}
    assert touching == {'finger2', 'finger3'}
    if margin_deg < 0:
        assert abs(travelled) < 2e-5
    else:
        t = steps * world.time_step_s
        mu = math.tan(math.radians(alpha_deg))
        expected = 0.5 * g * (math.sin(beta) - mu * math.cos(beta)) * t**2
        assert travelled == pytest.approx(expected, rel=0.03)


# --------------------------------------------------------------------------------------------
# The device watchdog driving the world


# --------------------------------------------------------------------------------------------
# Device-side joint impedance (IMPEDANCE mode)


def _impedance_on_finger1(world: HandWorld, theta_0: float, k: float, d: float) -> None:
    """Finger 1: compliant joint in IMPEDANCE, locked and position joints servoed at 0 (a
    straight finger); the other fingers hold."""
    n = world.n_joints
    modes = [H] * n
    modes[0:3] = [IMP, P, P]
    setpoints = [math.nan] * n
    setpoints[0:3] = [theta_0, 0.0, 0.0]
    stiffness = [math.nan] * n
    damping = [math.nan] * n
    stiffness[0], damping[0] = k, d
    world.set_joint_commands(modes, setpoints, stiffness, damping)


@pytest.mark.parametrize('theta_0_deg, k', [(30.0, 0.2), (20.0, 0.4), (-20.0, 0.1)])
def test_impedance_settles_where_stiffness_balances_gravity(
        world: HandWorld, cfg: DamConfig, theta_0_deg: float, k: float) -> None:
    """Static equilibrium k (theta_0 - theta) = g sin(theta) sum_i m_i r_i of a straight finger
    (r_i: distance of link i's centre from the compliant joint), solved here by bisection."""
    world.reset(object_position=[0.3, 0.0, 0.010], joint_positions=np.zeros(world.n_joints))
    theta_0 = math.radians(theta_0_deg)
    _impedance_on_finger1(world, theta_0, k, 0.02)
    world.step(1500)
    lengths = np.asarray(cfg.hand.link_lengths_m)
    masses = np.asarray(world.link_masses_kg)
    r = np.cumsum(lengths) - 0.5 * lengths
    moment = cfg.task.gravity_m_per_s2 * float(masses @ r)  # [N m] at 90 deg

    def residual(theta: float) -> float:
        return k * (theta_0 - theta) - moment * math.sin(theta)

    lo, hi = -math.pi / 2, math.pi / 2
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if residual(mid) > 0 else (lo, mid)
    expected = 0.5 * (lo + hi)
    js = world.joint_states()
    assert js.positions[0] == pytest.approx(expected, abs=math.radians(0.2))
    # sagged towards the vertical, by a visible amount
    assert abs(js.positions[0]) < abs(theta_0) - math.radians(0.5)
    assert abs(js.velocities[0]) < 1e-3
    # the torque sensor reads what the device applied, which is the gravity torque now
    assert js.torques[0] == pytest.approx(moment * math.sin(expected), rel=0.02, abs=1e-4)
    assert js.torques[0] == pytest.approx(k * (theta_0 - js.positions[0]), rel=0.02, abs=1e-4)
    assert world.joint_modes()[0] == IMP


def test_impedance_step_response_of_a_free_joint_is_the_damped_oscillator(
        world: HandWorld, cfg: DamConfig) -> None:
    """Without gravity, theta'' I + d theta' + k theta = k theta_0 with the finger's inertia I
    (parallel axes, computed here): the closed-form underdamped step response, sampled every
    physics step; the law must run at every step (once per 2 ms device cycle would not give
    this curve at this resolution)."""
    world.set_gravity((0.0, 0.0, 0.0))
    q0 = world.joint_states().positions.copy()
    inertia = _finger_inertia(cfg, world, q0[0:3])
    k, d = 0.05, 0.001
    step = 0.1
    n = world.n_joints
    modes = [H] * n
    modes[0] = IMP
    setpoints = [math.nan] * n
    setpoints[0] = q0[0] + step
    world.set_joint_commands(modes, setpoints, [k] + [0.0] * (n - 1), [d] + [0.0] * (n - 1))
    omega_n = math.sqrt(k / inertia)
    zeta = d / (2.0 * math.sqrt(k * inertia))
    assert 0.1 < zeta < 0.4
    omega_d = omega_n * math.sqrt(1.0 - zeta**2)
    dt = world.time_step_s
    errors = []
    peak = -math.inf
    for i in range(1, 401):
        world.step(1)
        t = i * dt
        expected = step * (1.0 - math.exp(-zeta * omega_n * t) * (
            math.cos(omega_d * t) + zeta / math.sqrt(1.0 - zeta**2) * math.sin(omega_d * t)))
        got = world.joint_states().positions[0] - q0[0]
        errors.append(got - expected)
        peak = max(peak, got)
    assert max(abs(e) for e in errors) < 0.03 * step
    overshoot = math.exp(-math.pi * zeta / math.sqrt(1.0 - zeta**2))
    assert peak - step == pytest.approx(overshoot * step, rel=0.05)


def test_impedance_torque_is_clipped_and_flagged(world: HandWorld) -> None:
    """An equilibrium 1 rad beyond the upper joint limit: the joint stops at the limit while
    the device's equilibrium ramps on, until the law demands 2 N*m, beyond the actuator."""
    world.set_gravity((0.0, 0.0, 0.0))
    upper = world.joint_upper_limits[0]
    limit = world.options.torque_limit_nm
    _impedance_on_finger1(world, upper + 1.0, 2.0, 0.0)
    world.step(1000)
    js = world.joint_states()
    assert js.positions[0] == pytest.approx(upper, abs=0.01)
    assert js.torques[0] == pytest.approx(limit)
    assert world.joint_faults()[0] & JointFault.SATURATED


@pytest.mark.parametrize('stiffness, damping, word', [
    (None, None, 'need a stiffness'),
    ([0.0] * 9, [0.0] * 9, 'stiffness > 0'),
    ([1.0] * 9, [-0.1] * 9, 'damping >= 0'),
    ([math.inf] * 9, [0.0] * 9, 'finite'),
    ([1.0] * 8, [0.0] * 9, 'shape'),
])
def test_bad_impedance_gains_are_refused(world: HandWorld, stiffness, damping, word) -> None:
    with pytest.raises(CommandError, match=word):
        world.set_joint_commands([IMP] * 9, [0.0] * 9, stiffness, damping)


def test_watchdog_safe_state_zeroes_impedance_torque(world: HandWorld, cfg: DamConfig) -> None:
    now = [0.0]
    watchdog = DeviceWatchdog(world.n_joints, cfg.device.watchdog_s, clock=lambda: now[0])
    cal = Calibration.from_config(cfg)
    modes = np.array([IMP, H, H] * 3)
    theta_0 = world.joint_states().positions + 0.2
    k_raw, d_raw = cal.gains_raw(modes, np.full(9, 0.5), np.full(9, 0.02))
    watchdog.feed(modes, cal.setpoints_raw(modes, np.where(modes == IMP, theta_0, 0.0)),
                  k_raw, d_raw)
    for _ in range(int(cfg.device.watchdog_s / world.time_step_s) + 50):
        out = watchdog.output()
        k, d = cal.gains_si(out.stiffness, out.damping)
        world.set_joint_commands(out.modes, cal.setpoints_si(out.modes, out.setpoints), k, d)
        world.step(1)
        now[0] += world.time_step_s
    assert out.tripped
    assert world.joint_modes().tolist() == [T, H, H] * 3
    assert world.joint_states().torques[0::3].tolist() == [0.0] * 3


def test_watchdog_safe_state_zeroes_torque_and_holds_servoed_joints(
        world: HandWorld, cfg: DamConfig) -> None:
    now = [0.0]
    watchdog = DeviceWatchdog(world.n_joints, cfg.device.watchdog_s, clock=lambda: now[0])
    cal = Calibration.from_config(cfg)

    def run(steps: int) -> bool:
        for _ in range(steps):
            modes, raw, _k, _d, tripped = watchdog.output()
            world.set_joint_commands(modes, cal.setpoints_si(modes, raw))
            world.step(1)
            now[0] += world.time_step_s
        return tripped

    modes = np.array([T, H, P] * 3)
    q0 = world.joint_states().positions
    for i in range(50):  # a ramp on the position joints, fed every step
        setpoints = np.where(modes == P, q0 + 0.5 * world.time_step_s * (i + 1), 0.02)
        watchdog.feed(modes, cal.setpoints_raw(modes, setpoints))
        assert not run(1)
    moving = world.joint_states()
    assert np.all(moving.velocities[2::3] > 0.3)  # position joints follow the ramp
    np.testing.assert_allclose(moving.torques[0::3], 0.02, atol=cal.torque_scale[0])
    tripped_at = moving.positions
    assert run(int(cfg.device.watchdog_s / world.time_step_s) + 300)
    assert world.joint_modes().tolist() == [T, H, H] * 3
    safe = world.joint_states()
    assert safe.torques[0::3].tolist() == [0.0] * 3
    # The position joints stopped where the watchdog tripped. The free compliant joints swing
    # into the object: a distal link it touches right now moves with that contact (a few
    # mrad/s, rigid or compliant), so only the others must be still; every angle holds.
    touching = {name for name, _ in world.hand_object_contacts()}
    still = [i for i in range(2, world.n_joints, 3) if world.joint_names[i] not in touching]
    assert np.all(np.abs(safe.velocities[still]) < 1e-3)
    np.testing.assert_allclose(safe.positions[2::3], tripped_at[2::3], atol=0.01)
    assert watchdog.trips == 1
    # A fresh command takes effect at once.
    watchdog.feed(modes, cal.setpoints_raw(modes, setpoints))
    assert not run(1)
    assert world.joint_modes().tolist() == modes.tolist()


# --------------------------------------------------------------------------------------------
# Lockstep speed (measured and printed; no timing assertion)


def test_lockstep_speed_is_measured(world: HandWorld) -> None:
    world.set_joint_commands([T, H, P] * 3, [0.0, 0.0, 0.3] * 3)
    steps = 3000
    started = time.perf_counter()
    world.step(steps)
    wall = time.perf_counter() - started
    assert world.sim_time == pytest.approx(steps * world.time_step_s)
    print(f'lockstep: {steps} steps, {world.sim_time:.3f} s simulated in {wall:.3f} s wall: '
          f'{world.sim_time / wall:.1f}x real time')


def test_lockstep_speed_with_a_command_every_step_is_measured(world: HandWorld) -> None:
    steps = 2000
    modes = np.array([T, H, P] * 3)
    started = time.perf_counter()
    for i in range(steps):
        q = world.joint_states().positions
        world.set_joint_commands(modes, np.where(modes == T, -0.05 * q, 0.3 + 1e-4 * i))
        world.step(1)
    wall = time.perf_counter() - started
    assert world.sim_time == pytest.approx(steps * world.time_step_s)
    print(f'lockstep with a command per step: {world.sim_time / wall:.1f}x real time')
