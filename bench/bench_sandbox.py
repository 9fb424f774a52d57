"""Benchmark of the user-program sandbox (asibot.web.sandbox) against the plain subprocess the
runner used before it:

1. start to first output: `ProgramRunner.start()` to the program's first line, for a program
   that prints at once and for one that first imports `asibot.client` (what a real program
   does), in the full sandbox (bubblewrap, cgroups, Landlock), with cgroups only, with the
   supervisor only (a machine with neither), beside a plain `subprocess.Popen` with the old
   rlimits and its own session (the reference).
2. Stop to all gone: a program whose children left its process group (one `setsid()`, one
   double-forked daemon), from `stop()` to the moment no process with the run's marker is
   left (`stop()` returns then); the budget is 100 ms. The plain subprocess's figure is its
   process-group kill, after which the escaped children are still running (counted).

    python bench/bench_sandbox.py [--runs N] [--quick]
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from table import QUICK_HELP, print_table  # noqa: E402  bench/table.py: run as `python bench/<name>.py`

from asibot.testing import ESCAPING_PROGRAM, processes_with  # noqa: E402
from asibot.web.runner import Limits, ProgramRunner, _limiter  # noqa: E402
from asibot.web.sandbox import Sandbox  # noqa: E402

MODES = {"sandbox": {}, "cgroups only": {"bwrap": False}, "supervisor only": {"bwrap": False, "cgroups": False}}
PROGRAMS = {"print": "print('up', flush=True)\n",
            "import asibot.client": "import asibot.client\nprint('up', flush=True)\n"}
class FirstLine:
    def __init__(self) -> None:
        self.event = threading.Event()
        self.at = 0.0

    def __call__(self, stream: str, line: str) -> None:
        if stream == "out" and not self.event.is_set():
            self.at = time.perf_counter()
            self.event.set()


def start_to_output(mode: dict, text: str, folder: Path, runs: int) -> list[float]:
    path = folder / "prog.py"
    path.write_text(text)
    seen = FirstLine()
    runner = ProgramRunner(on_output=seen, env={"ASIBOT_ROUTER": "tcp/127.0.0.1:7447"}, sandbox=Sandbox(**mode))
    out = []
    try:
        for _ in range(runs + 1):   # the first is a warm-up
            seen.event.clear()
            t = time.perf_counter()
            runner.start(path, "bench")
            seen.event.wait(30)
            out.append(seen.at - t)
            while runner.running():
                time.sleep(0.005)
    finally:
        runner.close()
    return out[1:]


def plain_start_to_output(text: str, folder: Path, runs: int) -> list[float]:
    """The runner before the sandbox: Popen with rlimits in preexec_fn and a session of its own."""
    path = folder / "plain.py"
    path.write_text(text)
    out = []
    for _ in range(runs + 1):
        t = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-u", str(path), "bench"], cwd=folder,
                                env={**os.environ, "ASIBOT_ROBOT": "bench"}, stdin=subprocess.DEVNULL,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True,
                                preexec_fn=_limiter(Limits()))
        proc.stdout.readline()
        out.append(time.perf_counter() - t)
        proc.communicate()
    return out[1:]


def stop_to_gone(mode: dict, folder: Path, runs: int) -> tuple[list[float], int]:
    times, left = [], 0
    seen = []
    runner = ProgramRunner(on_output=lambda s, line: seen.append(line), sandbox=Sandbox(**mode))
    try:
        for _ in range(runs):
            marker = f"bench-escape-{uuid.uuid4().hex}"
            path = folder / "escape.py"
            path.write_text(ESCAPING_PROGRAM.format(marker=marker, then="time.sleep(60)"))
            seen.clear()
            runner.start(path, "bench")
            deadline = time.monotonic() + 30
            while "both up" not in seen and time.monotonic() < deadline:
                time.sleep(0.005)
            t = time.perf_counter()
            runner.stop()
            while processes_with(marker) and time.perf_counter() - t < 10:
                time.sleep(0.0005)
            times.append(time.perf_counter() - t)
            left += len(processes_with(marker))
    finally:
        runner.close()
    return times, left


def plain_stop(folder: Path, runs: int) -> tuple[list[float], int]:
    times, left = [], 0
    for _ in range(runs):
        marker = f"bench-escape-{uuid.uuid4().hex}"
        path = folder / "escape.py"
        path.write_text(ESCAPING_PROGRAM.format(marker=marker, then="time.sleep(60)"))
        proc = subprocess.Popen([sys.executable, "-u", str(path)], cwd=folder, stdout=subprocess.PIPE,
                                start_new_session=True)
        proc.stdout.readline()
        t = time.perf_counter()
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        times.append(time.perf_counter() - t)
        survivors = processes_with(marker)
        left += len(survivors)
        for pid in survivors:
            os.kill(pid, signal.SIGKILL)
    return times, left


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--quick", action="store_true", help=QUICK_HELP)
    args = parser.parse_args()
    if args.quick:
        args.runs = 1
    logging.getLogger("asibot.web.sandbox").setLevel(logging.ERROR)   # each mode's "missing" line
    print("#", Sandbox().describe())
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, text in PROGRAMS.items():
            plain = plain_start_to_output(text, folder, args.runs)
            rows.append((f"start to first output, {name}: plain subprocess (reference)",
                         f"{statistics.median(plain) * 1e3:.1f} / {max(plain) * 1e3:.1f}", "ms p50/max", ""))
            for mode, kwargs in MODES.items():
                t = start_to_output(kwargs, text, folder, args.runs)
                rows.append((f"start to first output, {name}: {mode}",
                             f"{statistics.median(t) * 1e3:.1f} / {max(t) * 1e3:.1f}", "ms p50/max", ""))
        t, left = plain_stop(folder, args.runs)
        rows.append(("Stop to all gone, escaped children: plain process-group kill (reference)",
                     f"{statistics.median(t) * 1e3:.1f} / {max(t) * 1e3:.1f}", "ms p50/max",
                     f"{left} of {2 * args.runs} escaped children still running"))
        for mode, kwargs in MODES.items():
            t, left = stop_to_gone(kwargs, folder, args.runs)
            rows.append((f"Stop to all gone, escaped children: {mode}",
                         f"{statistics.median(t) * 1e3:.1f} / {max(t) * 1e3:.1f}", "ms p50/max",
                         f"100 ms; {left} left"))
    print_table(rows)


if __name__ == "__main__":
    main()
