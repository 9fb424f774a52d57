"""The sandbox of user programs (asibot.web.sandbox) against what programs did to the plain runner:
children that leave the process group, fork bombs, shared memory, programs that never end,
writes and reads of the server's files, listening sockets, and the server's bus passwords.

Each attack is a real program run by a real ProgramRunner; processes are found from this side
by a marker in their command line (inside the sandbox pids are its own namespace's).
"""

from __future__ import annotations

import dataclasses
import os
import socket
import textwrap
import threading
import uuid
from pathlib import Path

import pytest

from asibot import access, keys, messages
from asibot.bus import Bus, open_router
from asibot.errors import RpcError
from asibot.web import sandbox as sandbox_module
from asibot.testing import ATTEMPTS, ESCAPING_PROGRAM, free_port, processes_with, wait_until
from asibot.web.runner import Limits, ProgramRunner, RunResult
from asibot.web.sandbox import ACCESS_INSIDE, NOBODY, UNCONFINED_ENV, Features, Sandbox, probe

from .test_runner import program

ROBOT = "sandbox-bot"

#: How programs may run: the full sandbox; cgroups without bubblewrap; neither (a supervisor).
MODES = {"sandbox": {}, "cgroups-only": {"bwrap": False}, "bare": {"bwrap": False, "cgroups": False}}


class Run:
    """A runner and everything it told the server."""

    def __init__(self, limits: Limits | None = None, env: dict[str, str] | None = None,
                 **sandbox: object) -> None:
        self.lines: list[tuple[str, str]] = []
        self.results: list[RunResult] = []
        self.stopped: list[str] = []
        self.lock = threading.Lock()
        self.runner = ProgramRunner(limits=limits, env=env or {}, on_output=self._output,
                                    on_exit=self.results.append, stop_robot=self.stopped.append,
                                    sandbox=Sandbox(**sandbox))

    def _output(self, stream: str, line: str) -> None:
        with self.lock:
            self.lines.append((stream, line))

    def out(self) -> list[str]:
        with self.lock:
            return [line for stream, line in self.lines if stream == "out"]

    def run(self, path: Path, timeout: float = 30.0, **start: object) -> RunResult:
        count = len(self.results)
        self.runner.start(path, ROBOT, **start)
        wait_until(lambda: len(self.results) > count, timeout=timeout, message=f"{path.name} did not end")
        return self.results[-1]


@pytest.fixture
def make():
    made: list[Run] = []

    def factory(*args: object, **kwargs: object) -> Run:
        made.append(Run(*args, **kwargs))
        return made[-1]
    yield factory
    for r in made:
        r.runner.close()




@pytest.mark.parametrize("mode", MODES)
def test_stop_ends_children_that_left_the_process_group(make, tmp_path, mode):
    r = make(**MODES[mode])
    marker = f"escape-{uuid.uuid4().hex}"
    r.runner.start(program(tmp_path, ESCAPING_PROGRAM.format(marker=marker, then="time.sleep(60)")), ROBOT)
    wait_until(lambda: "both up" in r.out(), timeout=20, message="the program's children never ran")
    assert len(processes_with(marker)) == 2
    r.runner.stop()   # what Stop and the estop call; it returns once every process is gone
    assert processes_with(marker) == [], "a child that left the process group survived Stop"
    assert r.results[-1].reason == "stopped by the user"
    assert r.stopped == [ROBOT]


@pytest.mark.parametrize("mode", MODES)
def test_a_program_that_ends_takes_its_daemons_with_it(make, tmp_path, mode):
    r = make(**MODES[mode])
    marker = f"daemon-{uuid.uuid4().hex}"
    result = r.run(program(tmp_path, ESCAPING_PROGRAM.format(marker=marker, then="")))
    assert "both up" in r.out()
    assert (result.reason, result.ok) == ("finished", True)
    assert processes_with(marker) == [], "a daemon outlived the program that started it"


@pytest.mark.parametrize("mode", ["sandbox", "cgroups-only"])
def test_a_fork_bomb_stops_at_the_process_limit(make, tmp_path, mode):
    r = make(**MODES[mode])   # the default limits
    path = program(tmp_path, """
        import os, time
        n = 0
        try:
            for _ in range(200):
                if os.fork() == 0:
                    time.sleep(60)
                    os._exit(0)
                n += 1
        finally:
            print("forked", n, flush=True)
    """)
    result = r.run(path)
    forked = int(next(line for line in r.out() if line.startswith("forked ")).split()[1])
    assert forked < Limits().max_tasks < 200
    assert result.reason == f"stopped: it started more processes and threads than its limit of {Limits().max_tasks}"
    assert r.stopped == [ROBOT]


@pytest.mark.parametrize("mode", ["sandbox", "cgroups-only"])
def test_shared_memory_counts_against_the_memory_limit(make, tmp_path, mode):
    r = make(Limits(memory_bytes=128 << 20), **MODES[mode])
    path = program(tmp_path, """
        import mmap
        m = mmap.mmap(-1, 512 << 20, flags=mmap.MAP_SHARED)   # RLIMIT_DATA does not count it
        chunk = b"x" * (1 << 20)
        for i in range(512):
            m[i << 20:(i + 1) << 20] = chunk
            if i % 64 == 63:
                print("wrote", i + 1, "MiB", flush=True)
        print("all of it")
    """)
    result = r.run(path)
    assert result.reason == "stopped: it needed more memory than its limit of 128 MiB"
    assert "all of it" not in r.out()
    assert r.stopped == [ROBOT]


@pytest.mark.parametrize("mode", MODES)
def test_a_program_that_never_ends_meets_its_time_limit(make, tmp_path, mode):
    r = make(Limits(wall_seconds=1.0), **MODES[mode])
    path = program(tmp_path, "import time\nprint('asleep', flush=True)\ntime.sleep(600)\n")
    result = r.run(path)
    assert (result.reason, result.ok) == ("stopped: it ran longer than its time limit of 1 s", False)
    assert r.stopped == [ROBOT]
    # The page's own choice, for one run.
    assert r.run(path, wall_seconds=0.5).reason == "stopped: it ran longer than its time limit of 0.5 s"
    with pytest.raises(ValueError, match="the time limit must be more than 0 s"):
        r.runner.start(path, ROBOT, wall_seconds=0)


def test_a_program_writes_only_its_scratch_reads_no_secret_and_listens_nowhere(make, tmp_path):
    secrets_folder = access.ensure_credentials(tmp_path / "access")
    folder, elsewhere = tmp_path / "user", tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "file.txt").write_text("someone else's\n")
    (folder / ".lan").mkdir(parents=True)
    (folder / ".lan" / "token").write_text("page token\n")
    (folder / "points.ini").write_text("[points]\n")
    listener = socket.create_server(("127.0.0.1", 0))   # a service of the robot PC, not the bus
    try:
        r = make(env={"ASIBOT_ROUTER": f"tcp/127.0.0.1:{free_port()}"}, access=secrets_folder)
        path = program(folder, ATTEMPTS + textwrap.dedent(f"""
            import os, socket
            def listen():
                s = socket.socket()
                s.bind(("0.0.0.0", 0))
                s.listen()
            attempt("read /etc/shadow", lambda: open("/etc/shadow").read())
            attempt("read the access folder", lambda: open({str(secrets_folder / "controller.credentials")!r}).read())
            attempt("read the page's token", lambda: open(".lan/token").read())
            attempt("read its points", lambda: open("points.ini").read())
            attempt("write its folder", lambda: open("new.txt", "w"))
            attempt("write its points", lambda: open("points.ini", "a"))
            attempt("write another user file", lambda: open({str(elsewhere / "file.txt")!r}, "a"))
            attempt("write /usr/local", lambda: open("/usr/local/x", "w"))
            attempt("write its scratch", lambda: open("/tmp/scratch.txt", "w").write("x"))
            attempt("listen", listen)
            attempt("connect elsewhere", lambda: socket.create_connection(("127.0.0.1", {listener.getsockname()[1]}), timeout=5))
            print("uid", os.getuid())
        """))
        result = r.run(path)
    finally:
        listener.close()
    assert result.ok, (result.reason, r.runner.output())
    assert r.out() == [
        "read /etc/shadow refused", "read the access folder refused", "read the page's token refused",
        "read its points allowed", "write its folder refused", "write its points refused",
        "write another user file refused", "write /usr/local refused", "write its scratch allowed",
        "listen refused", "connect elsewhere refused", f"uid {NOBODY}"]
    assert (folder / "points.ini").read_text() == "[points]\n"
    assert (elsewhere / "file.txt").read_text() == "someone else's\n"
    assert probe().landlock >= 4   # this machine's kernel (6.7 or later) refuses listen and connect


def test_the_environment_holds_no_secret_and_only_the_programs_credentials(make, tmp_path, monkeypatch):
    folder = access.ensure_credentials(tmp_path / "access")
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))    # the server runs with --access
    monkeypatch.setenv(access.ROLE_ENV, "controller")
    monkeypatch.setenv("ROBOT_API_TOKEN", "hunter2")
    r = make(env={"ASIBOT_ROUTER": "tcp/127.0.0.1:7447", "ASIBOT_ROLE": "controller", "EXTRA": "ok"})
    path = program(tmp_path / "user", """
        import os
        print(sorted(k for k in os.environ if k.startswith("ASIBOT_") or "TOKEN" in k))
        print(os.environ["ASIBOT_ACCESS"], os.environ["ASIBOT_ROLE"], os.environ["EXTRA"])
        print(sorted(os.listdir(os.environ["ASIBOT_ACCESS"])))
        print(any("hunter2" in v for v in os.environ.values()))
    """)
    result = r.run(path)
    assert result.ok, (result.reason, r.runner.output())
    assert r.out() == [
        "['ASIBOT_ACCESS', 'ASIBOT_ROBOT', 'ASIBOT_ROLE', 'ASIBOT_ROUTER']",
        f"{ACCESS_INSIDE} program ok",
        "['ca.pem', 'program.credentials']",
        "False"]


@pytest.fixture
def secured(tmp_path):
    """A router with access control on a free loopback port; the folder of its credentials."""
    folder = access.ensure_credentials(tmp_path / "access")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    session = open_router(endpoint, folder)
    try:
        yield endpoint, folder
    finally:
        session.close()


def test_under_access_a_program_calls_kinematics_and_commands_nothing(make, tmp_path, secured, monkeypatch):
    endpoint, folder = secured
    monkeypatch.setenv(access.ACCESS_ENV, str(folder))
    monkeypatch.delenv(access.ROLE_ENV, raising=False)
    with Bus("kinematics", endpoint, wait=10.0) as controller, Bus("arm_driver", endpoint, wait=10.0) as driver:
        seen: list[tuple[str, dict]] = []
        lock = threading.Lock()

        def record(key: str, payload: bytes, _received: int) -> None:
            with lock:
                seen.append((key, messages.unpack(payload)))
        driver.subscribe_raw(f"{keys.robot(ROBOT)}/**", record)
        driver.subscribe_raw(keys.ALL_HEALTH, record)
        controller.serve(keys.cart_rpc(ROBOT, "stat"), lambda req: {"point": [0.0, 0.5, 0.2, 180.0, 0.0]})
        r = make(env={"ASIBOT_ROUTER": endpoint}, access=folder)
        path = program(tmp_path / "user", f"""
            import os
            from asibot import access, keys, messages
            from asibot.bus import Bus
            from asibot.messages import ArmCommand, EStop
            R = {ROBOT!r}
            with Bus("client", wait=10.0) as bus:
                print("logged in as", access.login("client").user)
                print("stat", bus.call(keys.cart_rpc(R, "stat"), {{}}, timeout=10.0)["point"][1])
                bus.put_raw(keys.arm_command(R), messages.encode(
                    ArmCommand(mode="velocity", values=[9.0], controller="program")))
                bus.put_raw(keys.estop(R), messages.encode(EStop(engaged=False, reason="program release")))
                bus.put_raw("health/program/done", messages.encode(EStop(engaged=False, reason="done")))
            os.environ["ASIBOT_ROLE"] = "controller"   # no controller.credentials to go with it
            print("as a controller it would be", access.login("client").user)
            try:
                open({str(folder / "controller.credentials")!r}).read()
                print("read the controller's password")
            except OSError:
                print("the controller's password is out of reach")
        """)
        result = r.run(path, timeout=60)
        assert result.ok, (result.reason, r.runner.output())
        assert r.out() == ["logged in as program", "stat 0.5", "as a controller it would be anonymous",
                           "the controller's password is out of reach"]
        # The refused command and estop went first on the same way as the permitted health put:
        # once that arrived, they never will.
        wait_until(lambda: any(k == "health/program/done" for k, _ in list(seen)), timeout=10.0,
                   message="the program's permitted put never arrived")
        with lock:
            assert [k for k, _ in seen if k in (keys.arm_command(ROBOT), keys.estop(ROBOT))] == []
        assert any("refuses publishing rb/sandbox-bot/arm/command" in line for _, line in r.runner.output())


def test_what_a_bare_machine_gets_is_said():
    bare = Sandbox(bwrap=False, cgroups=False, landlock=False).describe()
    assert bare.startswith("programs run with rlimits only; missing: bubblewrap (apt-get install bubblewrap")
    assert "subreaper supervisor" in bare and "programs may listen on sockets" in bare
    full = Sandbox().describe()
    assert "missing" not in full, full   # this machine (and CI) has every wall


@pytest.fixture
def no_bubblewrap(monkeypatch):
    """A machine where bubblewrap is wanted but cannot make a sandbox (Docker's default profile)."""
    monkeypatch.setattr(sandbox_module, "probe", lambda *a: Features(None, False, 0, None, frozenset(), {}))
    monkeypatch.delenv(UNCONFINED_ENV, raising=False)


def test_a_program_is_refused_where_bubblewrap_cannot_work_unless_the_deployment_says_so(
        make, tmp_path, no_bubblewrap, monkeypatch):
    path = program(tmp_path, "print('ran')\n")
    r = make()
    assert r.runner.sandbox.confinement()["runs"] is False
    with pytest.raises(RpcError, match=f"Programs cannot run here: bubblewrap .*{UNCONFINED_ENV}=1") as refused:
        r.runner.start(path, ROBOT)
    assert refused.value.code == "not_allowed" and not r.runner.running()
    monkeypatch.setenv(UNCONFINED_ENV, "1")
    allowed = make()
    said = allowed.runner.sandbox.confinement()
    assert (said["runs"], said["confined"]) == (True, False) and UNCONFINED_ENV in said["text"]
    result = allowed.run(path)
    assert result.ok and allowed.out() == ["ran"], (result.reason, allowed.runner.output())


def test_the_page_is_told_which_walls_programs_get():
    said = Sandbox().confinement()
    assert (said["runs"], said["confined"]) == (True, True)
    assert said["text"].startswith("Programs run confined: bubblewrap, no network but the bus,"), said


def test_a_program_of_a_users_own_server_sees_no_subfolder_of_its_folder(make, tmp_path, monkeypatch):
    """The image's web runs as a user, its folder /data: the AsTeRICS bridge's HTTP token lives
    in asterics/ there, nav's maps in nav/; the program reads its own top-level files only."""
    real = probe()
    # The user's own server (root's copies the folder's top-level files for nobody instead).
    monkeypatch.setattr(sandbox_module, "probe", lambda *a: dataclasses.replace(real, as_nobody=False))
    folder = tmp_path / "user"
    (folder / "asterics").mkdir(parents=True)
    (folder / "asterics" / "token").write_text("bridge token\n")
    (folder / "points.ini").write_text("[points]\n")
    r = make()
    path = program(folder, """
        import os
        for name in ("points.ini", "asterics/token"):
            try:
                print(name, open(name).read().strip())
            except OSError:
                print(name, "refused")
        print(sorted(os.listdir("asterics")))
    """)
    result = r.run(path)
    assert result.ok, (result.reason, r.runner.output())
    assert r.out() == ["points.ini [points]", "asterics/token refused", "[]"]


def test_the_program_role_may_call_kinematics_and_nav_and_nothing_else():
    may = access.may
    assert may("program", "query", keys.cart_rpc(ROBOT, "movl"))
    assert may("program", "query", keys.nav_rpc(ROBOT, "goto"))
    assert may("program", "declare_subscriber", keys.arm_state(ROBOT))
    assert not may("program", "put", keys.arm_command(ROBOT))
    assert not may("program", "put", keys.base_cmd_vel(ROBOT))
    assert not may("program", "put", keys.estop(ROBOT))
    assert not may("program", "query", keys.driver_rpc(ROBOT, "reset_fault"))
    assert not may("program", "query", keys.cart_rpc(ROBOT, "pointer"))
    assert not may("program", "declare_queryable", keys.cart_rpc(ROBOT, "movl"))
    assert not may("program", "liveliness_token", keys.controller_alive(ROBOT, "x"))
    assert not may("program", "query", keys.tasks_rpc("launch"))
    assert "program" in access.ROLES


@pytest.mark.parametrize("mode", ["cgroups-only", "bare"])
def test_without_bubblewrap_roots_server_still_runs_programs_as_nobody(make, tmp_path, mode):
    """The Docker image's case: no sandbox, but an interpreter nobody may run (not one under
    /root, as this machine's venv is, where the program stays root: the next test)."""
    system_python = "/usr/bin/python3"
    r = make(**MODES[mode])
    r.runner.python = system_python
    folder = tmp_path / "user"
    (folder / "points.ini").parent.mkdir(parents=True)
    (folder / "points.ini").write_text("[points]\n")
    path = program(folder, ATTEMPTS + textwrap.dedent("""
        import os
        print("uid", os.getuid())
        attempt("read /etc/shadow", lambda: open("/etc/shadow").read())
        attempt("read its points", lambda: open("points.ini").read())
        attempt("write its points", lambda: open("points.ini", "a"))
        print(undefined)
    """).lstrip("\n"))
    result = r.run(path)
    assert r.out() == [f"uid {NOBODY}", "read /etc/shadow refused", "read its points allowed",
                       "write its points refused"]
    assert result.reason == "failed with an error on line 12: NameError: name 'undefined' is not defined"
    assert (folder / "points.ini").read_text() == "[points]\n"


def test_an_interpreter_nobody_cannot_reach_keeps_the_servers_user_and_says_so(make, tmp_path, caplog):
    caplog.set_level("INFO", logger="asibot.web.sandbox")
    r = make(bwrap=False, cgroups=False)
    result = r.run(program(tmp_path, "import os\nprint('uid', os.getuid())\n"))
    assert result.ok
    if Sandbox._nobody_can_run(r.runner.python):
        assert r.out() == [f"uid {NOBODY}"]
    else:   # this machine: the venv's interpreter is under /root (pyenv)
        assert r.out() == [f"uid {os.geteuid()}"]
        assert "programs run as the server's user: nobody cannot reach" in caplog.text


def test_a_credentials_folder_from_before_the_program_role_gets_it(tmp_path):
    folder = access.ensure_credentials(tmp_path / "access")
    dictionary = folder / access.DICTIONARY
    (folder / "program.credentials").unlink()   # as a folder made before the role existed
    dictionary.write_text("".join(line + "\n" for line in dictionary.read_text().splitlines()
                                  if not line.startswith("program:")))
    before = {p.name: p.read_text() for p in folder.iterdir() if p.name != access.DICTIONARY}
    access.ensure_credentials(folder)
    login = (folder / "program.credentials").read_text().strip()
    assert login.startswith("program:") and login in dictionary.read_text().splitlines()
    assert oct((folder / "program.credentials").stat().st_mode & 0o777) == "0o600"
    assert {p.name: p.read_text() for p in folder.iterdir() if p.name in before} == before
    access.ensure_credentials(folder)   # once
    assert dictionary.read_text().count("program:") == 1
