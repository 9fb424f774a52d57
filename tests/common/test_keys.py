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


def test_status_without_a_router_says_so(monkeypatch, capsys):
    from asibot.cli import main
    from asibot.testing import free_port
    monkeypatch.setenv("ASIBOT_ROUTER", f"tcp/127.0.0.1:{free_port()}")
    assert main(["status", "--wait", "0.5"]) == 1
    assert "No Zenoh router answers" in capsys.readouterr().err
