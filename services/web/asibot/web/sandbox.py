"""The walls around a user's program: what it may see, write, reach and start, and how it ends.

The program runner (asibot.web.runner) runs what a user typed on the Program tab. The web
server runs as root on a robot PC and holds the access folder (every role's password, the
CA's key), so a program must get only what a program needs:

- **Its own processes, all of them ended at Stop.** A pid namespace (bubblewrap) whose
  init takes every process with it, and a cgroup per run that Stop kills whole
  (`cgroup.kill` on v2, kill-until-empty on v1): a child that calls `setsid()` or
  double-forks leaves the process group, never the namespace or the cgroup.
- **A count of processes and threads** (the pids cgroup: RLIMIT_NPROC does nothing for root)
  and **memory that counts shared mappings** (the memory cgroup: RLIMIT_DATA does not see a
  shared anonymous mmap), besides the rlimits the runner always sets.
- **An unprivileged user, a read-only machine**: bubblewrap binds `/` read-only, hides
  `/root`, `/home`, `/run` and the access folder behind empty tmpfs, gives a fresh sized
  tmpfs as `/tmp` (its scratch folder, also `$HOME`), gives it its own folder read-only
  (for `nobody`, a copy of its visible files: never `.lan`, with the page's token), and runs
  the program as `nobody` (root's server) or as the server's own user in a user namespace.
- **No listening sockets, and the bus as the only peer, with a program's rights**: the bus is
  the router's programs socket (ROUTER_INSIDE), where every session has the `program` role's
  rights whatever the router's profile (asibot.access); bubblewrap gives the program a network
  of its own, and a Landlock ruleset (Linux >= 6.7) refuses every TCP bind and connect, and
  (Linux >= 6.12) signals and abstract unix sockets out of the sandbox.
- **Its own bus identity**: an environment built from an allow list, never the server's
  (no ASIBOT_ACCESS, no secrets), and under access control a folder holding only
  `program.credentials`.

Each wall is used when the machine has it and said in one log line when it has not
(`Sandbox.describe()`); docs/sandbox.md has what each kind of deployment gets. Without
bubblewrap and cgroups a small supervisor (`SUPERVISOR`, a child subreaper) still ends every
descendant at Stop.
"""

from __future__ import annotations

import ctypes
import functools
import itertools
import json
import logging
import os
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from asibot.access import PROGRAM_LINK, PROGRAM_ROUTER_ENV, program_endpoint, program_socket
from asibot.bus import router_endpoint
from asibot.errors import RpcError

log = logging.getLogger(__name__)

NOBODY = 65534
#: Where the program's own credentials appear inside the sandbox.
ACCESS_INSIDE = "/run/asibot/access"
#: Where the router's programs socket (asibot.access.program_endpoint) appears inside it: the
#: program's only way to the bus, with the program role's rights on every profile.
ROUTER_INSIDE = "/run/asibot/router.sock"
#: The server's environment variables a program may see (values copied when set); the rest,
#: ASIBOT_ACCESS and ASIBOT_ROLE among them, it never gets.
ENV_ALLOWED = ("LANG", "LC_ALL", "LC_CTYPE", "TZ", "MUJOCO_GL", "ASIBOT_ROUTER")
#: Names the server's own `env` may not pass on either.
ENV_SECRET = re.compile(r"^ASIBOT_(ACCESS|ROLE)$|TOKEN|SECRET|PASSWORD|KEY", re.I)
_CGROUP_PREFIX = "asibot-program-"
#: Set to 1, programs run where bubblewrap cannot make a sandbox, with the weaker walls of
#: docs/sandbox.md ("What each machine gives"); unset, they are refused there. A deployment
#: says so knowingly: a program is text from a web page.
UNCONFINED_ENV = "ASIBOT_PROGRAMS_UNCONFINED"
#: Bigger files of the program's folder are left out of its copy (a program needs its
#: points and modules, not a video someone put there).
FOLDER_FILE_MAX = 16 << 20
_counter = itertools.count()

# Landlock (include/uapi/linux/landlock.h); the syscall numbers are the same on every
# architecture that has it but alpha and ia64.
_LL_CREATE, _LL_ADD, _LL_RESTRICT = 444, 445, 446
_LL_VERSION = 1
_LL_RULE_NET_PORT = 2
_LL_BIND_TCP, _LL_CONNECT_TCP = 1, 2
_LL_SCOPE_ABSTRACT_UNIX, _LL_SCOPE_SIGNAL = 1, 2
#: libc, loaded here: a child between fork and exec must not dlopen (another thread may have
#: held the loader's lock at fork).
_libc = ctypes.CDLL(None, use_errno=True)


# ------------------------------------------------------------------------- what we have

@dataclass(frozen=True)
class Features:
    """What this machine lets the runner use; found once by `probe()`."""

    bwrap: str | None          # a bubblewrap that ran a sandbox here
    as_nobody: bool            # the server is root: the program runs as nobody (setpriv)
    landlock: int              # Landlock ABI (0: none); >= 4 has network rules
    cgroup_v2: str | None      # our own v2 cgroup folder, when we may make children in it
    cgroup_v2_controllers: frozenset[str]
    cgroup_v1: dict[str, str]  # controller -> our own v1 cgroup folder we may make children in

    def has(self, controller: str) -> bool:
        return controller in self.cgroup_v2_controllers or controller in self.cgroup_v1

    def can_kill_cgroup(self) -> bool:
        return bool(self.cgroup_v2 or self.cgroup_v1)

    def describe(self) -> str:
        """One sentence per wall: what programs get here, and what is missing and why."""
        got, missing = [], []
        if self.bwrap:
            got.append("bubblewrap (own pid namespace, read-only system, scratch /tmp, "
                       + ("user nobody" if self.as_nobody else "own user namespace") + ")")
        else:
            missing.append("bubblewrap (apt-get install bubblewrap; in Docker it also needs "
                           "unshare and mount: see docs/sandbox.md): programs see the server's "
                           "files, as nobody only if the server is root and nobody can run the "
                           "interpreter")
        for controller, what in (("memory", "memory cgroup (shared memory counted)"),
                                 ("pids", "pids cgroup (process count)")):
            (got if self.has(controller) else missing).append(what)
        if self.can_kill_cgroup():
            got.append("Stop by cgroup")
        elif not self.bwrap:
            missing.append("cgroups and pid namespace: Stop ends descendants through a subreaper "
                           "supervisor" + ("" if self.landlock >= 6 else " the program could kill"))
        if self.landlock >= 4:
            got.append("Landlock network rules (no listening, bus only)")
        else:
            missing.append(f"Landlock network rules (ABI {self.landlock}, needs >= 4: Linux 6.7): "
                           "programs may listen on sockets and connect anywhere")
        text = "programs run with " + ", ".join(got) if got else "programs run with rlimits only"
        if missing:
            text += "; missing: " + "; ".join(missing)
        return text


def landlock_abi() -> int:
    try:
        abi = _libc.syscall(_LL_CREATE, None, ctypes.c_size_t(0), ctypes.c_uint32(_LL_VERSION))
    except AttributeError:
        return 0
    return max(int(abi), 0)


def _mounts(fstype: str) -> list[tuple[str, set[str]]]:
    """(mount point, super options) of every mount of `fstype`, from /proc/self/mountinfo."""
    found: list[tuple[str, set[str]]] = []
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return found
    for line in lines:
        left, _, right = line.partition(" - ")
        fields, tail = left.split(), right.split()
        if len(fields) >= 5 and len(tail) >= 3 and tail[0] == fstype:
            found.append((fields[4].replace("\\040", " "), set(tail[2].split(","))))
    return found


def _own_cgroups() -> dict[str, str]:
    """hierarchy -> our path in it: '' for v2, else the comma-joined controllers."""
    own = {}
    try:
        for line in Path("/proc/self/cgroup").read_text().splitlines():
            _, controllers, path = line.split(":", 2)
            own[controllers] = path
    except (OSError, ValueError):
        pass
    return own


def _can_make_child(folder: Path) -> bool:
    probe = folder / f"{_CGROUP_PREFIX}probe-{os.getpid()}"
    try:
        probe.mkdir()
        probe.rmdir()
        return True
    except OSError:
        return False


def _cgroup_v2() -> tuple[str | None, frozenset[str]]:
    own = _own_cgroups().get("")
    mounts = _mounts("cgroup2")
    if own is None or not mounts:
        return None, frozenset()
    folder = Path(mounts[0][0]) / own.lstrip("/")
    if not _can_make_child(folder):
        return None, frozenset()
    _remove_stale(folder)
    wanted = {"memory", "pids"}
    try:
        available = set((folder / "cgroup.controllers").read_text().split())
        enabled = set((folder / "cgroup.subtree_control").read_text().split())
        missing = sorted((wanted & available) - enabled)
        procs = [int(p) for p in (folder / "cgroup.procs").read_text().split()]
        if missing and own != "/" and all(_ours(p) for p in procs):
            # cgroup v2 lets a cgroup with processes in it (ours: a container's, a systemd
            # service's with Delegate=yes) give no controller to its children, so the server
            # and its children move to a leaf of their own first; never someone else's.
            leaf = folder / "asibot-server"
            leaf.mkdir(exist_ok=True)
            for pid in procs:
                try:
                    (leaf / "cgroup.procs").write_text(str(pid))
                except OSError:
                    pass
        for c in missing:
            try:
                (folder / "cgroup.subtree_control").write_text(f"+{c}")
                enabled.add(c)
            except OSError as exc:
                log.info("cannot enable the %s controller in %s (%s): programs do without it",
                         c, folder, exc.strerror)
    except OSError:
        enabled = set()
    return str(folder), frozenset(enabled & wanted)


def _ours(pid: int) -> bool:
    """Whether `pid` is this process or one of its descendants."""
    me = os.getpid()
    while pid > 1:
        if pid == me:
            return True
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            return False
    return pid == me


def _remove_stale(parent: Path) -> None:
    """Remove the empty cgroups of runs of a server that died (their processes are gone)."""
    for child in parent.glob(f"{_CGROUP_PREFIX}*-*"):
        owner = child.name[len(_CGROUP_PREFIX):].split("-")[0]
        if owner.isdigit() and int(owner) != os.getpid() and not Path(f"/proc/{owner}").exists():
            try:
                child.rmdir()
            except OSError:
                pass


def _cgroup_v1() -> dict[str, str]:
    own = _own_cgroups()
    found: dict[str, str] = {}
    for point, options in _mounts("cgroup"):
        for controller in ("memory", "pids"):
            if controller in options and controller not in found:
                path = next((p for names, p in own.items() if controller in names.split(",")), None)
                if path is not None and _can_make_child(Path(point) / path.lstrip("/")):
                    found[controller] = str(Path(point) / path.lstrip("/"))
                    _remove_stale(Path(found[controller]))
    return found


@functools.lru_cache(maxsize=None)
def _asibot_roots() -> list[Path]:
    """The folders `asibot` is imported from: one per package of the namespace (libs/common,
    services/web, ... in a checkout; site-packages once installed)."""
    import asibot
    return [Path(p).resolve().parent for p in asibot.__path__]


def _bwrap_has(bwrap: str, option: str) -> bool:
    """Whether this bubblewrap knows `option` (--disable-userns: 0.8, Debian 12)."""
    try:
        return option in subprocess.run([bwrap, "--help"], capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.TimeoutExpired):
        return False


def _bwrap_fails(bwrap: str, as_nobody: bool) -> str | None:
    """Why a sandbox does not start here (bubblewrap's own words), or None when it does. Docker's
    default seccomp profile refuses unshare and mount; its masks over /proc refuse a new proc."""
    sandbox = Sandbox.__new__(Sandbox)
    sandbox.features = Features(bwrap, as_nobody, 0, None, frozenset(), {})
    sandbox.access, sandbox.hide = None, ()
    argv = sandbox._bwrap_argv(Path("/"), [], None, 1 << 20) + ["/bin/true"]
    try:
        done = subprocess.run(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, timeout=10)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return str(exc)
    if done.returncode == 0:
        return None
    said = done.stderr.decode(errors="replace").strip().splitlines()
    return said[-1] if said else f"exit status {done.returncode}"


@functools.lru_cache(maxsize=None)
def probe(use_bwrap: bool = True, use_cgroups: bool = True, use_landlock: bool = True) -> Features:
    """What this machine offers, tried once per process (a sandbox started, a cgroup made)."""
    as_nobody = os.geteuid() == 0
    bwrap = shutil.which("bwrap") if use_bwrap else None
    if bwrap and as_nobody and not shutil.which("setpriv"):
        log.warning("setpriv (util-linux) is missing: programs would run as root; not using bubblewrap")
        bwrap = None
    why = _bwrap_fails(bwrap, as_nobody) if bwrap else None
    if bwrap and why:
        log.warning("bubblewrap cannot make a sandbox here (%s): programs are refused unless %s=1; in "
                    "Docker the web service needs the security_opt of compose.yaml (docs/sandbox.md)",
                    why, UNCONFINED_ENV)
        bwrap = None
    v2, v2c = _cgroup_v2() if use_cgroups else (None, frozenset())
    v1 = {c: p for c, p in _cgroup_v1().items() if c not in v2c} if use_cgroups else {}
    return Features(bwrap=bwrap, as_nobody=as_nobody and bool(bwrap),
                    landlock=landlock_abi() if use_landlock else 0,
                    cgroup_v2=v2, cgroup_v2_controllers=v2c, cgroup_v1=v1)


# ------------------------------------------------------------------------- one run's cgroups

class Cgroups:
    """The cgroups of one run (v2 and/or v1 hierarchies): limits, join, kill, wait, remove."""

    def __init__(self, features: Features, memory_bytes: int, max_tasks: int) -> None:
        name = f"{_CGROUP_PREFIX}{os.getpid()}-{next(_counter)}"
        self.folders: list[Path] = []
        self.v2: Path | None = None
        self.memory: Path | None = None   # the folder whose memory files say about the OOM killer
        self.pids: Path | None = None
        self.join_fds: list[int] = []
        try:
            if features.cgroup_v2:
                self.v2 = self._make(Path(features.cgroup_v2) / name)
                if self.v2 and "memory" in features.cgroup_v2_controllers:
                    _write(self.v2 / "memory.max", memory_bytes)
                    _write(self.v2 / "memory.swap.max", 0, missing_ok=True)
                    self.memory = self.v2
                if self.v2 and "pids" in features.cgroup_v2_controllers:
                    _write(self.v2 / "pids.max", max_tasks)
                    self.pids = self.v2
            for controller, parent in features.cgroup_v1.items():
                folder = self._make(Path(parent) / name)
                if folder is None:
                    continue
                if controller == "memory":
                    _write(folder / "memory.limit_in_bytes", memory_bytes)
                    _write(folder / "memory.memsw.limit_in_bytes", memory_bytes, missing_ok=True)
                    self.memory = folder
                elif controller == "pids":
                    _write(folder / "pids.max", max_tasks)
                    self.pids = folder
            # Opened here, written in the child before exec ("0": the writer itself).
            self.join_fds = [os.open(f / "cgroup.procs", os.O_WRONLY | os.O_CLOEXEC) for f in self.folders]
        except BaseException:
            self.remove()
            raise

    def _make(self, folder: Path) -> Path | None:
        try:
            folder.mkdir()
        except OSError as exc:
            log.warning("cannot make the cgroup %s (%s): this run goes without it", folder, exc.strerror)
            return None
        self.folders.append(folder)
        return folder

    def pids_inside(self) -> list[int]:
        for folder in self.folders:
            try:
                return [int(p) for p in (folder / "cgroup.procs").read_text().split()]
            except OSError:
                continue
        return []

    def kill(self) -> None:
        """SIGKILL every process in the run's cgroups (atomic with v2's cgroup.kill)."""
        if self.v2 is not None and (self.v2 / "cgroup.kill").exists():
            try:
                _write(self.v2 / "cgroup.kill", 1)
                return
            except OSError:
                pass
        for pid in self.pids_inside():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def wait_empty(self, timeout: float) -> bool:
        """Kill until nothing is left (a process may fork until its SIGKILL lands), up to `timeout` s."""
        deadline = time.monotonic() + timeout
        while self.pids_inside():
            if time.monotonic() > deadline:
                return False
            self.kill()
            time.sleep(0.002)
        return True

    def counter(self, filename: str, field: str) -> int:
        """A field of a flat-keyed cgroup file (memory.events oom_kill, pids.events max)."""
        folder = self.memory if filename.startswith("memory") else self.pids
        if folder is None:
            return 0
        for name in (filename, "memory.oom_control") if filename.startswith("memory") else (filename,):
            try:
                for line in (folder / name).read_text().splitlines():
                    key, _, value = line.partition(" ")
                    if key == field:
                        return int(value)
            except (OSError, ValueError):
                continue
        return 0

    def remove(self) -> None:
        for fd in self.join_fds:
            os.close(fd)
        self.join_fds = []
        for folder in self.folders:
            for _ in range(50):   # a killed process leaves its cgroup a moment after it is reaped
                try:
                    folder.rmdir()
                    break
                except FileNotFoundError:
                    break
                except OSError:
                    time.sleep(0.01)
            else:
                log.warning("could not remove the cgroup %s", folder)
        self.folders = []


def _write(path: Path, value: int, missing_ok: bool = False) -> None:
    """Write a cgroup file; `missing_ok`: an optional one (swap accounting may be off)."""
    try:
        path.write_text(str(value))
    except OSError:
        if not missing_ok:
            raise


# ------------------------------------------------------------------------- Landlock

def landlock_rules(abi: int) -> tuple[bytes, list[bytes], int] | None:
    """The ruleset attribute (and port rules: none) for `landlock_apply`, built in the parent:
    every TCP bind and connect refused, since the bus is the router's programs socket."""
    if abi < 4:
        return None
    scoped = (_LL_SCOPE_ABSTRACT_UNIX | _LL_SCOPE_SIGNAL) if abi >= 6 else 0
    net = _LL_BIND_TCP | _LL_CONNECT_TCP
    attr = struct.pack("QQQ", 0, net, scoped) if abi >= 6 else struct.pack("QQ", 0, net)
    return attr, [], abi


def landlock_apply(prepared: tuple[bytes, list[bytes], int]) -> None:
    """Restrict this process and all it starts (runs in the child before exec)."""
    attr, rules, _ = prepared
    libc = _libc
    fd = libc.syscall(_LL_CREATE, attr, ctypes.c_size_t(len(attr)), ctypes.c_uint32(0))
    if fd < 0:
        raise OSError(ctypes.get_errno(), "landlock_create_ruleset")
    try:
        for rule in rules:
            if libc.syscall(_LL_ADD, fd, _LL_RULE_NET_PORT, rule, ctypes.c_uint32(0)) < 0:
                raise OSError(ctypes.get_errno(), "landlock_add_rule")
        libc.prctl(38, 1, 0, 0, 0)   # PR_SET_NO_NEW_PRIVS: Landlock needs it without CAP_SYS_ADMIN
        if libc.syscall(_LL_RESTRICT, fd, ctypes.c_uint32(0)) < 0:
            raise OSError(ctypes.get_errno(), "landlock_restrict_self")
    finally:
        os.close(fd)


# ------------------------------------------------------------------------- the supervisor

#: Without a pid namespace or a cgroup, this runs first: a child subreaper (orphans of the
#: program become its children, whatever they call), which on SIGTERM or when the program
#: ends kills every descendant it has and ends as the program did. argv: landlock-json python args...
SUPERVISOR = r"""
import ctypes, json, os, signal, struct, sys
libc = ctypes.CDLL(None, use_errno=True)
libc.prctl(36, 1, 0, 0, 0)
me = os.getpid()
def children(pid):
    try:
        out = []
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                out += [int(p) for p in f.read().split()]
        return out
    except OSError:
        return []
def kill_all():
    while True:
        seen, todo = [], children(me)
        while todo:
            pid = todo.pop()
            seen.append(pid)
            todo += children(pid)
        for pid in seen:
            try: os.kill(pid, signal.SIGKILL)
            except OSError: pass
        try:
            while os.waitpid(-1, os.WNOHANG)[0]: pass
        except ChildProcessError:
            return
        if not seen: return
signal.signal(signal.SIGTERM, lambda *a: kill_all())
rules = json.loads(sys.argv[1])
program = os.fork()
if program == 0:
    try:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        if rules:
            attr, ports = bytes.fromhex(rules[0]), [bytes.fromhex(r) for r in rules[1]]
            fd = libc.syscall(444, attr, ctypes.c_size_t(len(attr)), ctypes.c_uint32(0))
            for rule in ports: libc.syscall(445, fd, 2, rule, ctypes.c_uint32(0))
            libc.prctl(38, 1, 0, 0, 0)
            if fd < 0 or libc.syscall(446, fd, ctypes.c_uint32(0)) < 0:
                print("the sandbox could not apply its Landlock rules", file=sys.stderr)
                os._exit(126)
            os.close(fd)
        os.execv(sys.argv[2], sys.argv[2:])
    finally:
        os._exit(127)
status = 0
while True:
    try:
        pid, st = os.waitpid(-1, 0)
    except InterruptedError:
        continue
    except ChildProcessError:
        break
    if pid == program:
        status = st
        kill_all()
        break
code = os.waitstatus_to_exitcode(status)
if code < 0:
    signal.signal(-code, signal.SIG_DFL)
    os.kill(me, -code)
os._exit(code & 0xFF)
"""


# ------------------------------------------------------------------------- a prepared run

@dataclass
class Prepared:
    """One run, ready for Popen; `close()` after it ended removes what it made."""

    argv: list[str]
    env: dict[str, str]
    pass_fds: tuple[int, ...]
    preexec: Callable[[], None]
    cgroups: Cgroups | None
    info_fd: int | None             # bwrap's --info-fd, read end (the namespace init's pid)
    info_w: int | None              # its write end, the child's; closed here once it started
    scratch: Path | None            # what the runner made and removes afterwards
    bwrap: bool
    supervised: bool
    cwd: Path = Path("/")            # where it runs (a copy of its folder when run as nobody)
    program: Path = Path("/")       # the file Python runs (tracebacks name it)
    as_nobody: bool = False
    init_pid: int | None = None
    init_pidfd: int | None = None

    def started(self, timeout: float = 10.0) -> None:
        """Learn the pid namespace's init from bwrap (it writes once its sandbox is made)."""
        if self.info_w is not None:
            os.close(self.info_w)
            self.info_w = None
        if self.info_fd is None:
            return
        data = b""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not _readable(self.info_fd, deadline - time.monotonic()):
                break
            chunk = os.read(self.info_fd, 4096)
            if not chunk:
                break
            data += chunk
            try:
                self.init_pid = int(json.loads(data)["child-pid"])
                break
            except (ValueError, KeyError):
                continue
        os.close(self.info_fd)
        self.info_fd = None
        if self.init_pid is not None:
            try:
                self.init_pidfd = os.pidfd_open(self.init_pid)
            except OSError:
                self.init_pidfd = None

    def kill(self) -> None:
        """SIGKILL every process of the run, however it detached (its group is the caller's)."""
        if self.cgroups is not None:
            self.cgroups.kill()
        if self.init_pidfd is not None:
            try:
                signal.pidfd_send_signal(self.init_pidfd, signal.SIGKILL)
            except ProcessLookupError:
                pass

    def wait_gone(self, timeout: float = 5.0) -> bool:
        """Until no process of the run is left: the cgroup empty, the namespace's init gone."""
        deadline = time.monotonic() + timeout
        ok = True
        if self.init_pidfd is not None:
            ok = _readable(self.init_pidfd, timeout)   # a pidfd is readable once its process ended
        if self.cgroups is not None:
            ok = self.cgroups.wait_empty(max(0.0, deadline - time.monotonic())) and ok
        return ok

    def close(self) -> None:
        if self.info_w is not None:
            os.close(self.info_w)
            self.info_w = None
        if self.info_fd is not None:
            os.close(self.info_fd)
            self.info_fd = None
        if self.init_pidfd is not None:
            os.close(self.init_pidfd)
            self.init_pidfd = None
        if self.cgroups is not None:
            self.cgroups.remove()
        if self.scratch is not None:
            shutil.rmtree(self.scratch, ignore_errors=True)
            self.scratch = None


def _readable(fd: int, timeout: float) -> bool:
    """poll, not select: a busy server's descriptors may be numbered past select's 1024."""
    poller = select.poll()
    poller.register(fd, select.POLLIN)
    return bool(poller.poll(max(0.0, timeout) * 1000))


# ------------------------------------------------------------------------- the sandbox

class Sandbox:
    """How programs run on this machine: `prepare()` one run; `describe()` says what they get."""

    def __init__(self, *, bwrap: bool = True, cgroups: bool = True, landlock: bool = True,
                 access: Path | str | None = None, hide: tuple[Path, ...] = (),
                 programs: str | None = None) -> None:
        """`access`: the server's access folder (default: $ASIBOT_ACCESS when set), whose
        `program.credentials` alone a program gets; `hide`: more folders it must not see;
        `programs`: where the router listens for programs (default: asibot.access.program_endpoint
        of this server's router), the program's only way to the bus."""
        self.features = probe(bwrap, cgroups, landlock)
        # Without bubblewrap a program reads what the server reads and has the server's network
        # (docs/sandbox.md): only a deployment that says so runs it. `bwrap=False` is the
        # caller's own choice (the tests and benches of the other walls).
        self.unconfined_allowed = not bwrap or os.environ.get(UNCONFINED_ENV, "") == "1"
        env_access = os.environ.get("ASIBOT_ACCESS")
        self.access = Path(access) if access else (Path(env_access) if env_access else None)
        self.hide = tuple(Path(h) for h in hide)
        self.programs = programs
        self._reported = False

    def router_socket(self, server_env: dict[str, str]) -> Path:
        """The programs socket of the router the server passes on (`ASIBOT_ROUTER` in its `env`),
        else of its own. Where no router listens (yet), a program still runs, and its bus says
        that nothing answers there: it never gets another way to the bus."""
        router = server_env.get("ASIBOT_ROUTER") or router_endpoint()
        sock = program_socket(self.programs or program_endpoint(router))
        if not sock.is_socket():
            log.warning("the router does not listen for programs at %s: programs reach no bus until it "
                        "does (restart `asibot up`, or set %s to where it listens)", sock, PROGRAM_ROUTER_ENV)
        return sock

    def describe(self) -> str:
        return self.features.describe()

    def confinement(self) -> dict:
        """What the page says of programs here: whether they run (`runs`), in bubblewrap
        (`confined`), and one sentence for the user (`text`), with what to do when they do not."""
        f = self.features
        if f.bwrap:
            walls = ["bubblewrap", "no network but the bus", "read-only system and folder",
                     "their own scratch /tmp", "user nobody" if f.as_nobody else "their own user namespace"]
            if f.has("memory"):
                walls.append("memory limit")
            if f.has("pids"):
                walls.append("process limit")
            return {"runs": True, "confined": True, "text": "Programs run confined: " + ", ".join(walls) + "."}
        if self.unconfined_allowed:
            return {"runs": True, "confined": False,
                    "text": f"Programs run without bubblewrap ({UNCONFINED_ENV}=1): they can read the web "
                            "service's files and reach its network (docs/sandbox.md)."}
        return {"runs": False, "confined": False, "text": self.refusal()}

    def refusal(self) -> str:
        return ("Programs cannot run here: bubblewrap cannot make a sandbox on this machine. Give it what "
                "it needs (docs/sandbox.md: in Docker, the web service's security_opt in compose.yaml), or "
                f"set {UNCONFINED_ENV}=1 for the web service to run programs without it knowingly.")

    def report(self) -> None:
        """Log what programs get, once (at the first run)."""
        if not self._reported:
            self._reported = True
            text = self.describe()
            log.log(logging.WARNING if "missing:" in text else logging.INFO, "%s", text)

    # -- one run -------------------------------------------------------------------------

    def environment(self, robot: str, server_env: dict[str, str], credentials: bool,
                    router: Path | None = None) -> dict[str, str]:
        """The program's environment, from an allow list: never a copy of the server's. Its
        router is the programs socket (`router`, seen at ROUTER_INSIDE in bubblewrap)."""
        env = {k: os.environ[k] for k in ENV_ALLOWED if k in os.environ}
        env.update({k: v for k, v in server_env.items() if not ENV_SECRET.search(k)})
        if router is not None:
            env["ASIBOT_ROUTER"] = f"{PROGRAM_LINK}/{ROUTER_INSIDE if self.features.bwrap else router}"
        env.update({"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": "/tmp", "TMPDIR": "/tmp",
                    "PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1", "ASIBOT_ROBOT": robot})
        env.setdefault("LANG", "C.UTF-8")
        if not self.features.bwrap:
            env["HOME"] = env["TMPDIR"] = tempfile.gettempdir()
        if credentials:
            env["ASIBOT_ACCESS"], env["ASIBOT_ROLE"] = ACCESS_INSIDE, "program"
        return env

    def _program_credentials(self, made: Path) -> Path | None:
        """A private folder in `made` with a copy of `program.credentials` (and `ca.pem`), or None."""
        if self.access is None or not self.features.bwrap:
            return None
        source = self.access / "program.credentials"
        if not source.is_file():
            log.warning("%s is missing: programs log in as the anonymous reader and move nothing. "
                        "Run `ASIBOT_ACCESS=%s python -m asibot.access` on the robot and restart "
                        "the router", source, self.access)
            return None
        folder = made / "access"
        folder.mkdir()
        for name in ("program.credentials", "ca.pem"):
            if (self.access / name).is_file():
                shutil.copyfile(self.access / name, folder / name)
                os.chmod(folder / name, 0o400)
        if self.features.as_nobody:
            for p in [folder, *folder.iterdir()]:
                os.chown(p, NOBODY, NOBODY)
        os.chmod(folder, 0o500)
        return folder

    def _folder_copy(self, folder: Path, made: Path) -> Path:
        """What `nobody` reads as the program's folder: a copy of its visible top-level files.

        The user's folder is the server's, 0700 (userdata), so nobody could not even enter it;
        a copy (bound read-only at the same path, so tracebacks name the user's own file) is
        readable, leaves hidden entries (.lan: the page's token and key) out, and changes nothing
        of the user's.
        """
        copy = made / "folder"
        copy.mkdir()
        for p in sorted(folder.iterdir()):
            try:
                if p.name.startswith(".") or not p.is_file() or p.stat().st_size > FOLDER_FILE_MAX:
                    continue
                shutil.copyfile(p, copy / p.name)
                os.chmod(copy / p.name, 0o444)
            except OSError as exc:
                log.warning("could not copy %s for the program (%s)", p, exc.strerror)
        os.chmod(copy, 0o555)
        return copy

    def _needed(self, python: str) -> list[Path]:
        """What the interpreter and `asibot` need readable: the venv, the base install, the source."""
        paths = {Path(sys.prefix), Path(sys.base_prefix), Path(python).absolute().parent.parent,
                 Path(os.path.realpath(python)).parent.parent, *_asibot_roots()}
        return sorted(p for p in paths if p.is_dir() and p != Path("/"))

    def _bwrap_argv(self, folder: Path, needed: list[Path], credentials: Path | None,
                    scratch_bytes: int, folder_source: Path | None = None,
                    router: Path | None = None) -> list[str]:
        f = self.features
        # A network of its own (only its own loopback): the router's programs socket, bound
        # in below, is its one way out, on any kernel (Landlock's network rules need 6.7).
        argv = [f.bwrap or "bwrap", "--unshare-pid", "--unshare-ipc", "--unshare-uts", "--unshare-net",
                "--unshare-cgroup-try", "--die-with-parent", "--new-session"]
        if not f.as_nobody:
            argv += ["--unshare-user"] + (["--disable-userns"] if _bwrap_has(argv[0], "--disable-userns") else [])
        argv += ["--ro-bind", "/", "/", "--proc", "/proc", "--dev", "/dev"]
        tmpfs = [m for m in ("/root", "/home", "/run", "/var/tmp") if os.path.isdir(m)]
        for masked in tmpfs:
            argv += ["--tmpfs", masked]
        # The scratch folder, and shared memory (Zenoh's shm segments): both sized, both
        # counted by the memory cgroup.
        argv += ["--perms", "01777", "--size", str(scratch_bytes), "--tmpfs", "/tmp",
                 "--perms", "01777", "--size", str(scratch_bytes), "--tmpfs", "/dev/shm"]
        for path in needed:
            argv += ["--ro-bind", str(path), str(path)]
        for secret in [self.access, *self.hide]:
            if secret is not None and secret.is_dir() and secret.resolve() not in (Path("/"), folder):
                argv += ["--tmpfs", str(secret.resolve())]
        argv += ["--ro-bind", str(folder_source or folder), str(folder)]
        # Its hidden entries and its subfolders are hidden, as the copy for nobody leaves them out:
        # .lan holds the page's token and key, asterics/ the bridge's HTTP token (the same folder
        # in the image), nav/ the maps a program reaches through nav's verbs; .trash and .versions
        # are not its business.
        try:
            hidden = [] if folder_source or folder == Path("/") else sorted(   # "/": the probe's, no folder
                p for p in folder.iterdir() if p.name.startswith(".") or (p.is_dir() and not p.is_symlink()))
        except OSError:
            hidden = []
        for p in hidden:
            argv += (["--tmpfs", str(p)] if p.is_dir() and not p.is_symlink() else ["--ro-bind", "/dev/null", str(p)])
        if credentials is not None:
            argv += ["--ro-bind", str(credentials), ACCESS_INSIDE]
        if router is not None and not router.is_socket():
            router = None    # no router listens there yet: the program's bus finds nothing
        if router is not None:
            argv += ["--bind", str(router), ROUTER_INSIDE]
        # bubblewrap makes the folders above a bind in a tmpfs with the modes of the real ones
        # (/tmp/pytest-of-root, /root: 0700), which nobody could not enter.
        tmpfs.append("/tmp")
        made: list[str] = []
        for dest in [*needed, folder, *([Path(ACCESS_INSIDE)] if credentials else []),
                     *([Path(ROUTER_INSIDE)] if router else [])]:
            for parent in reversed(dest.parents):
                if any(parent.is_relative_to(t) and str(parent) != t for t in tmpfs) and parent != dest \
                        and str(parent) not in made:
                    made.append(str(parent))
                    argv += ["--chmod", "0755", str(parent)]
        argv += ["--chdir", str(folder)]
        if f.as_nobody:
            argv += ["--", shutil.which("setpriv") or "setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}",
                     "--clear-groups", "--inh-caps=-all", "--bounding-set=-all", "--no-new-privs"]
        else:
            argv += ["--"]
        return argv

    def prepare(self, python: str, path: Path, robot: str, server_env: dict[str, str], *,
                memory_bytes: int, max_tasks: int, scratch_bytes: int,
                rlimits: Callable[[], None]) -> Prepared:
        """Everything for Popen to start `python -u path robot` in the sandbox, cwd its folder.
        RpcError `not_allowed` where bubblewrap cannot work and nobody allowed running without it."""
        self.report()
        if not self.features.bwrap and not self.unconfined_allowed:
            raise RpcError("not_allowed", self.refusal())
        router = self.router_socket(server_env)
        f = self.features
        folder = path.parent
        # Without bubblewrap, root's server still runs the program as nobody when nobody can
        # run the interpreter (not one under /root), on a copy of its folder.
        drop = os.geteuid() == 0 and not f.bwrap and self._nobody_can_run(python)
        made = Path(tempfile.mkdtemp(prefix="asibot-program-")) if f.bwrap or drop else None
        cgroups = None
        try:
            credentials = self._program_credentials(made) if made else None
            folder_source = self._folder_copy(folder, made) if made and (f.as_nobody or drop) else None
            cgroups = Cgroups(f, memory_bytes, max_tasks) if f.can_kill_cgroup() else None
        except BaseException:
            if cgroups is not None:
                cgroups.remove()
            if made is not None:
                shutil.rmtree(made, ignore_errors=True)
            raise
        cwd = folder
        if drop and made is not None and folder_source is not None:
            os.chmod(made, 0o755)
            cwd, path = folder_source, folder_source / path.name
        env = self.environment(robot, server_env, credentials is not None, router)
        rules = landlock_rules(f.landlock)
        program = [python, "-u", str(path), robot]
        info_r = info_w = None
        supervised = False
        if f.bwrap:
            info_r, info_w = os.pipe()
            os.set_inheritable(info_w, True)
            argv = self._bwrap_argv(folder, self._needed(python), credentials, scratch_bytes, folder_source,
                                    router)
            argv[1:1] = ["--info-fd", str(info_w)]
            argv += program
            landlock_in_child = rules
        elif cgroups is None:
            supervised = True   # no namespace, no cgroup: a subreaper ends what leaves the group
            packed = [rules[0].hex(), [r.hex() for r in rules[1]], rules[2]] if rules else []
            argv = [python, "-I", "-S", "-c", SUPERVISOR, json.dumps(packed), *program]
            landlock_in_child = None
        else:
            argv = program
            landlock_in_child = rules
        join = list(cgroups.join_fds) if cgroups else []

        def preexec() -> None:
            for fd in join:
                os.write(fd, b"0")   # into the run's cgroups before anything of the program runs
            rlimits()
            if drop:
                os.setgroups([])
                os.setresgid(NOBODY, NOBODY, NOBODY)
                os.setresuid(NOBODY, NOBODY, NOBODY)
            if landlock_in_child is not None:
                landlock_apply(landlock_in_child)

        return Prepared(argv=argv, env=env, pass_fds=(info_w,) if info_w is not None else (),
                        preexec=preexec, cgroups=cgroups, info_fd=info_r, info_w=info_w,
                        scratch=made, bwrap=bool(f.bwrap), supervised=supervised, cwd=cwd,
                        program=path, as_nobody=f.as_nobody or drop)

    @staticmethod
    def _nobody_can_run(python: str) -> bool:
        """Whether every folder down to the interpreter, the venv and `asibot` lets others in."""
        for target in (Path(os.path.realpath(python)), Path(python).absolute(), *_asibot_roots()):
            for p in [target, *target.parents]:
                try:
                    mode = p.stat().st_mode
                except OSError:
                    return False
                if not mode & (0o001 if p != target else 0o004):
                    log.info("programs run as the server's user: nobody cannot reach %s (%s)", target, p)
                    return False
        return True


def exit_code(code: int | None, prepared: Prepared) -> int | None:
    """The program's exit code in subprocess' convention: bubblewrap reports a program
    killed by signal N as 128 + N, which the page's sentences need as -N."""
    if prepared.bwrap and code is not None and 128 < code <= 128 + 64:
        return -(code - 128)
    return code

