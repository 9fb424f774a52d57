"""The `asibot` command line as people expect it (issue 28, point 7), without a router: its
version, negative numbers as values, degrees for every angle a person types or reads, one
recordings folder, and `status --json` with the restart counts `asibot up` reports."""

import importlib.metadata
import json
import math
import subprocess
import sys
import threading
import types
from pathlib import Path

import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.cli.compose import ServiceSpec
from asibot.cli.launcher import Supervisor
from asibot.cli.main import main as asibot

ROBOT = "cli-base"


def run(*argv: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "asibot.cli.main", *argv], capture_output=True, text=True,
                          timeout=60, cwd=cwd)


class FakeNav:
    """The nav service as the command line sees it: it records what it was asked, in the bus's units."""

    def __init__(self) -> None:
        self.requests: list[tuple[str, dict]] = []
        self.bus = Bus("nav")
        answers = {
            "status": {"state": "idle", "text": "idle", "pose": [1.0, 2.0, math.pi]},
            "goto": {"goal_id": 7, "place": "", "goal": [], "text": "on my way"},
            "turn": {"text": "turn right: started"},
            "places": {"places": [{"name": "fridge", "pose": [1.0, 2.0, math.pi / 2]}]},
            "save_place": {"name": "sofa", "pose": [0.5, -1.0, -math.pi / 4]},
        }
        for verb, answer in answers.items():
            self.bus.serve(keys.nav_rpc(ROBOT, verb), self._answer(verb, answer))

    def _answer(self, verb: str, answer: dict):
        def handler(request: dict) -> dict:
            self.requests.append((verb, request))
            return answer
        return handler

    def asked(self, verb: str) -> dict:
        return next(r for v, r in self.requests if v == verb)


@pytest.fixture
def nav(memory_bus):
    fake = FakeNav()
    yield fake
    fake.bus.close()


def test_version_is_the_installed_distribution():
    r = run("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == f"asibot {importlib.metadata.version('asibot-cli')}"


def test_negative_numbers_are_values_not_options(nav, capsys):
    assert asibot(["nav", "--robot", ROBOT, "goto", "-1,-2.5,0", "--no-wait"]) == 0
    assert nav.asked("goto")["pose"] == [-1.0, -2.5, 0.0]
    assert asibot(["nav", "--robot", ROBOT, "turn", "-90", "--no-wait"]) == 0
    assert nav.asked("turn")["angle"] == -90.0   # turn's contract is in degrees already
    assert "goal 7 started" in capsys.readouterr().out


def test_bad_numbers_are_one_sentence_and_exit_2():
    r = run("nav", "goto", "-1,2")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.splitlines()[-1] == ("asibot nav goto: error: argument target: give a place's name "
                                         "or x,y,theta (m, m, degrees) such as 1.5,-2,90, not '-1,2'")
    r = run("nav", "turn", "ninety")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.splitlines()[-1] == "asibot nav turn: error: argument amount: invalid float value: 'ninety'"


def test_angles_are_degrees_for_people_and_radians_on_the_bus(nav, capsys):
    assert asibot(["nav", "--robot", ROBOT, "goto", "1,2,90", "--no-wait"]) == 0
    assert nav.asked("goto")["pose"] == pytest.approx([1.0, 2.0, math.pi / 2])
    capsys.readouterr()
    assert asibot(["nav", "--robot", ROBOT, "places"]) == 0
    assert asibot(["nav", "--robot", ROBOT, "status"]) == 0
    assert asibot(["nav", "--robot", ROBOT, "save-place", "sofa"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("fridge") and out[0].endswith("theta   90 degrees"), out
    assert out[1] == f"{ROBOT}: idle: idle at (1.00, 2.00, 180 degrees)"
    assert out[2] == f"{ROBOT}: saved 'sofa' at (0.50, -1.00, -45 degrees)"


def test_help_says_degrees():
    for verb in ("goto", "turn"):
        text = run("nav", verb, "--help").stdout
        assert "degrees" in text and "rad" not in text.replace("radians", ""), text


def test_one_recordings_folder_from_anywhere_in_the_checkout(tmp_path, monkeypatch, capsys):
    """`asibot up` writes <checkout>/recordings; `asibot recordings` reads it from a subfolder too."""
    monkeypatch.delenv("ASIBOT_RECORDINGS", raising=False)
    monkeypatch.delenv("ASIBOT_COMPOSE", raising=False)
    (tmp_path / "compose.yaml").write_text("services: {}\n")
    (tmp_path / "recordings").mkdir()
    (tmp_path / "recordings" / "session-1.mcap").write_bytes(b"not yet")
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path / "sub")
    assert asibot(["recordings"]) == 0
    assert "session-1.mcap" in capsys.readouterr().out
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "session-2.mcap").write_bytes(b"not yet")
    monkeypatch.setenv("ASIBOT_RECORDINGS", str(elsewhere))   # the override, for every command
    assert asibot(["recordings"]) == 0
    out = capsys.readouterr().out
    assert "session-2.mcap" in out and "session-1.mcap" not in out


def test_status_json_gives_each_service_its_restart_count(memory_bus, capsys):
    """`asibot up`'s report (BusReport) joined to the services that report their health."""
    from asibot.cli.launcher import BusReport   # here: each test of this file fails on its own
    spec = ServiceSpec(name="nav-cli-base", command=["python"], environment={}, profiles=[],
                       restart="always", depends_on=[])
    sup = Supervisor([spec], memory_bus)
    child = sup.children[0]
    child.restarts, child.proc = 3, types.SimpleNamespace(pid=4242, returncode=None)  # as after 3 crashes
    report = BusReport(sup, memory_bus)
    service = Bus("nav")
    service.announce(keys.service("nav", ROBOT))
    health = service.publisher(keys.health("nav", ROBOT), m.Health)
    done = threading.Event()

    def report_health() -> None:
        while not done.wait(0.3):
            health.put(m.Health(service="nav", instance=ROBOT, uptime=5.0, pid=4242))

    threading.Thread(target=report_health, daemon=True).start()
    try:
        assert asibot(["status", "--json"]) == 0
    finally:
        done.set()
        report.close()
        service.close()
    status = json.loads(capsys.readouterr().out)
    nav = next(s for s in status["services"] if s["service"] == "nav")
    assert nav["instance"] == ROBOT and nav["pid"] == 4242
    assert nav["restarts"] == 3 and nav["launched_as"] == "nav-cli-base"
    assert status["launched"] == [{"name": "nav-cli-base", "pid": 4242, "restarts": 3, "running": True}]
    assert any(s["service"] == "launcher" for s in status["services"])


def test_nav_names_the_robot_that_is_there_when_the_default_is_not(memory_bus, monkeypatch, capsys):
    """The emulated profile runs `pioneer`, not the default `pioneer-sim`: the refusal names it."""
    monkeypatch.delenv("ASIBOT_ROBOT", raising=False)
    with Bus("nav") as there:
        there.announce(keys.service("nav", "pioneer"))
        assert asibot(["nav", "goto", "fridge"]) == 2
    said = capsys.readouterr().err.strip()
    assert said == ("asibot nav: No nav service answers for 'pioneer-sim' (the default robot); nav runs for "
                    "'pioneer': `asibot nav --robot pioneer goto ...`, or set ASIBOT_ROBOT."), said


def test_up_says_what_each_profile_runs():
    r = run("up", "--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    for profile in ("sim", "emulated", "real"):
        assert f"{profile}:" in text, text
