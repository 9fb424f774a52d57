"""Runs a user's Python program (from the Program tab) in its own process, with limits.

A user's program is untrusted in the everyday sense: it may loop forever, allocate without
bound, crash, or leave child processes behind, and in the plain sense too: it is text from a
web page, on a robot PC where the server is root and holds every bus password. So it never
runs inside the web server: it runs in a sandbox (asibot.web.sandbox: its own pid namespace
and cgroup, an unprivileged user, a read-only machine, no listening sockets, its own bus
login) with CPU, memory, process and wall-clock limits, no shell, no stdin. Stop kills every
process it started at once, however it detached. Its output comes back line by line, capped,
and whenever it ends for any reason but a clean exit the arm is told to stop (`stop_robot`),
because a program that dies mid-motion must not leave the arm moving. The page gets a sentence
saying why it ended; a Python error as one sentence with the user's line and its traceback as
details, the machine's paths left out of both and of the output (asibot.web.tracebacks).

Plain Python on purpose: the server wires the callbacks to its WebSocket and to the bus.
"""

from __future__ import annotations

import collections
import concurrent.futures
import dataclasses
import logging
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Callable

from asibot.web.sandbox import Prepared, Sandbox, exit_code
from asibot.web.tracebacks import Files, PythonError, read_error

log = logging.getLogger(__name__)

#: stderr lines kept to explain the end (a traceback's last frames and message fit easily).
STDERR_TAIL = 200
#: How long Stop waits for the fallback supervisor (no pid namespace, no cgroup) to end the
#: program's processes before it kills the group itself, s. Everywhere else Stop is SIGKILL.
TERM_GRACE = 1.0
#: How long ending a run may take before the runner says processes are left, s.
GONE_TIMEOUT = 5.0
#: Marks a line cut at max_line_chars.
CUT_MARK = " [line cut]"
#: Text in the stderr tail that says the program ran out of memory (Python, C++, OpenBLAS...).
_MEMORY_MARKERS = ("MemoryError", "std::bad_alloc", "Cannot allocate memory", "Memory allocation")


@dataclass
class Limits:
    """What one program may use; hitting a limit ends it with a sentence that says which."""

    cpu_seconds: int = 120
    # RLIMIT_DATA, not RLIMIT_AS. Measured on this stack: `import numpy, zenoh, asibot.client`
    # plus an open Zenoh session has ~100 MB of data (VmData) but ~370-520 MB of address space
    # on a 2-core machine, most of it glibc's 64 MiB malloc arena reservations per thread
    # (MALLOC_ARENA_MAX=1 takes it to 170 MB), so address space grows with the thread and core
    # count, not with what the program uses. When Zenoh cannot create its threads it hangs
    # instead of failing (seen with RLIMIT_AS up to 384 MiB and RLIMIT_DATA up to 160 MiB), so a
    # limit that is tight on a bigger machine would hang programs at start. RLIMIT_DATA (Linux
    # >= 4.7: heap plus private writable mappings, i.e. memory the program can actually fill)
    # counts what a program allocates, and 1 GiB leaves ~900 MiB for the program itself.
    # Also the memory cgroup's limit for the whole sandbox when the machine has one: it counts
    # what RLIMIT_DATA does not (shared mappings, tmpfs, every process of the program).
    memory_bytes: int = 1 << 30
    max_output_lines: int = 2000
    max_line_chars: int = 2000
    # Wall-clock time: a program asleep or waiting on the bus uses no CPU and would run for ever.
    wall_seconds: float = 600.0
    # Processes *and threads* of the whole sandbox (the pids cgroup counts tasks): a Zenoh
    # client with numpy has ~20 threads on 2 cores (numpy starts one per core), so 128 plus
    # one per core leaves room, and a fork bomb stops well short of hurting the server.
    max_tasks: int = 128 + (os.cpu_count() or 1)
    # The program's scratch folder (/tmp, also $HOME): a tmpfs, gone when the run ends.
    scratch_bytes: int = 64 << 20


@dataclass
class RunResult:
    """How one run ended, for the page: `reason` says it to the user, as words that follow the
    program's name and take the full stop after them ("finished", "stopped by the user",
    "failed with an error on line 7: ..."). A run that ended in a Python error also has
    `error`, the one sentence the page shows ("Line 7: ... point."), the user's `line` and the
    traceback's `details`, which its output no longer holds."""

    program: str
    robot: str
    started: float  # time.time()
    ended: float
    exit_code: int | None  # negative: killed by that signal (subprocess' convention)
    reason: str
    ok: bool
    error: str | None = None
    line: int | None = None
    details: list[str] = field(default_factory=list)


class ProgramRunner:
    """Runs one user program at a time in a child process with limits (see the module doc).

    Callbacks run on the runner's threads: `on_start(status)` once a run has started, before
    any of its output (with `status()` of the new run; it runs inside `start`, so it must be
    quick and must not call the runner), `on_output(stream, line)` with stream "out" or "err"
    (calls are serialised), `stop_robot(robot)` when a run ends in anything but a clean exit,
    then `on_exit(result)`. Their exceptions are logged and otherwise ignored.
    """

    def __init__(self, python: str = sys.executable, limits: Limits | None = None,
                 env: dict[str, str] | None = None,
                 on_output: Callable[[str, str], None] | None = None,
                 on_exit: Callable[[RunResult], None] | None = None,
                 stop_robot: Callable[[str], None] | None = None,
                 *, sandbox: Sandbox | None = None,
                 on_start: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.python = python
        self.sandbox = sandbox if sandbox is not None else Sandbox()
        self.limits = limits or Limits()
        self.env = dict(env or {})
        self.on_output = on_output
        self.on_exit = on_exit
        self.on_start = on_start
        self.stop_robot = stop_robot
        self._lock = threading.Lock()         # guards the run's state below
        self._signal_lock = threading.Lock()  # signals vs reaping: never signal a reaped pgid
        self._output_lock = threading.Lock()  # one on_output at a time, ring in call order
        self._ring: collections.deque[tuple[str, str]] = collections.deque(maxlen=self.limits.max_output_lines)
        self._proc: subprocess.Popen[bytes] | None = None
        self._run: Prepared | None = None
        self._timer: threading.Timer | None = None
        # One long-lived thread forks every program: bubblewrap's --die-with-parent is the
        # *thread* that forked it (PR_SET_PDEATHSIG), and a request thread that ends would
        # take the program with it.
        self._spawner = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="runner-spawn")
        self._waiter: threading.Thread | None = None
        self._reaped = threading.Event()
        self._done = threading.Event()
        self._done.set()
        self._program = ""
        self._robot = ""
        self._started = 0.0
        self._stop_reason: str | None = None
        self._last: RunResult | None = None

    # -- control ---------------------------------------------------------------------------

    def start(self, path: Path, robot: str, *, name: str | None = None,
              wall_seconds: float | None = None) -> None:
        """Run `python -u path robot` in the program's folder; returns once it has started.

        `wall_seconds` replaces the limits' wall-clock time for this run (the page's choice).
        """
        path = Path(path).resolve()
        if not path.is_file():
            raise FileNotFoundError(f"there is no program file {path.name!r}")
        limits = self.limits
        if wall_seconds is not None:
            if not wall_seconds > 0:
                raise ValueError(f"the time limit must be more than 0 s, got {wall_seconds}")
            limits = dataclasses.replace(limits, wall_seconds=float(wall_seconds))
        with self._lock:
            if not self._done.is_set():
                raise RuntimeError(f"{self._program!r} is still running; stop it first")
            run = self.sandbox.prepare(self.python, path, robot, self.env,
                                       memory_bytes=limits.memory_bytes, max_tasks=limits.max_tasks,
                                       scratch_bytes=limits.scratch_bytes, rlimits=_limiter(limits))
            try:
                proc = self._spawner.submit(
                    subprocess.Popen,
                    run.argv,  # a list: no shell ever sees user input
                    cwd=run.cwd, env=run.env, pass_fds=run.pass_fds,
                    stdin=subprocess.DEVNULL,  # input() gets EOF instead of blocking forever
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                    start_new_session=True,    # its own process group, apart from the server's
                    preexec_fn=run.preexec).result()
                run.started()
            except BaseException:
                run.close()
                raise
            self._proc, self._run = proc, run
            self._program = name or path.stem
            self._robot = robot
            self._started = time.time()
            self._stop_reason = None
            self._ring.clear()
            self._reaped.clear()
            self._done.clear()
            # Before its first line: a page that hears of the run clears the last run's output.
            _call(self.on_start, self._status())
            tail: collections.deque[str] = collections.deque(maxlen=STDERR_TAIL)
            files = Files(run.program)
            readers = [threading.Thread(target=self._read, args=(proc.stdout, "out", None, None),
                                        name=f"runner-out-{proc.pid}", daemon=True),
                       threading.Thread(target=self._read, args=(proc.stderr, "err", tail, files),
                                        name=f"runner-err-{proc.pid}", daemon=True)]
            for reader in readers:
                reader.start()
            self._waiter = threading.Thread(target=self._wait, args=(proc, run, limits, readers, tail, files),
                                            name=f"runner-wait-{proc.pid}", daemon=True)
            self._waiter.start()
            self._timer = threading.Timer(limits.wall_seconds, self._out_of_time, args=(proc, limits))
            self._timer.daemon = True
            self._timer.start()

    def _out_of_time(self, proc: subprocess.Popen[bytes], limits: Limits) -> None:
        with self._lock:
            if self._proc is not proc or self._done.is_set():
                return
        self.stop(f"stopped: it ran longer than its time limit of {_duration(limits.wall_seconds)}")

    def stop(self, reason: str = "stopped by the user") -> None:
        """Stop the running program and every process it started; returns once all are gone.

        SIGKILL at once, to every process of its pid namespace and cgroup: a program that
        setsid()s or double-forks leaves its process group, not those. No SIGTERM first: the
        arm must stop now, and a cleanup that ran on would be a program running after Stop.
        Idempotent.
        """
        with self._lock:
            proc, run, waiter = self._proc, self._run, self._waiter
            if proc is None or run is None or self._done.is_set():
                return
            if self._stop_reason is None:
                self._stop_reason = reason
        if run.supervised:   # only a supervisor knows the descendants that left the group
            self._signal(proc, signal.SIGTERM, group=False)
            if self._reaped.wait(TERM_GRACE):
                run = None
        if run is not None:
            self._kill(proc, run)
        self._reaped.wait()
        # The waiter makes sure all are gone, tells the robot to stop and records the result;
        # wait for that too, unless stop() is called from a callback on the waiter itself.
        if waiter is not None and waiter is not threading.current_thread():
            waiter.join(timeout=GONE_TIMEOUT + 5.0)

    def close(self) -> None:
        """Stop a running program (the server is going away)."""
        self.stop("stopped: the web server was shut down")

    # -- state -----------------------------------------------------------------------------

    def running(self) -> bool:
        return not self._done.is_set()

    def output(self) -> list[tuple[str, str]]:
        """The newest output lines of the current (or last) run, as (stream, line)."""
        with self._output_lock:
            return list(self._ring)

    def status(self) -> dict[str, Any]:
        with self._lock:
            return self._status()

    def _status(self) -> dict[str, Any]:
        """status(), with the lock held."""
        running = not self._done.is_set()
        return {"program": self._program or None, "robot": self._robot or None,
                "pid": self._proc.pid if running and self._proc else None,
                "running": running, "started": self._started or None,
                "last": dataclasses.asdict(self._last) if self._last else None}

    # -- threads ---------------------------------------------------------------------------

    def _read(self, stream: IO[bytes], name: str, tail: collections.deque[str] | None,
              files: Files | None) -> None:
        """Pass each line on, capped; an endless line is skipped past so it cannot fill memory.
        `tail` keeps the lines as written (they explain the end); `files` names the files of
        the lines passed on without the machine's paths."""
        chars = self.limits.max_line_chars
        try:
            while True:
                raw = stream.readline(4 * chars + 4)  # up to 4 bytes a character in UTF-8
                if not raw:
                    return
                cut = False
                if not raw.endswith(b"\n"):
                    while True:  # the rest of an over-long line
                        more = stream.readline(65536)
                        if not more:
                            break
                        cut = True
                        if more.endswith(b"\n"):
                            break
                line = raw.decode("utf-8", errors="replace").rstrip("\r\n")
                if cut or len(line) > chars:
                    line = line[:chars] + CUT_MARK
                if tail is not None:
                    tail.append(line)
                if files is not None:
                    line = files.line(line)
                with self._output_lock:
                    self._ring.append((name, line))
                    _call(self.on_output, name, line)
        except (OSError, ValueError):
            log.exception("reading the program's %s failed", name)
        finally:
            stream.close()

    def _wait(self, proc: subprocess.Popen[bytes], run: Prepared, limits: Limits,
              readers: list[threading.Thread], tail: collections.deque[str], files: Files) -> None:
        pid = proc.pid
        os.waitid(os.P_PID, pid, os.WEXITED | os.WNOWAIT)
        # The exited leader is a zombie until reaped, which keeps its process group id ours:
        # kill whatever it left now, in the group, the namespace and the cgroup, so no orphan
        # keeps moving the arm.
        self._kill(proc, run)
        with self._signal_lock:
            try:
                _, status, usage = os.wait4(pid, 0)
                code: int | None = exit_code(os.waitstatus_to_exitcode(status), run)
                cpu = usage.ru_utime + usage.ru_stime
            except ChildProcessError:  # someone else reaped it; we know less
                code, cpu = None, 0.0
            proc.returncode = code if code is not None else -1  # Popen must not wait on the pid again
            self._reaped.set()
        if not run.wait_gone(GONE_TIMEOUT):
            log.error("processes of the program %r were still running %.0f s after it ended: %s",
                      self._program, GONE_TIMEOUT, run.cgroups.pids_inside() if run.cgroups else "?")
        if self._timer is not None:
            self._timer.cancel()
        with self._lock:
            stop_reason = self._stop_reason
        if stop_reason is not None or code != 0:
            # First thing after it died: a crash mid-motion must not leave the arm moving.
            _call(self.stop_robot, self._robot)
        oom = bool(run.cgroups and run.cgroups.counter("memory.events", "oom_kill"))
        crowded = bool(run.cgroups and run.cgroups.counter("pids.events", "max"))
        run.close()
        for reader in readers:
            reader.join(timeout=2.0)
        reason, ok, error = explain(code, cpu, list(tail), files, limits, stop_reason,
                                    out_of_memory=oom, out_of_tasks=crowded)
        result = RunResult(program=self._program, robot=self._robot, started=self._started,
                           ended=time.time(), exit_code=code, reason=reason, ok=ok)
        if error is not None:
            result.error, result.line, result.details = error.sentence, error.line, error.details
            self._take_from_output(error.taken)
        with self._lock:
            self._last = result
            self._done.set()
        _call(self.on_exit, result)

    def _take_from_output(self, count: int) -> None:
        """Take the last `count` stderr lines out of the output: the traceback the result
        holds as its details (the page shows the sentence, and the traceback on demand)."""
        with self._output_lock:
            kept: list[tuple[str, str]] = []
            for entry in reversed(self._ring):
                if count > 0 and entry[0] == "err":
                    count -= 1
                else:
                    kept.append(entry)
            self._ring.clear()
            self._ring.extend(reversed(kept))

    def _kill(self, proc: subprocess.Popen[bytes], run: Prepared) -> None:
        """SIGKILL the run's group, namespace and cgroup (the last two are reuse-safe)."""
        run.kill()
        self._signal(proc, signal.SIGKILL)

    def _signal(self, proc: subprocess.Popen[bytes], sig: int, group: bool = True) -> None:
        with self._signal_lock:
            if not self._reaped.is_set():
                if group:
                    _killpg(proc.pid, sig)
                else:
                    try:
                        os.kill(proc.pid, sig)
                    except ProcessLookupError:
                        pass


def explain(code: int | None, cpu_seconds: float, stderr_tail: list[str], files: Files,
            limits: Limits, stop_reason: str | None = None, *, out_of_memory: bool = False,
            out_of_tasks: bool = False) -> tuple[str, bool, PythonError | None]:
    """Why a run ended, as (RunResult.reason, ok, the Python error it ended with).
    `out_of_memory`/`out_of_tasks`: its cgroup saw the OOM killer / a refused fork or thread."""
    if stop_reason is not None:
        return stop_reason, False, None
    if code == -signal.SIGXCPU or (code == -signal.SIGKILL and cpu_seconds >= limits.cpu_seconds):
        return f"stopped: it used all of its {limits.cpu_seconds} s of CPU time", False, None
    text = "\n".join(stderr_tail)
    # A SIGKILL that neither we nor the CPU limit sent is, on a robot PC, the kernel's OOM killer.
    if code != 0 and (out_of_memory or code == -signal.SIGKILL or any(m in text for m in _MEMORY_MARKERS)):
        return f"stopped: it needed more memory than its limit of {limits.memory_bytes // 2**20} MiB", False, None
    if code != 0 and out_of_tasks:
        return (f"stopped: it started more processes and threads than its limit of {limits.max_tasks}",
                False, None)
    if code == 0:
        return "finished", True, None
    error = read_error(stderr_tail, files)
    if error is not None:
        return error.reason, False, error
    if code is not None and code < 0:
        return f"killed by signal {-code} ({signal.Signals(-code).name})", False, None
    return f"exited with code {code}", False, None


def _limiter(limits: Limits) -> Callable[[], None]:
    """The child's preexec_fn. It runs between fork and exec in a copy of a threaded server,
    so it only calls setrlimit with numbers computed here, in the parent."""
    cpu = (limits.cpu_seconds, limits.cpu_seconds + 5)  # SIGXCPU at the soft limit, SIGKILL at the hard
    memory = (limits.memory_bytes, limits.memory_bytes)

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_CPU, cpu)
        resource.setrlimit(resource.RLIMIT_DATA, memory)
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # no core files of user programs on disk
    return apply


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:g} s"
    return f"{seconds / 60:g} min" if seconds < 7200 else f"{seconds / 3600:g} h"


def _killpg(pgid: int, sig: int) -> None:
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass  # the group is already empty


def _call(callback: Callable[..., None] | None, *args: Any) -> None:
    """Run a server callback; its failure must not kill the runner's threads."""
    if callback is None:
        return
    try:
        callback(*args)
    except Exception:
        log.exception("runner callback %r failed", callback)
