"""`asibot doctor`: each check finds what a robot's machine can get wrong and says what to do.

The CAN and USB cases are shown on a sysfs tree of the kernel's layout in a temporary folder
and `ip`'s JSON as iproute2 prints it (this machine has no CAN adapter or depth camera); the
serial, TCP, sound, disk and command-line cases run on this machine as they are.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from asibot.cli import doctor
from asibot.cli.doctor import FAIL, OK, WARN, Machine

ROOT = Path(__file__).resolve().parents[2]
BITRATE = 1_000_000


def ip_link(state: str = "ERROR-ACTIVE", bitrate: int = BITRATE, up: bool = True, restart_ms: int = 100) -> str:
    """`ip -details -json link show can0` of a PEAK PCAN-USB, as iproute2 6.x prints it."""
    flags = ["NOARP", "UP", "LOWER_UP", "ECHO"] if up else ["NOARP", "ECHO"]
    return json.dumps([{
        "ifindex": 5, "ifname": "can0", "flags": flags, "mtu": 16, "qdisc": "pfifo_fast",
        "operstate": "UP" if up else "DOWN", "linkmode": "DEFAULT", "group": "default", "txqlen": 10,
        "link_type": "can", "promiscuity": 0, "min_mtu": 0, "max_mtu": 0,
        "linkinfo": {"info_kind": "can", "info_data": {
            "ctrlmode": [], "state": state, "berr_counter": {"tx": 0, "rx": 0}, "restart_ms": restart_ms,
            "bittiming": {"bitrate": bitrate, "sample_point": "0.875", "tq": 125, "prop_seg": 3,
                          "phase_seg1": 3, "phase_seg2": 1, "sjw": 1, "brp": 10},
            "clock": 80000000}},
        "num_tx_queues": 1, "num_rx_queues": 1, "gso_max_size": 65536, "gso_max_segs": 65535,
    }])


def machine(tmp_path: Path, env: dict[str, str], ip: str | None = None, net_type: str | None = "280",
            usb: tuple[str, ...] = ()) -> Machine:
    sys_root = tmp_path / "sys"
    if net_type is not None:
        (sys_root / "class" / "net" / "can0").mkdir(parents=True)
        (sys_root / "class" / "net" / "can0" / "type").write_text(net_type + "\n")
    for i, vendor in enumerate(usb):
        dev = sys_root / "bus" / "usb" / "devices" / f"2-{i + 1}"
        dev.mkdir(parents=True)
        (dev / "idVendor").write_text(vendor + "\n")

    def run_ip(args: list[str]) -> str:
        assert args == ["-details", "-json", "link", "show", "can0"]
        if ip is None:
            raise subprocess.CalledProcessError(1, ["ip", *args])
        return ip
    return Machine(sys=sys_root, env=env, ip=run_ip)


CAN = {"ASIBOT_ARM_CAN": "socketcan:can0"}


@pytest.mark.parametrize("env, kwargs, status, says, fix", [
    ({}, {}, FAIL, "$ASIBOT_ARM_CAN is not set", "export ASIBOT_ARM_CAN=socketcan:can0"),
    ({"ASIBOT_ARM_CAN": "emulated"}, {}, OK, "no hardware to check", ""),
    ({"ASIBOT_ARM_CAN": "pcan:PCAN_USBBUS1"}, {}, WARN, "only SocketCAN", "the arm driver says at start"),
    (CAN, {"net_type": None}, FAIL, "no network interface can0", "sudo modprobe peak_usb"),
    (CAN, {"net_type": "1"}, FAIL, "can0 is not a CAN interface", "ip -details link"),
    (CAN, {"ip": ip_link(up=False)}, FAIL, "can0 is down", "sudo ip link set can0 up type can bitrate 1000000"),
    (CAN, {"ip": ip_link(bitrate=500_000)}, FAIL, "runs at 500000 bit/s; the arm's drives at 1000000",
     "sudo ip link set can0 down"),
    (CAN, {"ip": ip_link(state="ERROR-PASSIVE")}, FAIL, "its controller is ERROR-PASSIVE", "60 ohm between CAN-H and CAN-L"),
    (CAN, {"ip": ip_link(state="BUS-OFF")}, FAIL, "its controller is BUS-OFF", "120 ohm terminator"),
    (CAN, {"ip": ip_link(restart_ms=0)}, WARN, "stays off the bus after a bus-off", "restart-ms 100"),
    (CAN, {"ip": ip_link()}, OK, "can0 is up at 1000000 bit/s, ERROR-ACTIVE, restarts 100 ms after a bus-off", ""),
    ({"ASIBOT_ARM_CAN": "socketcan:can0,fd=false"}, {"ip": ip_link()}, OK, "can0 is up", ""),
], ids=["unset", "emulated", "pcan", "no-interface", "not-can", "down", "bitrate", "error-passive", "bus-off",
        "no-restart", "healthy", "options"])
def test_the_arm_can_bus_check_says_what_is_wrong_and_how_to_fix_it(tmp_path, env, kwargs, status, says, fix):
    found = doctor.can_bus(machine(tmp_path, env, **kwargs), BITRATE)
    assert (found.status, says in found.says, fix in found.fix) == (status, True, True), found


def test_a_failing_ip_command_is_named(tmp_path):
    found = doctor.can_bus(machine(tmp_path, CAN, ip=None), BITRATE)
    assert found.status == FAIL and "ip -details link show can0" in found.says and "iproute2" in found.fix


def test_a_serial_line_this_user_may_not_open_names_the_group_to_join(tmp_path):
    device = tmp_path / "ttyUSB0"
    device.write_text("")
    m = Machine(env={"ASIBOT_PIONEER_PORT": str(device)}, may_open=lambda path: False)
    found = doctor.serial_line(m, "Pioneer serial line", "ASIBOT_PIONEER_PORT", "/dev/ttyUSB0")
    group = doctor._group_of(device)
    assert found.status == FAIL and f"belongs to group {group}" in found.says
    assert found.fix == f"sudo usermod -aG {group} $USER, then log out and in again"


def test_serial_lines_on_this_machine(tmp_path):
    def check(url: str | None):
        env = {} if url is None else {"ASIBOT_PIONEER_PORT": url}
        return doctor.serial_line(Machine(env=env), "Pioneer serial line", "ASIBOT_PIONEER_PORT", "/dev/ttyUSB0")
    assert check(None).status == FAIL and check(None).fix.startswith("export ASIBOT_PIONEER_PORT=/dev/ttyUSB0")
    missing = check(str(tmp_path / "ttyUSB9"))
    assert missing.status == FAIL and "/dev/serial/by-id/" in missing.fix
    device = tmp_path / "ttyUSB0"
    device.write_text("")
    assert check(str(device)).status == OK
    with socket.create_server(("127.0.0.1", 0)) as bridge:           # a serial-to-TCP bridge that answers
        port = bridge.getsockname()[1]
        assert check(f"socket://127.0.0.1:{port}").status == OK
    silent = check(f"socket://127.0.0.1:{port}")                      # closed now
    assert silent.status == FAIL and "nothing answers" in silent.says


def test_the_katana_is_optional_and_its_line_checked_when_named(tmp_path):
    assert doctor.katana_line(Machine(env={"ASIBOT_KATANA_PORT": ""})).status == WARN
    device = tmp_path / "ttyUSB1"
    device.write_text("")
    assert doctor.katana_line(Machine(env={"ASIBOT_KATANA_PORT": str(device)})).status == OK
    missing = doctor.katana_line(Machine(env={"ASIBOT_KATANA_PORT": str(tmp_path / "gone")}))
    assert missing.status == FAIL and missing.check == "Katana serial line"


def test_depth_cameras_are_found_by_their_usb_vendor(tmp_path):
    assert doctor.depth_camera(machine(tmp_path / "a", {}, usb=("1d6b",))).status == WARN   # a root hub only
    found = doctor.depth_camera(machine(tmp_path / "b", {}, usb=("1d6b", "8086", "2bc5")))
    assert found.status == OK and found.says == "on USB: Intel RealSense, Orbbec Astra"


def test_spoken_feedback_needs_espeak_ng():
    assert doctor.spoken_feedback(Machine(which=lambda name: None)).fix == "sudo apt-get install espeak-ng"
    assert doctor.spoken_feedback(Machine()).status == (OK if shutil.which("espeak-ng") else FAIL)


def test_the_recordings_folder_is_writable_with_room(tmp_path):
    found = doctor.recordings(tmp_path / "recordings")
    assert found.status in (OK, WARN) and str(tmp_path / "recordings") in found.says
    assert doctor.recordings(tmp_path).status != FAIL


def test_the_real_profiles_settings_come_from_compose_with_its_defaults(monkeypatch):
    monkeypatch.delenv("ASIBOT_ARM_CAN", raising=False)
    monkeypatch.delenv("ASIBOT_PIONEER_PORT", raising=False)
    env = doctor.settings("real", ROOT / "compose.yaml")
    assert env["ASIBOT_ARM_CAN"] == "socketcan:can0" and env["ASIBOT_PIONEER_PORT"] == "/dev/ttyUSB0"
    monkeypatch.setenv("ASIBOT_ARM_CAN", "pcan:PCAN_USBBUS1")
    assert doctor.settings("real", ROOT / "compose.yaml")["ASIBOT_ARM_CAN"] == "pcan:PCAN_USBBUS1"


def _doctor(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "asibot.cli.main", "doctor", *args], capture_output=True, text=True,
                          cwd=ROOT, env={**os.environ, **(env or {})}, timeout=60)


def test_the_command_passes_the_emulated_profile_here():
    done = _doctor("--profile", "emulated")
    assert done.returncode == (0 if shutil.which("espeak-ng") else 1), done.stdout + done.stderr
    assert "spoken feedback" in done.stdout and "recordings" in done.stdout


def test_the_command_fails_on_a_machine_without_the_robots_and_says_so_in_json():
    with socket.create_server(("127.0.0.1", 0)) as bridge:
        done = _doctor("--json", env={"ASIBOT_ARM_CAN": "socketcan:nocan7",
                                      "ASIBOT_PIONEER_PORT": f"socket://127.0.0.1:{bridge.getsockname()[1]}"})
    assert done.returncode == 1, done.stderr
    found = {f["check"]: f for f in json.loads(done.stdout)}
    assert found["arm CAN bus"]["status"] == FAIL and found["arm CAN bus"]["says"] == "no network interface nocan7"
    assert found["Pioneer serial line"]["status"] == OK
    assert found["arm zero"]["status"] == "by hand" and "zero marks" in found["arm zero"]["fix"]
