"""`asibot up` and compose.yaml: the launcher starts, restarts and stops; compose agrees."""

import io
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest
import yaml

from asibot.cli import compose
from asibot.cli.launcher import Supervisor
from asibot.testing import free_port, wait_until

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = ROOT / "compose.yaml"


#: Compose v2, which implements the Compose specification: the Docker CLI's plugin.
DOCKER_COMPOSE = ["docker", "compose", "-f", str(COMPOSE)]


def test_compose_is_compose_v2_and_valid_for_every_profile():
    assert shutil.which("docker"), "install Docker's client: ./bootstrap does (Debian's docker.io)"
    version = subprocess.run([*DOCKER_COMPOSE, "version", "--short"], capture_output=True, text=True)
    assert version.returncode == 0 and version.stdout.startswith("2."), \
        f"`docker compose` is not Compose v2 ({version.stdout}{version.stderr}): ./bootstrap installs it"
    for profile in compose.PROFILES:
        subprocess.run([*DOCKER_COMPOSE, "--profile", profile, "config", "-q"], check=True)


@pytest.mark.parametrize("profile", compose.PROFILES)
def test_launcher_and_compose_agree(profile):
    out = subprocess.run([*DOCKER_COMPOSE, "--profile", profile, "config"],
                         check=True, capture_output=True, text=True).stdout
    resolved = yaml.safe_load(out)["services"]
    ours = {s.name: s for s in compose.select(compose.load(COMPOSE), profile)}
    assert set(ours) == set(resolved)
    for name, spec in ours.items():
        assert spec.command == resolved[name]["command"], name
        env = {k: str(v) for k, v in (resolved[name].get("environment") or {}).items()}
        assert spec.environment == env, name


def test_variables_are_substituted_like_docker_compose(monkeypatch):
    monkeypatch.setenv("ASIBOT_ARM_CAN", "pcan:PCAN_USBBUS1")
    monkeypatch.delenv("ASIBOT_PIONEER_PORT", raising=False)
    out = subprocess.run([*DOCKER_COMPOSE, "--profile", "real", "config"],
                         check=True, capture_output=True, text=True).stdout
    resolved = yaml.safe_load(out)["services"]
    ours = compose.load(COMPOSE)
    for name in ("arm-driver", "base-driver"):
        env = {k: str(v) for k, v in resolved[name]["environment"].items()}
        assert ours[name].environment == env
    assert ours["arm-driver"].environment["ASIBOT_ARM_CAN"] == "pcan:PCAN_USBBUS1"
    assert ours["base-driver"].environment["ASIBOT_PIONEER_PORT"] == "/dev/ttyUSB0"  # the default


def test_variable_syntax():
    env = {"SET": "x", "EMPTY": ""}
    assert compose.interpolate("${SET} ${NO:-d} ${EMPTY:-d} ${EMPTY-d} $$SET $SET", env) == "x d d  $SET x"
    with pytest.raises(compose.ComposeError, match="say which bus"):
        compose.interpolate("${NO:?say which bus}", env)


def test_compose_errors_are_sentences():
    with pytest.raises(compose.ComposeError, match="needs a command"):
        compose.parse("services: {a: {image: x}}")
    with pytest.raises(compose.ComposeError, match="unknown profile"):
        compose.parse("services: {a: {command: x, profiles: [moon]}}")
    with pytest.raises(compose.ComposeError, match="depends on unknown"):
        compose.parse("services: {a: {command: x, depends_on: [b]}}")
    with pytest.raises(compose.ComposeError, match="no service named"):
        compose.select(compose.parse("services: {a: {command: x}}"), "sim", ["zz"])


def test_only_keeps_dependencies_and_order():
    services = compose.parse(textwrap.dedent("""
        services:
          web: {command: w, depends_on: [kin], profiles: [sim]}
          router: {command: r}
          kin: {command: k, depends_on: [router], profiles: [sim]}
          drv: {command: d, profiles: [real]}
    """))
    assert [s.name for s in compose.select(services, "sim", ["web"])] == ["router", "kin", "web"]
    assert [s.name for s in compose.select(services, "real")] == ["router", "drv"]


def write_compose(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "compose.yaml"
    path.write_text(textwrap.dedent(body))
    return path


@pytest.mark.slow
def test_supervisor_restarts_with_backoff_and_stops_everything(tmp_path):
    marker = tmp_path / "runs"
    path = write_compose(tmp_path, f"""
        services:
          flaky:
            command: ["python", "-c", "open(r'{marker}', 'a').write('x'); print('flaky run'); raise SystemExit(3)"]
            restart: on-failure
          once:
            command: ["python", "-c", "print('done once')"]
            restart: on-failure
          steady:
            command: ["python", "-c", "import time; print('steady up', flush=True); time.sleep(60)"]
            restart: always
    """)
    out = io.StringIO()
    sup = Supervisor(compose.select(compose.load(path), "sim"), "tcp/127.0.0.1:1", root=tmp_path, out=out, color=False)
    stop = threading.Event()
    t = threading.Thread(target=sup.run, args=(stop,))
    t.start()
    # backoff 0.5 + 1.0 + 2.0 s: four runs within ~4 s, not a tight loop
    wait_until(lambda: marker.exists() and len(marker.read_text()) >= 4, 8)
    time.sleep(0.2)
    assert len(marker.read_text()) <= 5
    steady_pid = sup.pids()["steady"]
    stop.set()
    t.join(10)
    text = out.getvalue()
    assert "flaky  | flaky run" in text
    assert "once   | done once" in text
    assert "once exited with code 0 (restart: on-failure)" in text
    assert "flaky exited with code 3; restarting in 1.0 s" in text
    with pytest.raises(ProcessLookupError):
        os.kill(steady_pid, 0)


@pytest.mark.slow
def test_asibot_up_status_and_ctrl_c(tmp_path):
    """The user's path: `asibot up`, `asibot status` lists router and recorder, Ctrl-C, a recording
    in the folder ASIBOT_RECORDINGS names (which `asibot recordings` lists too)."""
    shutil.copy(COMPOSE, tmp_path / "compose.yaml")
    elsewhere = tmp_path / "elsewhere"
    env = dict(os.environ, ASIBOT_ROUTER=f"tcp/127.0.0.1:{free_port()}", ASIBOT_RECORDINGS=str(elsewhere))
    up = subprocess.Popen([sys.executable, "-m", "asibot.cli.main", "up", "--only", "recorder"],
                          cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(up.stdout), daemon=True).start()
    try:
        def status() -> str:
            r = subprocess.run([sys.executable, "-m", "asibot.cli.main", "status"], env=env,
                               capture_output=True, text=True)
            return r.stdout if r.returncode == 0 and "recorder" in r.stdout else ""
        out = wait_until(status, 20, interval=0.3)
        assert "router" in out and "recorder" in out
        time.sleep(1.2)
    finally:
        up.send_signal(signal.SIGINT)
        assert up.wait(10) == 130   # Ctrl-C: the shell's 128 + SIGINT
    text = "".join(lines)
    assert "recorder | " in text and "asibot   | stopped" in text and f"recordings in {elsewhere}" in text
    recordings = list(elsewhere.glob("*.mcap"))
    assert len(recordings) == 1 and not (tmp_path / "recordings").exists()
    listing = subprocess.run([sys.executable, "-m", "asibot.cli.main", "recordings"], cwd=tmp_path,
                             capture_output=True, text=True, env=env).stdout
    assert recordings[0].name in listing


def test_up_refuses_a_second_instance_on_the_same_port(router, tmp_path):
    r = subprocess.run([sys.executable, "-m", "asibot.cli.main", "up", "--file", str(COMPOSE)],
                       capture_output=True, text=True, timeout=20)
    assert r.returncode == 1 and "already listens" in r.stderr


def test_up_with_an_unknown_service_is_a_sentence():
    r = subprocess.run([sys.executable, "-m", "asibot.cli.main", "up", "--file", str(COMPOSE), "--only", "nope"],
                       capture_output=True, text=True, timeout=20,
                       env=dict(os.environ, ASIBOT_ROUTER=f"tcp/127.0.0.1:{free_port()}"))
    assert r.returncode == 2 and "no service named nope" in r.stderr and "Traceback" not in r.stderr
