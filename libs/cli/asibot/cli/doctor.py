"""`asibot doctor`: is this machine ready to drive the real robots? Each check says what it
found and, when something is wrong, what to do about it, in the installer's words.

    asibot doctor                      # the real profile's hardware (the default)
    asibot doctor --profile emulated   # what the emulated profile needs (no hardware)
    asibot doctor --json               # the same findings for a script

It only looks: it opens no port a driver may be using, sends no frame and moves nothing, so it
can run beside a live stack. The exit status is 1 when a check failed, else 0. What no program
can see (the arm's q1 and q5 on their zero marks before power-on, the CAN terminations' 120 ohm)
is listed as a step to do by hand, with how to do it (docs/hardware.md).
"""

from __future__ import annotations

import argparse
import grp
import json
import os
import shutil
import socket
import subprocess
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterable

from asibot.cli import compose

OK, WARN, FAIL, BY_HAND = "ok", "warn", "FAIL", "by hand"
#: ARPHRD_CAN in include/uapi/linux/if_arp.h: what /sys/class/net/IF/type says of a CAN interface.
ARPHRD_CAN = 280
#: SocketCAN's controller states (iproute2 `ip -details link`): only this one means a healthy bus.
CAN_HEALTHY = "ERROR-ACTIVE"
#: USB vendor ids of the depth cameras perception can read (docs/hardware.md, "Depth camera").
DEPTH_CAMERA_VENDORS = {"8086": "Intel RealSense", "045e": "Microsoft Kinect", "1d27": "ASUS Xtion (PrimeSense)",
                        "2bc5": "Orbbec Astra"}
#: Below this free space the recorder fills the disk within a working day (a session records
#: the cameras: about 1 GB an hour).
MIN_FREE_BYTES = 4 * 1024**3
ARM_CAN_ENV, PIONEER_PORT_ENV, KATANA_PORT_ENV = "ASIBOT_ARM_CAN", "ASIBOT_PIONEER_PORT", "ASIBOT_KATANA_PORT"


@dataclass
class Finding:
    check: str
    status: str
    says: str
    fix: str = ""


@dataclass
class Machine:
    """What the checks look at: the kernel's view of devices (sysfs, /dev), the environment and
    `ip`. Its parts can be pointed elsewhere, so each check can be shown every case it knows."""
    sys: Path = Path("/sys")
    env: dict[str, str] = field(default_factory=lambda: dict(os.environ))
    ip: Callable[[list[str]], str] = field(default=lambda args: subprocess.run(
        ["ip", *args], check=True, capture_output=True, text=True, timeout=5).stdout)
    which: Callable[[str], str | None] = shutil.which
    #: Whether this user may open a device for reading and writing (root may open anything).
    may_open: Callable[[Path], bool] = field(default=lambda path: os.access(path, os.R_OK | os.W_OK))


# ---------------------------------------------------------------- the arm's CAN bus
def can_bus(m: Machine, bitrate: int) -> Finding:
    """The arm's CAN interface: there, a CAN interface, up, at the drives' bitrate, and a bus
    without errors (errors on an idle bus mean a missing termination or a node at another rate)."""
    name = m.env.get(ARM_CAN_ENV, "")
    if not name:
        return Finding("arm CAN bus", FAIL, f"${ARM_CAN_ENV} is not set: the arm driver does not know its bus",
                       f"export {ARM_CAN_ENV}=socketcan:can0 (or pcan:PCAN_USBBUS1), see docs/hardware.md")
    interface, _, channel = name.partition(":")
    if interface == "emulated":
        return Finding("arm CAN bus", OK, "emulated drives in the driver's process: no hardware to check")
    if interface != "socketcan":
        return Finding("arm CAN bus", WARN, f"{name}: only SocketCAN interfaces can be looked at from here",
                       "the arm driver says at start whether it can open it; a SocketCAN adapter "
                       "(PEAK's peak_usb, for one) can be checked by this command")
    channel = channel.split(",")[0]
    up = f"sudo ip link set {channel} up type can bitrate {bitrate} restart-ms 100"
    dev = m.sys / "class" / "net" / channel
    if not dev.exists():
        return Finding("arm CAN bus", FAIL, f"no network interface {channel}",
                       "plug the CAN adapter in; `ip link` lists the interfaces; a PEAK PCAN-USB needs the "
                       f"peak_usb module (sudo modprobe peak_usb); then {up}")
    if _read(dev / "type") != str(ARPHRD_CAN):
        return Finding("arm CAN bus", FAIL, f"{channel} is not a CAN interface",
                       f"name the CAN adapter's interface in ${ARM_CAN_ENV} (`ip -details link` shows 'can' ones)")
    try:
        info = json.loads(m.ip(["-details", "-json", "link", "show", channel]))[0]
    except (OSError, subprocess.SubprocessError, ValueError, IndexError) as exc:
        return Finding("arm CAN bus", FAIL, f"`ip -details link show {channel}` failed: {exc}",
                       "install iproute2 (sudo apt-get install iproute2)")
    data = info.get("linkinfo", {}).get("info_data", {})
    if "UP" not in info.get("flags", []):
        return Finding("arm CAN bus", FAIL, f"{channel} is down", up)
    have = data.get("bittiming", {}).get("bitrate")
    if have != bitrate:
        return Finding("arm CAN bus", FAIL, f"{channel} runs at {have} bit/s; the arm's drives at {bitrate}",
                       f"sudo ip link set {channel} down; {up}")
    state = data.get("state", "")
    if state != CAN_HEALTHY:
        return Finding("arm CAN bus", FAIL, f"{channel} is up at {bitrate} bit/s but its controller is {state}: "
                       "frames are not acknowledged or arrive broken",
                       "with the power off, measure about 60 ohm between CAN-H and CAN-L (a 120 ohm terminator at "
                       "each end); check every drive is set to the same bitrate and the cable's pins; "
                       f"then {up}")
    restart = data.get("restart_ms", 0)
    if not restart:
        return Finding("arm CAN bus", WARN, f"{channel} is up at {bitrate} bit/s and healthy, but stays off the "
                       "bus after a bus-off until someone restarts it", up)
    return Finding("arm CAN bus", OK, f"{channel} is up at {bitrate} bit/s, {state}, restarts {restart} ms after a bus-off")


# ---------------------------------------------------------------- serial lines
def serial_line(m: Machine, what: str, env: str, example: str) -> Finding:
    """A serial line named by a pyserial URL: a device this user may open, or a TCP bridge that
    answers."""
    url = m.env.get(env, "")
    if not url:
        return Finding(what, FAIL, f"${env} is not set", f"export {env}={example} (docs/hardware.md)")
    if url.startswith("socket://"):
        host, _, port = url.removeprefix("socket://").partition(":")
        try:
            socket.create_connection((host, int(port)), timeout=2).close()
        except (OSError, ValueError) as exc:
            return Finding(what, FAIL, f"nothing answers at {url}: {exc}",
                           "start the serial-to-TCP bridge (or the emulator) and check its address")
        return Finding(what, OK, f"{url} answers")
    path = Path(url)
    if not path.exists():
        return Finding(what, FAIL, f"no {url}",
                       "plug the USB-serial adapter in; `ls /dev/serial/by-id/` shows what the kernel found; "
                       f"name that path in ${env} (a by-id path survives replugging)")
    if not m.may_open(path):
        group = _group_of(path)
        return Finding(what, FAIL, f"you may not open {url} (it belongs to group {group})",
                       f"sudo usermod -aG {group} $USER, then log out and in again")
    return Finding(what, OK, f"{url} is there and this user may open it")


def katana_line(m: Machine) -> Finding:
    """The Pioneer's Katana, optional: the base driver serves it when its port is named."""
    if not m.env.get(KATANA_PORT_ENV):
        return Finding("Katana serial line", WARN, f"${KATANA_PORT_ENV} is empty: the Pioneer runs without its arm",
                       f"export {KATANA_PORT_ENV}=/dev/serial/by-id/... (the Katana's USB-serial adapter, "
                       "docs/hardware.md)")
    return serial_line(m, "Katana serial line", KATANA_PORT_ENV, "/dev/ttyUSB1")


# ---------------------------------------------------------------- cameras, sound, disk
def depth_camera(m: Machine) -> Finding:
    """A depth camera on USB, by vendor id (perception uses the sonar alone without one)."""
    found = sorted({DEPTH_CAMERA_VENDORS[v] for v in _usb_vendors(m.sys) if v in DEPTH_CAMERA_VENDORS})
    if not found:
        return Finding("depth camera", WARN, "no depth camera on USB: the Pioneer sees obstacles with its sonar alone",
                       "plug a RealSense or an OpenNI2 camera into a USB 3 port for better obstacle warnings "
                       "and localisation; mount it and set its pose (docs/hardware.md, 'Depth camera'; docs/cameras.md)")
    return Finding("depth camera", OK, "on USB: " + ", ".join(found))


def spoken_feedback(m: Machine) -> Finding:
    if m.which("espeak-ng") is None:
        return Finding("spoken feedback", FAIL, "espeak-ng is not installed: the robots cannot speak",
                       "sudo apt-get install espeak-ng")
    return Finding("spoken feedback", OK, "espeak-ng is installed")


def recordings(folder: Path) -> Finding:
    """The recorder's folder: writable, and room for a working day of sessions."""
    probe = folder if folder.exists() else folder.parent
    if not os.access(probe, os.W_OK):
        return Finding("recordings", FAIL, f"{folder} is not writable: sessions would not be recorded",
                       "give this user the folder, or set ASIBOT_RECORDINGS to one it may write")
    free = shutil.disk_usage(probe).free
    if free < MIN_FREE_BYTES:
        return Finding("recordings", WARN, f"{free / 1024**3:.1f} GB free under {folder}",
                       "free some space or move ASIBOT_RECORDINGS: a session with cameras records about 1 GB an hour")
    return Finding("recordings", OK, f"{folder}: {free / 1024**3:.0f} GB free")


def by_hand() -> list[Finding]:
    """What only a person can check (docs/hardware.md says how)."""
    return [
        Finding("arm zero", BY_HAND, "q1 and q5 have no absolute encoder: the arm takes their angle at power-on as zero",
                "before switching the arm on, turn q1 and q5 to their zero marks (docs/hardware.md, 'First power-on')"),
        Finding("CAN terminations", BY_HAND, "a missing terminator may work on a short bench cable and fail on the robot",
                "power off, measure about 60 ohm between CAN-H and CAN-L at the adapter's connector"),
    ]


def run_checks(profile: str, m: Machine, arm_bitrate: Callable[[], int], recorded_in: Path) -> list[Finding]:
    """Every check of `profile` (real: the hardware; emulated: what the emulators need)."""
    found = [spoken_feedback(m), recordings(recorded_in)]
    if profile == "real":
        found[:0] = [can_bus(m, arm_bitrate()),
                     serial_line(m, "Pioneer serial line", PIONEER_PORT_ENV, "/dev/ttyUSB0"),
                     katana_line(m),
                     depth_camera(m)]
        found += by_hand()
    return found


# ---------------------------------------------------------------- the command
def _arm_bitrate() -> int:
    from asibot.arm_driver import config     # the drives' bitrate is the arm driver's configuration
    return config.load("asibot").bitrate


def settings(profile: str, compose_file: Path | None) -> dict[str, str]:
    """The environment the profile's services get from `asibot up`: this shell's, with what
    compose.yaml gives them (its defaults filled in: `${ASIBOT_ARM_CAN:-socketcan:can0}`)."""
    env = dict(os.environ)
    if compose_file is not None:
        for spec in compose.select(compose.load(compose_file), profile):
            env.update(spec.environment)
    return env


def cmd_doctor(args: argparse.Namespace) -> int:
    from asibot.cli.main import _find_compose, recordings_folder     # main registers this command
    compose_file = Path(args.file) if args.file else _find_compose()
    machine = Machine(env=settings(args.profile, compose_file))
    found = run_checks(args.profile, machine, _arm_bitrate, recordings_folder())
    if args.json:
        print(json.dumps([asdict(f) for f in found], indent=2))
    else:
        print(render(found))
    return 1 if any(f.status == FAIL for f in found) else 0


def render(found: Iterable[Finding]) -> str:
    found = list(found)
    width = max(len(f.check) for f in found)
    lines = []
    for f in found:
        lines.append(f"{f.status:>7}  {f.check:<{width}}  {f.says}")
        if f.fix and f.status != OK:
            lines.append(f"{'':>7}  {'':<{width}}  -> {f.fix}")
    failed = sum(f.status == FAIL for f in found)
    lines.append(f"{failed} check{'s' if failed != 1 else ''} failed." if failed else "Nothing failed.")
    return "\n".join(lines)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("doctor", help="check this machine for the real robots (CAN, serial lines, camera, sound, disk)")
    p.add_argument("--profile", choices=("real", "emulated"), default="real")
    p.add_argument("--json", action="store_true", help="the findings as JSON")
    p.add_argument("--file", default=None, help="compose file whose settings the services get (default: as asibot up)")
    p.set_defaults(func=cmd_doctor)


# ---------------------------------------------------------------- small readers
def _read(path: Path) -> str:
    try:
        return path.read_text().strip()
    except OSError:
        return ""


def _usb_vendors(sys_root: Path) -> set[str]:
    return {_read(d / "idVendor") for d in (sys_root / "bus" / "usb" / "devices").glob("*")} - {""}


def _group_of(path: Path) -> str:
    gid = path.stat().st_gid
    try:
        return grp.getgrgid(gid).gr_name
    except KeyError:
        return str(gid)
