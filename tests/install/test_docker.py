"""The image builds from a clean copy of the repository and `docker compose` runs the sim
profile with it, as an installer would: every service shows in `asibot status` from the host,
the simulated arm moves, the page loads; a program run by the page is in bubblewrap and each
escape of docs/sandbox.md fails; the recorder writes into a fresh checkout's recordings/, owned
by someone other than the image's user, without a chown; every service has a healthcheck and
becomes healthy; `docker compose down` leaves no anonymous volume; then it all comes down.

On its own Docker engine (docs/docker.md: vfs storage, no bridge, host networking), from base
images made on this machine (docker/make-local-bases). Needs root; CI runs as root."""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import yaml

from asibot.cli import compose
from asibot.testing import ATTEMPTS, free_port, wait_until

ROOT = Path(__file__).resolve().parents[2]
PROJECT = "asibot-test"
IMAGE = "asibot:test"
STAGES = ("web", "python")      # the Dockerfile's build stages
#: The machine's download proxy's certificate authority, for pip and npm inside the build.
MACHINE_CA = Path("/etc/ssl/certs/ca-certificates.crt")

# Building the image is minutes of downloads and vfs copies (docs/docker.md has the figures).
pytestmark = [pytest.mark.slow, pytest.mark.docker, pytest.mark.alone, pytest.mark.timeout(2400)]


def run(argv: list[str], env: dict[str, str], timeout: float, **kw) -> subprocess.CompletedProcess:
    done = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=timeout, **kw)
    assert done.returncode == 0, f"{' '.join(argv)} failed ({done.returncode}):\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


#: The engine's storage, kept between runs as a CI keeps its Docker layer cache: the base
#: images and the locked packages' layer are built once; each run rebuilds what its commit
#: changed. Emptied when it outgrows CACHE_LIMIT (vfs keeps every layer whole).
CACHE = Path(os.environ.get("ASIBOT_DOCKER_CACHE", "/var/cache/asibot/docker-test"))
CACHE_LIMIT = 40e9


def cache_size(folder: Path) -> int:
    done = subprocess.run(["du", "-sb", str(folder)], capture_output=True, text=True)
    return int(done.stdout.split()[0]) if done.returncode == 0 else 0


def storage_driver() -> str:
    """overlay2 where the kernel can mount an overlay on the cache's disk, else vfs. vfs copies the
    whole image for every container and every layer (minutes for the profile's twelve containers);
    overlay2 shares them. Docker checks the same, but a data root it has used keeps its driver."""
    if os.environ.get("ASIBOT_DOCKER_STORAGE"):
        return os.environ["ASIBOT_DOCKER_STORAGE"]
    probe = Path(tempfile.mkdtemp(dir=CACHE.parent))
    try:
        for name in ("lower", "upper", "work", "mounted"):
            (probe / name).mkdir()
        mounted = subprocess.run(
            ["mount", "-t", "overlay", "overlay", "-o",
             f"lowerdir={probe / 'lower'},upperdir={probe / 'upper'},workdir={probe / 'work'}", str(probe / "mounted")],
            capture_output=True).returncode == 0
        if mounted:
            subprocess.run(["umount", str(probe / "mounted")], capture_output=True)
        return "overlay2" if mounted else "vfs"
    finally:
        shutil.rmtree(probe, ignore_errors=True)


@pytest.fixture(scope="module")
def engine(tmp_path_factory: pytest.TempPathFactory):
    """A Docker engine of the test's own, with the recipe of docs/docker.md; its environment."""
    if os.geteuid() != 0:
        pytest.skip("the image test runs its own Docker engine, which needs root (CI runs as root)")
    assert shutil.which("dockerd"), "the image test needs Docker's engine: ./bootstrap installs docker.io as root"
    CACHE.mkdir(parents=True, exist_ok=True)
    hold = open(CACHE.with_suffix(".lock"), "w")
    fcntl.flock(hold, fcntl.LOCK_EX)            # one engine on the cache at a time
    driver = storage_driver()
    # A data root keeps the driver it was made with. Not CACHE/vfs: an older version of this
    # test used CACHE itself as vfs's data root, whose layers are in CACHE/vfs.
    root = CACHE / f"root-{driver}"
    if cache_size(CACHE) > CACHE_LIMIT:
        shutil.rmtree(CACHE)
    root.mkdir(parents=True, exist_ok=True)
    folder = Path(tmp_path_factory.mktemp("docker", numbered=True))
    sock = folder / "docker.sock"
    log = open(folder / "dockerd.log", "w")
    daemon = subprocess.Popen(
        ["dockerd", f"--storage-driver={driver}", "--iptables=false", "--ip6tables=false", "--bridge=none",
         "--data-root", str(root), "--exec-root", str(folder / "exec"),
         "--pidfile", str(folder / "docker.pid"), "-H", f"unix://{sock}"],
        stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    env = {**os.environ, "DOCKER_HOST": f"unix://{sock}"}
    try:
        wait_until(lambda: subprocess.run(["docker", "info"], env=env, capture_output=True).returncode == 0,
                   60, interval=0.5, message=lambda: (folder / "dockerd.log").read_text()[-2000:])
        print(f"\nDocker engine: {driver} storage")
        # a run cut short leaves its containers; they would hold the old image's layers
        run(["docker", "container", "prune", "-f"], env, 600)
        yield env
    finally:
        daemon.send_signal(signal.SIGTERM)
        try:
            daemon.wait(60)
        except subprocess.TimeoutExpired:
            daemon.kill()
        log.close()
        # The engine leaves its network namespace (and overlay2 its layers' mounts) mounted; then
        # the folder goes.
        for mount in reversed(Path("/proc/mounts").read_text().splitlines()):
            if mount.split()[1].startswith((str(folder), str(root))):
                subprocess.run(["umount", "-l", mount.split()[1]], capture_output=True)
        shutil.rmtree(folder, ignore_errors=True)
        hold.close()


@pytest.fixture(scope="module")
def image(engine: dict[str, str], tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The image, built from what git tracks (a clean checkout), and the figures of its build."""
    context = Path(tmp_path_factory.mktemp("context"))
    files = run(["git", "ls-files", "-co", "--exclude-standard"], os.environ, 60, cwd=ROOT).stdout.splitlines()
    for name in files:
        if (ROOT / name).is_file():
            (context / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, context / name)
    if MACHINE_CA.exists():
        shutil.copy(MACHINE_CA, context / "docker" / "extra-ca.crt")
    started = time.monotonic()
    run([str(ROOT / "docker" / "make-local-bases")], engine, 900)
    bases = time.monotonic() - started
    build = ["docker", "build", "--network", "host", "-q", "--build-arg", "BASE=local/debian:bookworm",
             "--build-arg", "NODE=local/node:host"]
    # The stages by name too: an untagged stage is pruned below with the older builds' layers,
    # and with it the cache of its downloads.
    for stage in STAGES:
        run([*build, "--target", stage, "-t", f"{IMAGE}-{stage}", str(context)], engine, 1800)
    run([*build, "-t", IMAGE, str(context)], engine, 1800)
    run(["docker", "image", "prune", "-f"], engine, 600)
    built = time.monotonic() - started - bases
    size = int(run(["docker", "image", "inspect", "-f", "{{.Size}}", IMAGE], engine, 60).stdout)
    print(f"\nimage {IMAGE}: {size / 1e6:.0f} MB; base images {bases:.0f} s, build {built:.0f} s")
    return {"size": str(size)}


def host_network(document: dict, ports: dict[str, int]) -> dict:
    """compose.yaml as it is but for the network: every service on the host's network, bound to
    127.0.0.1 on the test's own ports (the engine here has no bridge: docs/docker.md). A whole
    file, not an override: Compose adds an override's ports to the original's, and host
    networking refuses published ports."""
    router = f"tcp/127.0.0.1:{ports['router']}"
    ours = {"ASIBOT_ROUTER": router, "ASIBOT_WEB_HOST": "127.0.0.1", "ASIBOT_WEB_PORT": str(ports["web"]),
            "ASIBOT_ASTERICS_PORT": str(ports["asterics"]), "ASIBOT_ASTERICS_HTTP_PORT": str(ports["asterics_http"])}
    services = {}
    for name, body in document["services"].items():
        body = {k: v for k, v in body.items() if k not in ("ports", "build", "network_mode")}
        body["environment"] = {**body.get("environment", {}), **ours,
                               **({"ASIBOT_ROUTER_LISTEN": router} if name == "router" else {})}
        services[name] = {**body, "image": IMAGE, "network_mode": "host"}
    return {**document, "services": services}


#: The owner of the test's fresh checkout: a user who is not the image's asibot (uid 1000).
CHECKOUT_UID = 1234


@pytest.fixture(scope="module")
def stack(image: dict[str, str], engine: dict[str, str], tmp_path_factory: pytest.TempPathFactory) -> dict:
    """The sim profile up with compose as a user runs it: the user's files in the named volume,
    the recordings in the checkout's own recordings/ (0755, its owner's, no chown), loopback ports."""
    folder = Path(tmp_path_factory.mktemp("checkout"))
    ports = {"router": free_port(), "web": free_port(), "asterics": free_port(), "asterics_http": free_port()}
    document = yaml.safe_load((ROOT / "compose.yaml").read_text())
    (folder / "compose.yaml").write_text(yaml.safe_dump(host_network(document, ports)))
    # What compose.yaml names beside itself (the web service's seccomp profile), as a checkout has it.
    shutil.copytree(ROOT / "docker", folder / "docker", ignore=shutil.ignore_patterns("extra-ca.crt"))
    recordings = folder / "recordings"
    recordings.mkdir(mode=0o755)
    os.chown(recordings, CHECKOUT_UID, CHECKOUT_UID)
    env = {**engine, "ASIBOT_RECORDINGS": str(recordings), "COMPOSE_PROJECT_NAME": PROJECT}
    env.pop("ASIBOT_DATA_VOLUME", None)
    # Compose v2, the Docker CLI's plugin, as a user types it (docs/docker.md).
    up = ["docker", "compose", "-f", str(folder / "compose.yaml"), "--profile", "sim"]
    assert run(["docker", "compose", "version", "--short"], env, 60).stdout.startswith("2."), \
        "the image test needs Compose v2: ./bootstrap installs it"
    remove_volumes(env)                   # a run cut short leaves the last run's user files
    volumes = set(run(["docker", "volume", "ls", "-q"], env, 60).stdout.split())
    host = {**os.environ, "ASIBOT_ROUTER": f"tcp/127.0.0.1:{ports['router']}"}
    try:
        run([*up, "up", "-d", "--no-build"], env, 600)
        # Each service of the profile as `asibot status` names it: its program and its robot. Not
        # the recorder, which has a test of its own: one that cannot write must fail that test,
        # not hide what the others check.
        wanted = {(spec.command[2].removeprefix("asibot."), spec.command[spec.command.index("--robot") + 1]
                   if "--robot" in spec.command else None)
                  for spec in compose.select(compose.load(ROOT / "compose.yaml"), "sim")
                  if spec.name not in ("router", "recorder")}

        def missing() -> set | None:
            done = subprocess.run([sys.executable, "-m", "asibot.cli.main", "status", "--json"], env=host,
                                  capture_output=True, text=True, timeout=30)
            if done.returncode != 0:
                return None
            seen = {(s["service"], s["instance"]) for s in json.loads(done.stdout)["services"]}
            return {(name, robot) for name, robot in wanted
                    if not any(n == name and (robot is None or i == robot) for n, i in seen)}
        # Up to 8 min: each container imports MuJoCo, Pinocchio or OpenCV from vfs layers, and on a
        # loaded CI a run that passed in one stop took over the 4 min this waited before.
        wait_until(lambda: missing() == set(), 480, interval=2,
                   message=lambda: f"not in `asibot status`: {missing()}; {logs(up, env)}")
        yield {"up": up, "env": env, "ports": ports, "recordings": recordings, "host": host, "volumes": volumes}
    finally:
        subprocess.run([*up, "down", "--volumes", "--timeout", "20"], env=env, capture_output=True, timeout=300)
        remove_volumes(env)


def remove_volumes(env: dict[str, str]) -> None:
    """The project's named volumes (the user's files of a test run)."""
    names = [v for v in run(["docker", "volume", "ls", "-q"], env, 60).stdout.split() if v.startswith(f"{PROJECT}_")]
    if names:
        run(["docker", "volume", "rm", *names], env, 120)


def web(port: int, method: str, path: str, body: dict | None = None) -> tuple[int, dict]:
    """One call of the page's API as the page makes it, with the session token the page carries."""
    base = f"http://127.0.0.1:{port}"
    with urllib.request.urlopen(base + "/", timeout=30) as page:
        token = re.search(r'<meta name="asibot-session" content="([^"]+)">', page.read().decode()).group(1)
    request = urllib.request.Request(base + path, method=method, data=None if body is None else json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json", "X-Asibot-Session": token})
    try:
        with urllib.request.urlopen(request, timeout=30) as reply:
            return reply.status, json.loads(reply.read() or b"null")
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"null")


def test_the_image_runs_the_sim_profile_with_compose(stack: dict) -> None:
    ports = stack["ports"]
    moved = run([sys.executable, "-c", MOVE_THE_ARM], stack["host"], 120).stdout
    before, after = json.loads(moved)
    assert abs(after[0] - before[0] - 10.0) < 0.5, (before, after)

    page = urllib.request.urlopen(f"http://127.0.0.1:{ports['web']}/", timeout=30)
    assert page.status == 200 and "<title>" in page.read().decode()
    script = urllib.request.urlopen(f"http://127.0.0.1:{ports['web']}/static/vendor/three.js", timeout=30)
    assert script.status == 200       # the npm bundle the front-end stage made


#: A program that tries each wall of docs/sandbox.md from inside `docker compose up`, and a few
#: things it may do (its own file, its scratch), so that a program that cannot run at all fails too.
ESCAPES = "import ctypes, os, socket\n" + ATTEMPTS + """

def user_namespace():
    if ctypes.CDLL(None, use_errno=True).unshare(0x10000000) != 0:   # CLONE_NEWUSER
        raise OSError(ctypes.get_errno(), "unshare")

def the_server():
    seen = [open(f"/proc/{p}/cmdline", "rb").read() for p in os.listdir("/proc") if p.isdigit()]
    if not any(b"asibot.web" in c for c in seen):
        raise OSError("no such process here")

attempt("read its own file", lambda: open(__file__).read())
attempt("write its scratch", lambda: open("/tmp/scratch.txt", "w").write("x"))
attempt("connect to the page", lambda: socket.create_connection(("127.0.0.1", WEB_PORT), timeout=5))
attempt("connect to the router's TCP port", lambda: socket.create_connection(("127.0.0.1", ROUTER_PORT), timeout=5))
attempt("connect to the bridge", lambda: socket.create_connection(("127.0.0.1", BRIDGE_PORT), timeout=5))
attempt("read the bridge's HTTP token", lambda: open("/data/asterics/token").read())
attempt("write its folder", lambda: open("/data/escaped.txt", "w"))
attempt("write the system", lambda: open("/opt/asibot/escaped.txt", "w"))
attempt("make a user namespace", user_namespace)
attempt("see the web server", the_server)
print("secrets", sorted(k for k in os.environ if "ACCESS" in k or "TOKEN" in k or "KEY" in k))
"""


def test_a_program_in_the_image_runs_in_bubblewrap_and_every_escape_fails(stack: dict) -> None:
    ports, up, env = stack["ports"], stack["up"], stack["env"]
    status, answer = web(ports["web"], "GET", "/api/run")
    assert status == 200 and answer.get("confinement", {}).get("confined") is True, \
        f"the page says programs are not confined: {answer.get('confinement')}; {logs(up, env)}"
    assert answer["confinement"]["text"].startswith("Programs run confined: bubblewrap")
    # The bridge's token is there to be stolen: the web and the bridge share the user's volume.
    run([*up, "exec", "-T", "web", "test", "-s", "/data/asterics/token"], env, 60)
    text = ESCAPES.replace("WEB_PORT", str(ports["web"])).replace("ROUTER_PORT", str(ports["router"])) \
        .replace("BRIDGE_PORT", str(ports["asterics"]))
    status, answer = web(ports["web"], "PUT", "/api/programs/escapes", {"text": text})
    assert status == 200, answer
    status, answer = web(ports["web"], "POST", "/api/programs/escapes/run", {"robot": "asibot-sim"})
    assert status == 200, answer
    wait_until(lambda: not web(ports["web"], "GET", "/api/run")[1]["running"], 120, interval=1,
               message="the program did not end")
    done = web(ports["web"], "GET", "/api/run")[1]
    lines = [line for stream, line in done["output"] if stream == "out"]
    assert lines == [
        "read its own file allowed", "write its scratch allowed",
        "connect to the page refused", "connect to the router's TCP port refused", "connect to the bridge refused",
        "read the bridge's HTTP token refused", "write its folder refused", "write the system refused",
        "make a user namespace refused", "see the web server refused", "secrets []"], done


def test_the_recorder_writes_into_a_fresh_checkouts_recordings(stack: dict) -> None:
    recordings, up, env = stack["recordings"], stack["up"], stack["env"]
    wait_until(lambda: any(recordings.glob("*.mcap")), 120, interval=1,
               message=lambda: f"the recorder wrote nothing into {recordings}: "
                               f"{run([*up, 'logs', '--tail', '5', '--no-color', 'recorder'], env, 60).stdout}")
    for f in recordings.glob("*.mcap"):
        st = f.stat()
        # The checkout's owner's, and private: a recording holds the user's voice and pictures.
        assert (st.st_uid, st.st_mode & 0o777) == (CHECKOUT_UID, 0o600), (f, st.st_uid, oct(st.st_mode))
    assert recordings.stat().st_mode & 0o777 == 0o700
    recorder = run([*up, "ps", "-q", "recorder"], env, 60).stdout.split()
    assert run(["docker", "inspect", "-f", "{{.RestartCount}}", *recorder], env, 60).stdout.split() == ["0"]


def test_every_service_has_a_healthcheck_and_becomes_healthy(stack: dict) -> None:
    up, env = stack["up"], stack["env"]
    containers = run([*up, "ps", "-q"], env, 60).stdout.split()

    def states() -> dict[str, str | None]:
        found = json.loads(run(["docker", "inspect", *containers], env, 60).stdout)
        return {c["Name"].lstrip("/"): (c["State"].get("Health") or {}).get("Status") if c["Config"].get("Healthcheck")
                else None for c in found}
    assert len(containers) == len(states()) >= 10
    assert [name for name, state in states().items() if state is None] == [], "containers without a healthcheck"
    # The first check runs an interval (15 s) after the start; a sim service imports for longer.
    wait_until(lambda: set(states().values()) == {"healthy"}, 300, interval=3,
               message=lambda: f"not healthy: {states()}; {logs(up, env)}")


def test_compose_down_leaves_no_anonymous_volume(stack: dict) -> None:
    """Last in the file: it takes the stack down, as a user does (without --volumes)."""
    up, env = stack["up"], stack["env"]
    run([*up, "down", "--timeout", "20"], env, 300)
    left = set(run(["docker", "volume", "ls", "-q"], env, 60).stdout.split()) - stack["volumes"]
    assert sorted(left) == [f"{PROJECT}_asibot-data", f"{PROJECT}_asibot-router"], \
        "`docker compose down` should leave only the named volumes, the user's files"


def logs(up: list[str], env: dict[str, str]) -> str:
    return subprocess.run([*up, "logs", "--tail", "15", "--no-color"], env=env, capture_output=True,
                          text=True, timeout=60).stdout[-6000:]


#: From the host: turn the simulated arm's first joint by 10 degrees, print the joints before and
#: after. `wait` ends once the arm is within 0.5 degrees of the motion's end, or 3 s after the plan's
#: end (in containers on a loaded machine the joint was 1.8 degrees behind at the plan's end): the
#: joint is read until it is within the check's 0.5 degrees, 30 s at most.
MOVE_THE_ARM = """
import json, time
from asibot.client import CartesianClient
arm = CartesianClient("asibot-sim", timeout=30)
before = arm.state()["joints"]
arm.relj([10, 0, 0, 0, 0], speed=0.5)
arm.wait(timeout=60)
deadline = time.monotonic() + 30
after = arm.state()["joints"]
while abs(after[0] - before[0] - 10.0) >= 0.5 and time.monotonic() < deadline:
    time.sleep(0.2)
    after = arm.state()["joints"]
print(json.dumps([before, after]))
"""
