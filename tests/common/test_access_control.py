"""The router's access control (asibot.access) against a real Zenoh router on loopback:
a wrong login is refused, the anonymous reader reads and moves nothing, and each role
publishes only its own keys.

A refused put is silent on the sender's side, so "never delivered" is shown by order: after
the refused message, a permitted one goes the same way and is waited for; once it arrived,
the refused one (sent earlier, on the same router, to the same subscriber) never will. That
holds only once the router knows the subscriber: a put before then is dropped whoever sent it,
so each test first hears a probe from every sender (`_heard`) before it sends anything refused.
"""

from __future__ import annotations

import os
import shutil
import signal
import stat
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from asibot import access, keys, messages
from asibot.bus import Bus, open_router
from asibot.errors import NotAllowed, Unavailable
from asibot.messages import ArmCommand, ArmState, EStop, Twist
from asibot.testing import free_port, wait_until

ROBOT = "acl-bot"
COMPOSE = Path(__file__).resolve().parents[2] / "compose.yaml"


class Inbox:
    """What one subscriber received, by key and payload, thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.items: list[tuple[str, dict]] = []

    def __call__(self, key: str, payload: bytes, _received: int) -> None:
        with self._lock:
            self.items.append((key, messages.unpack(payload)))

    def where(self, key: str, **fields: object) -> list[dict]:
        with self._lock:
            return [m for k, m in self.items
                    if k == key and all(m.get(f) == v for f, v in fields.items())]


@pytest.fixture
def secured(tmp_path, monkeypatch):
    """A router with access control on a free loopback port; the folder of its credentials."""
    folder = access.ensure_credentials(tmp_path / "access")
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))
    monkeypatch.delenv(access.ROLE_ENV, raising=False)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_router(endpoint, folder)
    try:
        yield endpoint, folder
    finally:
        session.close()


def _open(name: str, endpoint: str) -> Bus:
    return Bus(name, endpoint, wait=10.0)


def _heard(send: Callable[[], object], arrived: Callable[[], object], who: str) -> None:
    """Send a permitted probe until it arrives: the router then routes this sender's puts to
    the subscriber, so a later refused put is dropped by access control, not by timing."""
    wait_until(lambda: send() or arrived(), timeout=10.0, interval=0.1,
               message=f"{who}'s probe never reached the subscriber")


def test_credentials_are_private_and_made_once(tmp_path):
    folder = access.ensure_credentials(tmp_path / "access")
    assert stat.S_IMODE(folder.stat().st_mode) == 0o700
    files = sorted(p.name for p in folder.iterdir())
    assert files == ["ca.key", "ca.pem", "controller.credentials", "driver.credentials",
                     "operator.credentials", "program.credentials", "router.key", access.DICTIONARY,
                     "router.pem"]
    # Every file is private but the CA's certificate, which every client gets (test_router_tls).
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o600 for p in folder.iterdir() if p.name != "ca.pem")
    before = {p.name: p.read_text() for p in folder.iterdir()}
    access.ensure_credentials(folder)
    assert {p.name: p.read_text() for p in folder.iterdir()} == before
    dictionary = before[access.DICTIONARY].splitlines()
    for role in ("driver", "controller", "operator", "program"):
        assert before[f"{role}.credentials"].strip() in dictionary
    assert "anonymous:anonymous" in dictionary
    passwords = [line.split(":", 1)[1] for line in dictionary if not line.startswith("anonymous")]
    assert len(set(passwords)) == 4 and all(len(p) >= 24 for p in passwords)


def test_roles_come_from_the_bus_name_unless_set(monkeypatch, tmp_path):
    monkeypatch.setenv(access.ACCESS_ENV, str(access.ensure_credentials(tmp_path / "a")))
    monkeypatch.delenv(access.ROLE_ENV, raising=False)
    assert access.login("arm_driver").user == "driver"
    assert access.login("kinematics").user == "controller"
    assert access.login("release").user == "operator"
    assert access.login("recorder") == access.Login("anonymous", "anonymous")
    monkeypatch.setenv(access.ROLE_ENV, "pilot")
    with pytest.raises(ValueError, match="ASIBOT_ROLE='pilot' is not a role: use one of"):
        access.login("web")
    monkeypatch.delenv(access.ACCESS_ENV)
    assert access.login("web") is None


def test_a_router_without_its_passwords_says_how_to_make_them(tmp_path):
    with pytest.raises(ValueError, match="Make them on the robot with `ASIBOT_ACCESS=.* python -m asibot.access`"):
        open_router(f"tcp/127.0.0.1:{free_port()}", tmp_path / "nowhere")


def test_a_wrong_password_or_no_login_is_refused(secured, tmp_path, monkeypatch):
    endpoint, folder = secured
    forged = tmp_path / "forged"
    forged.mkdir()
    (forged / "operator.credentials").write_text("operator:not-the-password\n")
    monkeypatch.setenv(access.ACCESS_ENV, str(forged))
    with pytest.raises(Unavailable, match="accepted the login 'operator'"):
        Bus("web", endpoint, wait=1.5)
    monkeypatch.delenv(access.ACCESS_ENV)
    with pytest.raises(Unavailable, match="set ASIBOT_ACCESS to its credentials folder"):
        Bus("web", endpoint, wait=1.5)
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))
    with _open("web", endpoint) as bus:   # the right one gets in
        assert bus.alive(keys.ALL_SERVICES) == []


def test_the_anonymous_reader_reads_state_and_moves_nothing(secured):
    endpoint, _ = secured
    with _open("arm_driver", endpoint) as driver, _open("kinematics", endpoint) as controller, \
            _open("web", endpoint) as operator, _open("recorder", endpoint) as anonymous:
        seen_by_driver, seen_by_anonymous = Inbox(), Inbox()
        driver.subscribe_raw(f"{keys.robot(ROBOT)}/**", seen_by_driver)
        anonymous.subscribe_raw(keys.arm_state(ROBOT), seen_by_anonymous)
        stop_calls: list[dict] = []
        controller.serve(keys.cart_rpc(ROBOT, "stop"), lambda req: stop_calls.append(req) or {})
        assert operator.wait_for(keys.cart_rpc(ROBOT, "stop"))

        # Reads: the driver's state reaches the anonymous session.
        state = driver.publisher(keys.arm_state(ROBOT), ArmState)
        wait_until(lambda: state.put(ArmState(names=["q1"], positions=[0.1], velocities=[0.0],
                                              mode="idle")) or seen_by_anonymous.where(keys.arm_state(ROBOT)),
                   timeout=10.0, interval=0.1, message="the anonymous session never received arm/state")
        probe = ArmCommand(mode="velocity", values=[0.0], controller="probe")
        _heard(lambda: controller.put_raw(keys.arm_command(ROBOT), messages.encode(probe)),
               lambda: seen_by_driver.where(keys.arm_command(ROBOT), controller="probe"), "the controller")

        # Moves nothing: commands, cmd_vel, estop, a controller's token, an RPC.
        anonymous.put_raw(keys.arm_command(ROBOT), messages.encode(
            ArmCommand(mode="velocity", values=[9.0], controller="anonymous")))
        anonymous.put_raw(keys.base_cmd_vel(ROBOT), messages.encode(Twist(vx=9.0, wz=0.0)))
        anonymous.latch(keys.estop(ROBOT), EStop(engaged=False, reason="anonymous release"))
        anonymous.announce(keys.controller_alive(ROBOT, "anonymous"))
        with pytest.raises(NotAllowed, match=r"refuses calling rb/acl-bot/cart/rpc/stop to 'anonymous' "
                                             r"\(reader, .*only an operator may"):
            anonymous.call(keys.cart_rpc(ROBOT, "stop"), timeout=1.0)

        # The permitted ones, after them, on the same ways.
        controller.put_raw(keys.arm_command(ROBOT), messages.encode(
            ArmCommand(mode="velocity", values=[1.0], controller="kin")))
        controller.put_raw(keys.base_cmd_vel(ROBOT), messages.encode(Twist(vx=1.0, wz=0.0)))
        operator.latch(keys.estop(ROBOT), EStop(engaged=True, reason="operator stop"))
        controller.announce(keys.controller_alive(ROBOT, "kin"))
        assert operator.call(keys.cart_rpc(ROBOT, "stop"), {"who": "operator"}, timeout=5.0)["ok"]
        wait_until(lambda: seen_by_driver.where(keys.arm_command(ROBOT), controller="kin")
                   and seen_by_driver.where(keys.base_cmd_vel(ROBOT), vx=1.0)
                   and seen_by_driver.where(keys.estop(ROBOT), reason="operator stop"),
                   timeout=10.0, message="the permitted command, cmd_vel or estop did not arrive")
        wait_until(lambda: keys.controller_alive(ROBOT, "kin") in driver.alive(keys.controllers_alive(ROBOT)),
                   timeout=10.0, message="the controller's token never appeared")

        assert seen_by_driver.where(keys.arm_command(ROBOT), controller="anonymous") == []
        assert seen_by_driver.where(keys.base_cmd_vel(ROBOT), vx=9.0) == []
        assert seen_by_driver.where(keys.estop(ROBOT), reason="anonymous release") == []
        assert driver.alive(keys.controllers_alive(ROBOT)) == [keys.controller_alive(ROBOT, "kin")]
        assert stop_calls == [{"who": "operator"}]
        # A late joiner asking for the latched estop hears only the operator's.
        late = Inbox()
        driver.subscribe(keys.estop(ROBOT), EStop, lambda m: late("", messages.encode(m), 0), latest=True)
        wait_until(lambda: late.items, timeout=10.0, message="no latched estop answered")
        assert [m["reason"] for _, m in late.items] == ["operator stop"]


def test_each_role_publishes_only_its_own_keys(secured):
    endpoint, _ = secured
    with _open("sim", endpoint) as driver, _open("nav", endpoint) as controller, \
            _open("asterics_bridge", endpoint) as operator, _open("status", endpoint) as watcher:
        seen = Inbox()
        watcher.subscribe_raw(f"{keys.robot(ROBOT)}/**", seen)
        odom, cmd_vel = keys.base_odom(ROBOT), keys.base_cmd_vel(ROBOT)
        _heard(lambda: driver.put_raw(odom, messages.encode(
                   messages.Odometry(x=0.0, y=0.0, theta=0.0, vx=0.0, wz=0.0))),
               lambda: seen.where(odom, x=0.0), "the driver")
        _heard(lambda: controller.put_raw(cmd_vel, messages.encode(Twist(vx=0.0, wz=0.0))),
               lambda: seen.where(cmd_vel, vx=0.0), "the controller")
        _heard(lambda: operator.put_raw(keys.estop(ROBOT), messages.encode(EStop(engaged=True, reason="probe"))),
               lambda: seen.where(keys.estop(ROBOT), reason="probe"), "the operator")
        # Refused: a controller or an operator faking state, a driver commanding, a controller's estop.
        controller.put_raw(odom, messages.encode(messages.Odometry(x=7.0, y=0.0, theta=0.0, vx=0.0, wz=0.0)))
        operator.put_raw(odom, messages.encode(messages.Odometry(x=8.0, y=0.0, theta=0.0, vx=0.0, wz=0.0)))
        driver.put_raw(cmd_vel, messages.encode(Twist(vx=7.0, wz=0.0)))
        operator.put_raw(cmd_vel, messages.encode(Twist(vx=8.0, wz=0.0)))
        controller.put_raw(keys.estop(ROBOT), messages.encode(EStop(engaged=False, reason="controller")))
        # Permitted: the driver's state, the controller's command, the operator's estop.
        driver.put_raw(odom, messages.encode(messages.Odometry(x=1.0, y=0.0, theta=0.0, vx=0.0, wz=0.0)))
        controller.put_raw(cmd_vel, messages.encode(Twist(vx=1.0, wz=0.0)))
        operator.put_raw(keys.estop(ROBOT), messages.encode(EStop(engaged=True, reason="operator")))
        wait_until(lambda: seen.where(odom, x=1.0) and seen.where(cmd_vel, vx=1.0)
                   and seen.where(keys.estop(ROBOT), reason="operator"),
                   timeout=10.0, message="a permitted state, command or estop did not arrive")
        assert {m["x"] for m in seen.where(odom)} == {0.0, 1.0}
        assert {m["vx"] for m in seen.where(cmd_vel)} == {0.0, 1.0}
        assert {m["reason"] for m in seen.where(keys.estop(ROBOT))} == {"probe", "operator"}


def test_an_open_router_is_unchanged(router, monkeypatch):
    """Without ASIBOT_ACCESS nothing logs in, so sim and emulated on loopback work as before."""
    monkeypatch.delenv(access.ACCESS_ENV, raising=False)
    with Bus("recorder", router, wait=5.0) as anyone:
        seen = Inbox()
        anyone.subscribe_raw(keys.arm_command(ROBOT), seen)
        wait_until(lambda: anyone.put_raw(keys.arm_command(ROBOT), messages.encode(
            ArmCommand(mode="velocity", values=[1.0], controller="any"))) or seen.items,
            timeout=10.0, interval=0.1, message="an open router did not deliver")


def _cli(*argv: str, env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "asibot.cli.main", *argv], capture_output=True, text=True,
                          timeout=60, env=env)


def test_only_an_operator_releases_the_estop_and_the_release_says_who(secured):
    endpoint, folder = secured
    with _open("arm_driver", endpoint) as driver:
        held: list[EStop] = []
        driver.subscribe(keys.estop(ROBOT), EStop, held.append, latest=True)
        driver.serve(keys.driver_rpc(ROBOT, "status"),
                     lambda req: {"estop": bool(held) and held[-1].engaged})
        driver.announce(keys.driver_alive(ROBOT))
        env = dict(os.environ, ASIBOT_ROUTER=endpoint, ASIBOT_ACCESS=str(folder))
        assert _cli("estop", ROBOT, env=env).returncode == 0
        wait_until(lambda: held and held[-1].engaged, timeout=10.0, message="the estop never arrived")

        refused = _cli("release", ROBOT, env=dict(env, ASIBOT_ROLE="reader"))
        assert refused.returncode == 1
        assert "refuses publishing rb/acl-bot/estop to 'anonymous' (reader" in refused.stderr
        released = _cli("release", ROBOT, env=env)
        assert released.returncode == 0, released.stderr
        assert not held[-1].engaged and held[-1].by.endswith(" as operator")
        assert f"released by {held[-1].by}" in released.stdout
        # The anonymous release, sent first, never reached the driver.
        assert [m.engaged for m in held] == [True, False]


def test_a_refusal_is_said_where_the_router_would_drop_it_silently(secured, caplog):
    """A refused call fails at once with who may, not "nobody answers"; a refused publisher
    says so once in the log; each role's own keys are never called refused."""
    endpoint, _ = secured
    with _open("recorder", endpoint) as reader, _open("nav", endpoint) as controller:
        with pytest.raises(NotAllowed, match="only an operator may: run it with ASIBOT_ROLE=operator"):
            reader.call(keys.nav_rpc(ROBOT, "goto_place"), {"place": "fridge"}, timeout=5.0)
        with caplog.at_level("WARNING", logger="asibot.bus"):
            for _ in range(3):
                controller.put_raw(keys.base_odom(ROBOT), b"\x80")
        said = [r.getMessage() for r in caplog.records if "refuses publishing" in r.getMessage()]
        assert said == [f"The router's access control refuses publishing {keys.base_odom(ROBOT)} to "
                        f"'controller' (controller, from ASIBOT_ACCESS={access.default_folder()}); only a "
                        f"driver may: run it with ASIBOT_ROLE=driver and "
                        f"{access.default_folder() / 'driver.credentials'} in place."]
        assert controller.refusal("put", keys.base_cmd_vel(ROBOT)) is None
        assert controller.refusal("query", keys.driver_rpc(ROBOT, "status")) is None


def test_replay_under_access_control_refuses_with_a_sentence(secured):
    """`asibot replay` logs in as a reader: the router would drop all it publishes."""
    endpoint, folder = secured
    env = dict(os.environ, ASIBOT_ROUTER=endpoint, ASIBOT_ACCESS=str(folder))
    env.pop(access.ROLE_ENV, None)
    fixture = Path(__file__).resolve().parents[2] / "recordings" / "fixtures" / "nav_drive.mcap"
    done = _cli("replay", str(fixture), "--fast", env=env)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "Not replaying: The router's access control refuses publishing rb/" in done.stderr
    assert "to 'anonymous' (reader" in done.stderr and "asibot up --no-access" in done.stderr


@pytest.mark.slow
def test_asibot_up_with_access_makes_the_logins_and_admits_only_them(tmp_path):
    """`asibot up --access`: the credentials are made on first use, the services log in
    with them, `asibot status` works with the folder and says what to do without it."""
    shutil.copy(COMPOSE, tmp_path / "compose.yaml")
    folder = tmp_path / "logins"
    env = dict(os.environ, ASIBOT_ROUTER=f"tcp/127.0.0.1:{free_port()}", ASIBOT_ACCESS=str(folder),
               ASIBOT_RECORDINGS=str(tmp_path / "recordings"))
    env.pop(access.ROLE_ENV, None)
    tls = free_port()
    up = subprocess.Popen([sys.executable, "-m", "asibot.cli.main", "up", "--access", "--only", "recorder",
                           "--tls", f"127.0.0.1:{tls}"],
                          cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(up.stdout), daemon=True).start()
    try:
        def status() -> str:
            r = _cli("status", env=env)
            return r.stdout if r.returncode == 0 and "recorder" in r.stdout and "router" in r.stdout else ""
        wait_until(status, 30, interval=0.3, message="asibot status never listed the router and the recorder")
        assert stat.S_IMODE(folder.stat().st_mode) == 0o700
        anonymous = _cli("status", "--wait", "1", env={k: v for k, v in env.items() if k != access.ACCESS_ENV})
        assert anonymous.returncode == 1 and "set ASIBOT_ACCESS to its credentials folder" in anonymous.stderr
        # Another machine comes in over TLS with the folder's ca.pem (test_router_tls).
        remote = _cli("status", env=dict(env, ASIBOT_ROUTER=f"tls/127.0.0.1:{tls}"))
        assert remote.returncode == 0 and "recorder" in remote.stdout, remote.stderr
    finally:
        up.send_signal(signal.SIGINT)
        assert up.wait(15) == 130   # Ctrl-C: the shell's 128 + SIGINT
    assert f"access control on: logins in {folder}" in "".join(lines)
    assert f"other machines: ASIBOT_ROUTER=tls/<this machine>:{tls}" in "".join(lines)
    open_router_for_all = _cli("up", "--no-access", "--tls", "0.0.0.0:7448", env=env)
    assert open_router_for_all.returncode == 2 and "it needs access control" in open_router_for_all.stderr
