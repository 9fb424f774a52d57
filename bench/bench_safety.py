"""Benchmark of the safety figures issue 10 asks the closing note to report, on a real Zenoh
router with every service in its own process, as deployed (the `emulated` profile's command
lines, compose.yaml):

1. arm stop after a controller kill: the CANopen arm driver with its five emulated drives and
   the kinematics service; a movj is under way when the kinematics process gets SIGKILL. The
   reference, measured in the same run, is the user's own `stop()` at the same point of the
   same motion; the configured one is the 200 ms command watchdog.
2. base stop without commands: the ARCOS base driver against the emulated P3-AT; a cmd_vel
   stream ends (its 200 ms watchdog stops the base), its sender is killed (liveliness), and,
   as the reference, the sender sends a zero.
3. memory under the fuzzer: VmRSS of a kinematics process before and after malformed and
   oversized requests (up to 8 MB) to every verb of keys.RPC_VERBS_CART, against the same
   number of valid `stat` requests, with the replies counted by error code.

    python bench/bench_safety.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Callable, TextIO

import numpy as np

from asibot import keys, messages, testing
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.client import CartesianClient
from asibot.errors import RpcError
from asibot.kinematics import requests
from asibot.messages import COMMAND_WATCHDOG_S, ArmState, Event, Odometry, Twist
from asibot.base_driver.emulator.robot import SIP_PERIOD, TRANS_ACCEL

from table import QUICK_HELP, print_table  # bench/table.py: run as `python bench/<name>.py`

#: The only CAN arm the catalog and arm_driver/robots/*.yaml know; the private router keeps
#: this run apart from any stack using the same id.
ARM = "asibot"
BASE = "bench-base"
REPS = 5
ARM_STILL = 1e-3        # rad/s: every joint below this counts as stopped
BASE_STILL = 1e-3       # m/s and rad/s
BASE_SPEED = 0.3        # m/s of the cmd_vel stream
FUZZ_REQUESTS = 4000
#: VmRSS is read after each of these shares of the fuzzed requests: a ceiling, or a growth?
FUZZ_QUARTERS = 4
SENDER = """
import sys, time
from asibot import keys, testing
from asibot.safety import ownership
from asibot.bus import Bus
from asibot.messages import Twist
robot, vx = sys.argv[1], float(sys.argv[2])
bus = Bus("bench-sender", wait=20)
me = ownership.announce(bus, robot, "base", "bench-sender")
testing.wait_until(lambda: bus.call(keys.driver_rpc(robot, "status"), timeout=2)["holders"]["base"] == me.id, 10)
time.sleep(0.3)                     # a stream begun after taking hold moves the base at once
pub = bus.publisher(keys.base_cmd_vel(robot), Twist, express=True)
testing.Stream(lambda: me.put(pub, Twist(vx=vx, wz=0.0)), period=0.05)
print("READY", flush=True)
sys.stdin.read()
"""


# ---------------------------------------------------------------- processes
class Processes:
    """The services of this run, each `python -m asibot.<service>` with its log in a file; the
    logs are printed when the run fails, every process is ended and the logs removed at close."""

    def __init__(self) -> None:
        self.folder = Path(tempfile.mkdtemp(prefix="bench-safety-"))
        self.procs: list[tuple[str, subprocess.Popen]] = []
        self._logs: list[TextIO] = []

    def start(self, name: str, *args: str, stdin: bool = False) -> subprocess.Popen:
        log = open(self.folder / f"{name}-{len(self.procs)}.log", "w")
        self._logs.append(log)
        proc = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE if stdin else log,
                                stderr=log, stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
                                text=True)
        self.procs.append((name, proc))
        return proc

    def service(self, module: str, *args: str) -> subprocess.Popen:
        return self.start(module.rsplit(".", 1)[-1], "-m", module, *args)

    def logs(self) -> str:
        return "\n".join(f"--- {p.name}\n{p.read_text()[-2000:]}" for p in sorted(self.folder.glob("*.log")))

    def close(self) -> None:
        for _, proc in reversed(self.procs):
            if proc.poll() is None:
                proc.terminate()
        for _, proc in self.procs:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        for log in self._logs:
            log.close()
        shutil.rmtree(self.folder, ignore_errors=True)


def kill(proc: subprocess.Popen) -> float:
    """SIGKILL `proc`; the monotonic time just before the signal."""
    t = time.monotonic()
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(10)
    return t


class Trace:
    """Timestamped samples (arrival time, value) from a subscription, thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.samples: list[tuple[float, object]] = []

    def add(self, value: object) -> None:
        with self._lock:
            self.samples.append((time.monotonic(), value))

    def since(self, t0: float) -> list[tuple[float, object]]:
        with self._lock:
            return [s for s in self.samples if s[0] >= t0]

    def last(self) -> object | None:
        with self._lock:
            return self.samples[-1][1] if self.samples else None


def settled_at(samples: list[tuple[float, object]], still: Callable[[object], bool]) -> float | None:
    """Arrival time of the first sample from which every later one is still (None: never)."""
    at = None
    for t, value in samples:
        if not still(value):
            at = None
        elif at is None:
            at = t
    return at


def stop_latency(trace: Trace, t0: float, still: Callable[[object], bool], watch: float) -> float:
    """Seconds from t0 until the samples show the robot stopped for good (watched `watch` s)."""
    time.sleep(max(0.0, t0 + watch - time.monotonic()))
    at = settled_at(trace.since(t0), still)
    if at is None:
        raise AssertionError(f"the robot had not stopped {watch} s after the event")
    return at - t0


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


# ---------------------------------------------------------------- 1. the arm
def arm_still(state: ArmState) -> bool:
    return max(abs(v) for v in state.velocities) < ARM_STILL


def cruising(state: ArmState | None, share: float = 0.6) -> bool:
    """The arm moves at `share` of the ASIBOT's 25 deg/s on some joint."""
    return state is not None and max(abs(v) for v in state.velocities) > share * np.radians(25)


def controller_ready(client: CartesianClient) -> bool:
    try:
        return client.state().get("joints") is not None
    except RpcError:
        return False


def stop_during_movj(client: CartesianClient, trace: Trace, target_deg: float,
                     act: Callable[[], float], rng: random.Random) -> tuple[float, float, float]:
    """Start a movj of q1 to target_deg and call `act` (it returns its start time) while the arm
    cruises; (that start time, s until every joint is still for good, deg q1 travelled after)."""
    client.movj(joints=[target_deg, 0, 0, 0, 0], speed=1.0)    # a cubic peaking at 25 deg/s
    testing.wait_until(lambda: cruising(trace.last()), 5, message="the movj did not start")
    time.sleep(rng.uniform(0.0, 0.15))      # a random phase of the 10 ms control cycles, >= 15 deg/s
    t0 = act()
    at_act = [s for t, s in trace.since(t0 - 0.1) if t < t0][-1]
    latency = stop_latency(trace, t0, arm_still, 1.2)
    travel = abs(trace.last().positions[0] - at_act.positions[0])
    return t0, latency, float(np.degrees(travel))


def arm_stops(procs: Processes, observer: Bus, rng: random.Random) -> dict[str, list[float]]:
    """Per repetition, on a new kinematics process: its stop() mid-movj, then its SIGKILL
    mid-movj; also when an observer saw the killed controller's liveliness token vanish."""
    trace = Trace()
    observer.subscribe(keys.arm_state(ARM), ArmState, trace.add)
    gone: list[float] = []
    observer.watch(keys.controllers_alive(ARM), lambda key, alive: alive or gone.append(time.monotonic()))
    procs.service("asibot.arm_driver", "--robot", ARM, "--can", "emulated")
    testing.wait_until(lambda: trace.last() is not None and trace.last().mode != "fault", 30,
                       message="the emulated drives did not come up")
    out: dict[str, list[float]] = {k: [] for k in ("stop", "stop_travel", "kill", "kill_travel", "token")}
    sign = 1.0
    for _ in range(REPS):
        kinematics = procs.service("asibot.kinematics", "--robot", ARM)
        with CartesianClient(ARM, timeout=30) as client:
            testing.wait_until(lambda: controller_ready(client), 30, message="kinematics never saw the arm")
            # no wait for the driver to name the new holder: a movj at once is what a user does
            # (kinematics waits, once, until the driver names it: its first command could
            # otherwise outrun its token and the whole movj be refused as a stream from before)
            _, latency, travel = stop_during_movj(client, trace, 60 * sign, lambda: user_stop(client), rng)
            out["stop"].append(latency)
            out["stop_travel"].append(travel)
            t0, latency, travel = stop_during_movj(client, trace, -60 * sign, lambda: kill(kinematics), rng)
        out["kill"].append(latency)
        out["kill_travel"].append(travel)
        out["token"].append(min(t for t in gone if t >= t0) - t0)
        sign = -sign
    return out


def user_stop(client: CartesianClient) -> float:
    t = time.monotonic()
    client.stop()
    return t


# ---------------------------------------------------------------- 2. the base
def base_still(odom: Odometry) -> bool:
    return abs(odom.vx) < BASE_STILL and abs(odom.wz) < BASE_STILL


def base_cruising(trace: Trace) -> bool:
    odom = trace.last()
    return odom is not None and abs(odom.vx) > 0.8 * BASE_SPEED


def held_by(bus: Bus, controller: str) -> bool:
    try:
        return bus.call(keys.driver_rpc(BASE, "status"), timeout=2)["holders"]["base"] == controller
    except RpcError:
        return False


def stream_then(pub_send: Callable[[], None], trace: Trace, end: Callable[["testing.Stream"], float],
                rng: random.Random) -> float:
    """Stream cmd_vel every 50 ms until the base cruises, end it with `end` (which returns the
    event's time); seconds from that event until odometry shows the base stopped for good."""
    with testing.Stream(pub_send, period=0.05) as stream:
        testing.wait_until(lambda: base_cruising(trace), 5, message="the base did not start")
        time.sleep(rng.uniform(0.0, SIP_PERIOD))      # a random phase of the SIP cycle
        t0 = end(stream)
        latency = stop_latency(trace, t0, base_still, 1.5)
    time.sleep(COMMAND_WATCHDOG_S)      # the next stream is a new one (asibot.safety.arming)
    return latency


def last_sent(stream: testing.Stream) -> float:
    stream.pause()
    return stream.sent[-1]


def base_stops(procs: Processes, observer: Bus, rng: random.Random) -> dict[str, list[float]]:
    """Per repetition: the stream ends (the watchdog), the stream ends with a zero (the
    reference), and a sender process is SIGKILLed (its liveliness token vanishes)."""
    port = testing.free_port()
    procs.service("asibot.base_driver.emulator", "--listen", f"127.0.0.1:{port}")
    procs.service("asibot.base_driver", "--robot", BASE, "--port", f"socket://127.0.0.1:{port}")
    trace = Trace()
    observer.subscribe(keys.base_odom(BASE), Odometry, trace.add)
    out: dict[str, list[float]] = {"watchdog": [], "zero": [], "kill": []}
    with Bus("bench-base-controller") as bus:
        me = ownership.announce(bus, BASE, "base", "bench")
        testing.wait_until(lambda: held_by(bus, me.id) and trace.last() is not None, 30,
                           message="the base driver did not connect to the emulator")
        time.sleep(COMMAND_WATCHDOG_S)
        pub = bus.publisher(keys.base_cmd_vel(BASE), Twist, express=True)
        sign = 1.0
        for _ in range(REPS):
            send = (lambda v: lambda: me.put(pub, Twist(vx=v, wz=0.0)))(sign * BASE_SPEED)
            out["watchdog"].append(stream_then(send, trace, last_sent, rng))

            def zero(stream: testing.Stream) -> float:
                stream.pause()
                t = time.monotonic()
                me.put(pub, Twist(vx=0.0, wz=0.0))
                return t

            send = (lambda v: lambda: me.put(pub, Twist(vx=v, wz=0.0)))(-sign * BASE_SPEED)
            out["zero"].append(stream_then(send, trace, zero, rng))
            sign = -sign
    for i in range(REPS):
        sender = procs.start("sender", "-c", SENDER, BASE, str((1 if i % 2 == 0 else -1) * BASE_SPEED), stdin=True)
        if sender.stdout.readline().strip() != "READY":
            raise AssertionError("the cmd_vel sender did not start")
        testing.wait_until(lambda: base_cruising(trace), 5, message="the sender did not move the base")
        time.sleep(rng.uniform(0.0, SIP_PERIOD))
        t0 = kill(sender)
        out["kill"].append(stop_latency(trace, t0, base_still, 1.5))
    return out


# ---------------------------------------------------------------- 3. memory
def status_kb(pid: int, field: str) -> int:
    """A /proc/<pid>/status figure in kB (VmRSS: resident now, VmHWM: the most ever)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise KeyError(field)


class PeakRss:
    """The highest VmRSS of `pid`, sampled every 10 ms on a thread while in the `with` block."""

    def __init__(self, pid: int) -> None:
        self.pid, self.peak_kb = pid, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            self.peak_kb = max(self.peak_kb, status_kb(self.pid, "VmRSS"))

    def __enter__(self) -> "PeakRss":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


ODD_VALUES: list[object] = [
    None, True, "", "forward", "nan", b"\0\1", float("nan"), float("inf"), -float("inf"), 1e300, -2**63,
    2**64 - 1, 0, 0.5, {"x": 1}, [], [float("nan")] * 5, [1, 2], [[1]] * 5, ["a"] * 5, [None] * 5,
    [1e300] * 5, [0.1] * 6, [0.0, 0.5, 1.2, 180, 0], list(range(7)), np.zeros((5, 1)), np.array([True] * 5),
    np.full(5, np.nan), {"point": [0, 0, 1.4, 0, 0]},
]


def fuzzed(rng: random.Random, verb: str) -> tuple[str, bytes]:
    """One bad request for `verb`, as bytes: mostly its own fields with wrong or odd values,
    else unknown fields, ~800 KB values (under the bus's 1 MiB limit: they reach the
    validators), 8 MB ones, requests that are not maps, bytes that are not msgpack."""
    fields = sorted(requests.verbs(5)[verb].fields) or ["point"]
    kind = rng.random()
    if kind < 0.025:
        return "8 MB", messages.pack({rng.choice(fields): np.full(1_000_000, 0.5)})
    if kind < 0.05:
        return "8 MB", messages.pack({rng.choice(fields): "x" * 8_000_000})
    if kind < 0.15:
        big = [0.123456789] * 88_000 if rng.random() < 0.5 else "x" * 800_000
        return "800 kB", messages.pack({rng.choice(fields): big})
    if kind < 0.30:
        return "not msgpack", rng.randbytes(rng.randint(1, 64))
    if kind < 0.35:
        return "not a map", messages.pack(rng.choice([[1, 2], "stat", 7, None, [{"point": 1}]]))
    if kind < 0.45:
        return "unknown fields", messages.pack({rng.choice(["", "x" * 300, "timeout ", "Point"]): rng.choice(ODD_VALUES)})
    picked = rng.sample(fields, rng.randint(1, len(fields)))
    return "odd values", messages.pack({name: rng.choice(ODD_VALUES) for name in picked})


def ask(bus: Bus, verb: str, payload: bytes) -> str:
    """Send raw bytes to the verb (the bus's own query: a fuzzer sends what `call` cannot
    pack); the reply's error code, "ok", or "no reply"."""
    answers = [a for a in bus._get(keys.cart_rpc(ARM, verb), payload, 5.0) if a is not None]
    if not answers:
        return "no reply"
    reply = messages.unpack(answers[0][1])
    return "ok" if reply["ok"] else str(reply["error"])


def memory(procs: Processes, rng: random.Random) -> dict[str, object]:
    """RSS of a new kinematics process (the arm driver of part 1 still runs) after warming up,
    after FUZZ_REQUESTS valid `stat`s, after each quarter of FUZZ_REQUESTS fuzzed requests."""
    kinematics = procs.service("asibot.kinematics", "--robot", ARM)
    out: dict[str, object] = {}
    with CartesianClient(ARM, timeout=30) as client, Bus("bench-fuzzer") as bus:
        testing.wait_until(lambda: controller_ready(client), 30, message="kinematics never saw the arm")
        for verb in keys.RPC_VERBS_CART:         # every path once, so imports and caches are in
            bus.wait_for(keys.cart_rpc(ARM, verb), 10)
            ask(bus, verb, messages.pack({"point": [float("nan")] * 5}))
        for _ in range(50):
            client.stat()
        out["start"] = status_kb(kinematics.pid, "VmRSS")
        for _ in range(FUZZ_REQUESTS):
            client.stat()
        out["stat"] = status_kb(kinematics.pid, "VmRSS")
        codes, kinds, sent = Counter(), Counter(), 0
        t = time.monotonic()
        with PeakRss(kinematics.pid) as peak:
            for i in range(FUZZ_REQUESTS):
                verb = rng.choice(keys.RPC_VERBS_CART)
                kind, payload = fuzzed(rng, verb)
                kinds[kind] += 1
                sent += len(payload)
                codes[ask(bus, verb, payload)] += 1
                if (i + 1) % (FUZZ_REQUESTS // FUZZ_QUARTERS) == 0:
                    out.setdefault("after", []).append((i + 1, status_kb(kinematics.pid, "VmRSS")))
        out["fuzz_s"] = time.monotonic() - t
        out["fuzz"] = status_kb(kinematics.pid, "VmRSS")
        out["peak"], out["hwm"] = peak.peak_kb, status_kb(kinematics.pid, "VmHWM")
        out["alive"] = kinematics.poll() is None and controller_ready(client)
        out["codes"], out["kinds"], out["sent_mb"] = codes, kinds, sent / 1e6
        client.stop()
    return out


# ---------------------------------------------------------------- the table
def arm_rows(arm: dict[str, list[float]]) -> list[tuple]:
    ms, n = 1e3, len(arm["kill"])
    stop = f"stop() mid-movj, same run: p50 {pct(arm['stop'], 50) * ms:.0f} ms, max {max(arm['stop']) * ms:.0f} ms"
    return [
        (f"arm stopped after SIGKILL of kinematics mid-movj, p50 ({n} runs, emulated CANopen drives)",
         pct(arm["kill"], 50) * ms, "ms", f"watchdog {COMMAND_WATCHDOG_S * 1e3:.0f} ms; {stop}"),
        ("arm stopped after SIGKILL of kinematics, max", max(arm["kill"]) * ms, "ms",
         f"watchdog {COMMAND_WATCHDOG_S * 1e3:.0f} ms"),
        ("q1 travel after the kill, max (moving at 15-25 deg/s)", max(arm["kill_travel"]), "deg",
         f"after stop(): max {max(arm['stop_travel']):.2f} deg"),
        ("controller's liveliness token gone at an observer after SIGKILL, p50 / max",
         f"{pct(arm['token'], 50) * ms:.1f} / {max(arm['token']) * ms:.1f}", "ms", "-"),
    ]


def base_rows(base: dict[str, list[float]]) -> list[tuple]:
    ms, n = 1e3, len(base["kill"])
    decel = BASE_SPEED / (TRANS_ACCEL / 1000.0)
    zero = f"cmd_vel 0 sent, same run: p50 {pct(base['zero'], 50) * ms:.0f} ms, max {max(base['zero']) * ms:.0f} ms"
    bound = (COMMAND_WATCHDOG_S + decel + SIP_PERIOD) * ms
    return [
        (f"base stopped after its cmd_vel stream ends (watchdog), p50 ({n} runs, {BASE_SPEED} m/s, emulated P3-AT)",
         pct(base["watchdog"], 50) * ms, "ms",
         f"<= {bound:.0f} (watchdog {COMMAND_WATCHDOG_S * ms:.0f} + braking {decel * ms:.0f} + SIP {SIP_PERIOD * ms:.0f}); {zero}"),
        ("base stopped after its cmd_vel stream ends, max", max(base["watchdog"]) * ms, "ms", f"<= {bound:.0f}"),
        ("base stopped after SIGKILL of the cmd_vel sender, p50 / max",
         f"{pct(base['kill'], 50) * ms:.0f} / {max(base['kill']) * ms:.0f}", "ms",
         f"<= {(decel + SIP_PERIOD) * ms:.0f} (braking + SIP); {zero}"),
    ]


def memory_rows(mem: dict[str, object]) -> list[tuple]:
    mb = 1 / 1024
    codes = ", ".join(f"{c} {k}" for c, k in sorted(mem["codes"].items(), key=lambda x: -x[1]))
    kinds = ", ".join(f"{k} {c}" for k, c in sorted(mem["kinds"].items(), key=lambda x: -x[1]))
    stat = f"after {FUZZ_REQUESTS} valid stat: {mem['stat'] * mb:.1f} MB"
    return [
        ("kinematics VmRSS after warm-up", mem["start"] * mb, "MB", "-"),
        *((f"kinematics VmRSS after {n} fuzzed requests", kb * mb, "MB", stat) for n, kb in mem["after"][:-1]),
        (f"kinematics VmRSS after all {FUZZ_REQUESTS} fuzzed requests ({mem['sent_mb']:.0f} MB in {mem['fuzz_s']:.0f} s)",
         mem["fuzz"] * mb, "MB", stat),
        ("kinematics VmRSS peak while fuzzed (10 ms samples) / VmHWM", f"{mem['peak'] * mb:.1f} / {mem['hwm'] * mb:.1f}",
         "MB", stat),
        (f"fuzzed requests ({kinds}) by reply", codes, "count", "no `internal`, no `no reply`"),
        ("kinematics alive and answering after the fuzzer", "yes" if mem["alive"] else "NO", "-", "yes"),
    ]


def main() -> int:
    global REPS, FUZZ_REQUESTS
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help=QUICK_HELP)
    if ap.parse_args().quick:
        REPS, FUZZ_REQUESTS = 1, FUZZ_QUARTERS          # one request a quarter: VmRSS is read after each
    rng = random.Random(10)         # issue 10
    procs = Processes()
    events = Trace()
    try:
        with testing.router(), Bus("bench-observer") as observer:
            for robot in (ARM, BASE):
                observer.subscribe(keys.events(robot), Event, events.add)
            arm = arm_stops(procs, observer, rng)
            mem = memory(procs, rng)
            base = base_stops(procs, observer, rng)
    except Exception:
        print(procs.logs(), file=sys.stderr)
        print("--- events\n" + "\n".join(f"{t:.3f} {e.code}: {e.text}" for t, e in events.since(0)), file=sys.stderr)
        raise
    finally:
        procs.close()
    rows = arm_rows(arm) + base_rows(base) + memory_rows(mem)
    print_table(((what, f"{v:.1f}" if isinstance(v, float) else v, unit, ref) for what, v, unit, ref in rows),
                header=("what", "value", "unit", "reference (same run)"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
