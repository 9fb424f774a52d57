"""The physics core through its plain API: tracking, safety, base motion, grasping."""

import math

import numpy as np
import pytest
from .sim_reach import move_to, solve_down

from asibot.messages import COMMAND_WATCHDOG_S, ArmCommand
from asibot.safety.events import CommandRefused

TOL = math.radians(0.5)


def drain(sim):
    out = []
    while not sim.notices.empty():
        out.append(sim.notices.get())
    return out


@pytest.mark.parametrize("world", ["kitchen", "apartment"])
def test_commanded_joint_positions_are_reached(world, request):
    sim = request.getfixturevalue(world)
    lo, hi = np.array(sim.robot.lower), np.array(sim.robot.upper)
    home = np.array(sim.robot.home)
    goal = np.clip(home + np.radians([20, 10, -10, 15, 30]), lo, hi)
    move_to(sim, goal, settle_s=1.0)
    state = sim.arm_state()
    assert np.max(np.abs(np.array(state.positions) - goal)) < TOL
    assert state.mode == "position" and state.fault == ""
    assert np.max(np.abs(state.velocities)) < 0.01


def test_position_command_beyond_limits_is_refused_and_moves_nothing(kitchen):
    upper = np.array(kitchen.robot.upper)
    goal = np.array(kitchen.robot.home, float)
    goal[1] = upper[1] + 1.0
    before = kitchen.arm_state().positions
    with pytest.raises(CommandRefused, match=r"joint q2 position 3.36 rad is beyond its upper limit 2.36 rad"):
        kitchen.command_arm(ArmCommand(mode="position", values=goal.tolist()))
    kitchen.step(int(0.5 / kitchen.dt))
    assert kitchen.arm_state().positions == pytest.approx(before, abs=1e-3) and kitchen.arm.mode == "idle"


@pytest.mark.parametrize("values", [[1e300] * 5, [math.nan, 0, 0, 0, 0], [0, 0, 0, 0, -1e300]])
def test_huge_and_non_finite_positions_are_refused(kitchen, values):
    before = kitchen.arm_state().positions
    cmd = ArmCommand(mode="position", values=[0.0] * 5)
    cmd.values = values                   # bypass the message's own check (NaN)
    with pytest.raises(CommandRefused, match="joint q[15] "):
        kitchen.command_arm(cmd)
    kitchen.step(int(0.5 / kitchen.dt))
    assert kitchen.arm_state().positions == pytest.approx(before, abs=1e-3)


def test_a_goal_at_a_limit_is_reached_and_never_passed(kitchen):
    """And the hold the kinematics service sends on a stop, at a position measured a few
    mrad past the limit while the servo overshoots, is not refused."""
    upper = kitchen.robot.upper[2]
    goal = [0.0, 0.0, upper, 0.0, 0.0]
    kitchen.command_arm(ArmCommand(mode="position", values=goal))
    peak = -1.0
    for _ in range(int(8.0 / kitchen.dt) // 5):
        kitchen.step(5)
        q = kitchen.arm_state().positions
        peak = max(peak, q[2])
        kitchen.command_arm(ArmCommand(mode="position", values=q))   # hold where it is: accepted
        kitchen.command_arm(ArmCommand(mode="position", values=goal))
    assert kitchen.arm.q_ref[2] == upper
    assert peak <= upper + 0.01


def test_velocity_mode_watchdog_stops_the_arm(kitchen):
    kitchen.command_arm(ArmCommand(mode="velocity", values=[0.2, 0, 0, 0, 0]))
    kitchen.step(int(1.0 / kitchen.dt))          # no further command for 1 s
    q = kitchen.arm_state().positions[0]
    assert q == pytest.approx(0.2 * 0.2, abs=0.01)   # moved for the 200 ms only
    kitchen.step(int(0.5 / kitchen.dt))
    assert kitchen.arm_state().positions[0] == pytest.approx(q, abs=1e-3)
    assert "watchdog" in [n.code for n in drain(kitchen)]


def test_estop_stops_arm_and_base_and_is_latched(apartment):
    sim = apartment
    for _ in range(25):
        sim.command_arm(ArmCommand(mode="velocity", values=[0.3, 0, 0, 0, 0]))
        sim.command_base(0.4, 0.0)
        sim.step(10)
    sim.set_estop(True, "test")
    sim.step(int(0.3 / sim.dt))
    q, pose = sim.arm_state().positions[0], sim.truth()
    assert sim.command_base(0.4, 0.0) is False          # ignored, as every driver does
    assert sim.command_arm(ArmCommand(mode="velocity", values=[0.3, 0, 0, 0, 0])) is False
    assert sim.command_gripper(0.0) is False
    sim.step(int(1.0 / sim.dt))
    assert sim.arm_state().positions[0] == pytest.approx(q, abs=1e-3)
    assert sim.truth()[0] == pytest.approx(pose[0], abs=1e-3)
    assert [n.code for n in drain(sim)].count("estop") == 1
    sim.set_estop(False)
    assert sim.command_base(0.4, 0.0) is True


def test_base_at_0_3_m_per_s_for_2_s_travels_0_6_m(apartment):
    sim = apartment
    x0, y0, _ = sim.truth()
    for _ in range(100):                      # 2 s of commands at 50 Hz
        sim.command_base(0.3, 0.0)
        sim.step(10)
    sim.command_base(0.0, 0.0)
    sim.step(int(0.5 / sim.dt))
    x, y, th = sim.truth()
    travelled = math.hypot(x - x0, y - y0)
    assert travelled == pytest.approx(0.6, abs=0.03)
    odom = sim.odometry()
    assert odom.x == pytest.approx(travelled, abs=0.005)
    assert abs(odom.y) < 0.005 and abs(th) < 0.01


def test_base_turns_in_place_and_odometry_follows(apartment):
    sim = apartment
    for _ in range(100):                      # 0.5 rad/s for 2 s
        sim.command_base(0.0, 0.5)
        sim.step(10)
    sim.command_base(0.0, 0.0)
    sim.step(int(0.5 / sim.dt))
    _, _, th = sim.truth()
    assert th == pytest.approx(1.0, abs=0.05)
    assert sim.odometry().theta == pytest.approx(th, abs=0.005)


def test_furniture_blocks_the_base_and_the_bumper_reports_it(apartment):
    sim = apartment
    sim.set_estop(False)
    # the charging station is behind the robot (west); drive backwards into it
    for _ in range(200):
        sim.command_base(-0.4, 0.0)
        sim.step(10)
    x, _, _ = sim.truth()
    assert x > 0.15 + 0.3                      # did not pass through the station
    bumpers = sim.bumpers()
    assert any(bumpers.rear) and not any(bumpers.front)


def test_sonar_sees_the_wall_behind(apartment):
    sonar = apartment.sonar()
    assert len(sonar.ranges) == 16 and len(sonar.angles) == 16
    # sonar 11 and 12 look backwards (+-170 deg) from x = -0.241; the charging station's
    # face is at x = 0.15 in the world, the robot at x = 1.0
    rear = min(sonar.ranges[11], sonar.ranges[12])
    assert rear == pytest.approx(1.0 - 0.241 - 0.15, abs=0.05)


def test_grasp_lift_and_drop_the_red_can(kitchen):
    sim = kitchen
    can0 = sim.object_position("red_can")
    grip_at = can0 + [0, 0, 0.03]  # fingers around the upper half; the wrist stays above the can
    q_above = solve_down(sim, grip_at + [0, 0, 0.12], np.array(sim.robot.home) + np.radians([0, 20, 60, 60, 0]))
    q_at = solve_down(sim, grip_at, q_above)
    sim.command_gripper(sim.scene.gripper.max_opening)
    move_to(sim, q_above)
    move_to(sim, q_at)
    assert sim.holding() == ""
    sim.command_gripper(0.0)
    sim.step(int(1.0 / sim.dt))
    grip = sim.gripper_state()
    assert grip.holding and sim.holding() == "red_can"
    assert grip.opening == pytest.approx(0.066, abs=0.01)   # stopped by the can's diameter
    held = sim.object_position("red_can")
    q_lift = solve_down(sim, grip_at + [0, 0, 0.10], q_at)
    move_to(sim, q_lift, settle_s=1.0)
    can = sim.object_position("red_can")
    assert can[2] - held[2] == pytest.approx(0.10, abs=0.01)
    assert can[2] - can0[2] > 0.09
    sim.command_gripper(sim.scene.gripper.max_opening)
    sim.step(int(1.0 / sim.dt))
    assert not sim.gripper_state().holding
    assert sim.object_position("red_can")[2] < can[2] - 0.05   # it fell


def test_closing_on_nothing_holds_nothing(kitchen):
    kitchen.command_gripper(0.0)
    kitchen.step(int(1.0 / kitchen.dt))
    g = kitchen.gripper_state()
    assert g.opening < 0.005 and not g.holding


def test_set_object_pose_validates_and_teleports(kitchen):
    with pytest.raises(KeyError, match="no object"):
        kitchen.set_object_pose("unicorn", [0, 0, 1])
    with pytest.raises(ValueError, match="finite"):
        kitchen.set_object_pose("red_can", [0, math.nan, 1])
    before = kitchen.object_position("green_cup")
    with pytest.raises(ValueError, match="quat"):
        kitchen.set_object_pose("green_cup", [0, 0, 1], [0, 0, 0, 0])
    assert np.allclose(kitchen.object_position("green_cup"), before)
    kitchen.set_object_pose("red_can", [1.7, 0.8, 0.9])
    kitchen.step(int(0.5 / kitchen.dt))
    assert kitchen.object_position("red_can")[2] == pytest.approx(0.75 + 0.06, abs=0.01)  # on the table


def test_reset_world_restores_everything(apartment):
    sim = apartment
    for _ in range(50):
        sim.command_base(0.3, 0.2)
        sim.step(10)
    sim.reset_world()
    assert sim.truth() == pytest.approx((1.0, 1.5, 0.0))
    assert sim.odometry().x == 0.0
    assert sim.arm_state().positions == pytest.approx(list(sim.robot.home))


def test_losing_the_controller_stops_a_moving_arm(kitchen):
    kitchen.command_arm(ArmCommand(mode="position", values=[1.0, 0, 0, 0, 0]))
    kitchen.step(int(0.5 / kitchen.dt))
    kitchen.set_controller("arm", None)
    q = kitchen.arm_state().positions[0]
    kitchen.step(int(1.0 / kitchen.dt))
    # it stops where its reference was (a servo lag of ~0.02 rad behind the reading), far from 1.0
    assert kitchen.arm_state().positions[0] == pytest.approx(q, abs=0.03)
    assert q < 0.5
    assert "controller_lost" in [n.code for n in drain(kitchen)]


def test_a_fault_is_reported_and_reset(kitchen):
    kitchen.arm.fail("following_error", "joint q2 cannot follow its command", kitchen.arm_state().positions)
    assert kitchen.command_arm(ArmCommand(mode="position", values=[0.1, 0, 0, 0, 0])) is False   # ignored
    assert kitchen.arm_state().mode == "fault" and kitchen.arm_state().fault
    assert kitchen.reset_fault() == {}
    assert [n.code for n in drain(kitchen)][-2:] == ["fault_reset", "ready"]
    kitchen.step(int(COMMAND_WATCHDOG_S / kitchen.dt) + 1)   # a new request (asibot.safety.arming)
    kitchen.command_arm(ArmCommand(mode="position", values=[0.1, 0, 0, 0, 0]))
    assert kitchen.arm_state().mode == "position"
