import pytest

from asibot import keys


def test_keys_follow_the_catalog():
    assert keys.arm_state("asibot-sim") == "rb/asibot-sim/arm/state"
    assert keys.cart_rpc("asibot", "movl") == "rb/asibot/cart/rpc/movl"
    assert keys.camera_depth("pioneer-sim", "front") == "rb/pioneer-sim/camera/front/depth"
    assert keys.service("kinematics", "asibot-sim") == "svc/kinematics/asibot-sim"
    assert keys.parse_service("svc/kinematics/asibot-sim") == ("kinematics", "asibot-sim")


@pytest.mark.parametrize("bad", ["", "a/b", "*", "a**", "rb/x", " x", "x y", None, 3])
def test_names_that_would_change_a_key_are_refused(bad):
    with pytest.raises(ValueError, match="not a valid name"):
        keys.arm_state(bad)


def test_robot_keys_parse_back_into_robot_and_rest():
    assert keys.parse_robot(keys.arm_state("asibot-sim")) == ("asibot-sim", "arm/state")
    assert keys.parse_robot(keys.cart_rpc("asibot", "movl")) == ("asibot", "cart/rpc/movl")
    assert keys.parse_robot(keys.robot("pioneer")) == ("pioneer", "")
    assert keys.robot_of(keys.base_odom("pioneer-sim")) == "pioneer-sim"
    assert keys.robot_of(keys.camera_info("pioneer-sim", "front")) == "pioneer-sim"


@pytest.mark.parametrize("other", ["svc/kinematics/main", "health/sim/main", "rb", "rb/", "rb/*/arm/state",
                                   "rb/**", "xrb/a/arm/state", "/rb/a/arm/state", "", "**"])
def test_keys_of_no_robot_parse_as_none(other):
    assert keys.robot_of(other) is None
    assert keys.camera_of(other) is None
    with pytest.raises(ValueError, match="not a robot key"):
        keys.parse_robot(other)


def test_camera_keys_give_their_camera_name():
    for key in (keys.camera_depth("pioneer-sim", "front"), keys.camera_rgb("pioneer-sim", "front"),
                keys.camera_info("pioneer-sim", "front")):
        assert keys.camera_of(key) == "front"
    # `camera` as a robot id or in another position is not a camera key.
    for key in (keys.arm_state("camera"), keys.scan("pioneer"), keys.robot("pioneer") + "/camera/front",
                "rb/pioneer/camera/*/depth", "svc/camera/front/depth"):
        assert keys.camera_of(key) is None, key


def test_service_keys_parse_back_and_the_patterns_match_them():
    key = keys.service("kinematics", "asibot-sim")
    assert keys.parse_service(key) == ("kinematics", "asibot-sim")
    assert keys.ALL_SERVICES == "svc/**" and key.startswith(keys.ALL_SERVICES.removesuffix("**"))
    assert keys.health("kinematics", "asibot-sim").startswith(keys.ALL_HEALTH.removesuffix("**"))
    with pytest.raises(ValueError):
        keys.parse_service(keys.arm_state("asibot"))


def test_status_without_a_router_says_so(monkeypatch, capsys):
    from asibot.cli.main import main
    from asibot.testing import free_port
    monkeypatch.setenv("ASIBOT_ROUTER", f"tcp/127.0.0.1:{free_port()}")
    assert main(["status", "--wait", "0.5"]) == 1
    assert "No Zenoh router answers" in capsys.readouterr().err


def test_commands_are_told_apart_from_state():
    for key in (keys.arm_command("r"), keys.gripper_command("r"), keys.base_cmd_vel("r"), keys.estop("r"),
                keys.cart_rpc("r", "movl"), keys.driver_rpc("r", "reset_fault"), keys.nav_rpc("r", "goto"),
                keys.voice_audio("web-1")):
        assert keys.is_command(key), key
    for key in (keys.arm_state("r"), keys.base_odom("r"), keys.events("r"), keys.health("sim", "r"),
                keys.service("sim", "r"), keys.camera_depth("r", "front"), "rb/r/rpcx", keys.voice_heard()):
        assert not keys.is_command(key), key
