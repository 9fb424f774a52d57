"""Navigation end to end: `asibot up` with the apartment sim, perception and nav, driven by the
user's NavClient and `asibot nav`, judged by the sim's ground truth (never nav's own estimate)."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from asibot import keys
from asibot.bus import Bus
from asibot.safety import ownership
from asibot import messages as m
from asibot.client import NavClient
from asibot.errors import RpcError
from asibot.testing import Inbox, Stack, Stream, wait_until

ROOT = Path(__file__).resolve().parents[2]
ROBOT = "pioneer-sim"
XY_TOL, YAW_TOL = 0.25, 0.25
BOX = (2.8, 1.6)           # on the way from the start to the kitchen, not on the map
BOX_HALF = 0.2

pytestmark = pytest.mark.slow


class Truth:
    """The sim's ground-truth pose, kept as a trace; beside it what nav believed and said, for
    a failure's message."""

    def __init__(self, bus) -> None:
        self._lock = threading.Lock()
        self.trace: list[tuple[float, float, float]] = []
        self.times: list[float] = []
        self.belief: list[tuple[float, float, float, bool]] = []     # (time, x, y, localised)
        self.said: list[str] = []                                    # nav's status texts, as they changed
        bus.subscribe(keys.sim_truth(ROBOT), m.Pose2D, self._on)
        bus.subscribe(keys.nav_pose(ROBOT), m.NavPose, self._on_belief)
        bus.subscribe(keys.nav_status(ROBOT), m.NavStatus, self._on_status)

    def _on(self, p: m.Pose2D) -> None:
        with self._lock:
            self.trace.append((p.x, p.y, p.theta))
            self.times.append(time.monotonic())

    def _on_belief(self, p: m.NavPose) -> None:
        with self._lock:
            self.belief.append((time.monotonic(), p.x, p.y, p.localised))

    def _on_status(self, s: m.NavStatus) -> None:
        with self._lock:
            # "driving to fridge, 3.2 m left" changes every tick: a change of words counts
            if not self.said or re.sub(r"[\d.]+", "#", self.said[-1]) != re.sub(r"[\d.]+", "#", s.text):
                self.said.append(s.text)

    def drift(self) -> str:
        """When nav's belief first strayed more than 0.3 m from the truth, and the worst."""
        with self._lock:
            times, trace, belief = np.array(self.times), np.array(self.trace), list(self.belief)
        if len(times) == 0 or not belief:
            return "no truth or no belief to compare"
        t0, worst, first = belief[0][0], (0.0, 0.0), None
        for t, x, y, localised in belief:
            i = min(int(np.searchsorted(times, t)), len(times) - 1)
            err = math.hypot(x - trace[i, 0], y - trace[i, 1])
            if err > 0.3 and first is None:
                first = f"{t - t0:.1f} s after the start, at ({trace[i, 0]:.2f}, {trace[i, 1]:.2f}), localised: {localised}"
            worst = max(worst, (err, t - t0))
        return (f"nav's belief first strayed over 0.3 m {first or 'never'}; the worst: {worst[0]:.2f} m, "
                f"{worst[1]:.1f} s after the start")

    @property
    def pose(self) -> tuple[float, float, float]:
        wait_until(lambda: self.trace, 10, message="no ground truth from the sim")
        with self._lock:
            return self.trace[-1]

    def mark(self) -> int:
        with self._lock:
            return len(self.trace)

    def since(self, mark: int) -> np.ndarray:
        with self._lock:
            return np.array(self.trace[mark:])


@pytest.fixture(scope="module")
def stack(tmp_path_factory):
    folder = tmp_path_factory.mktemp("nav")
    s = Stack(folder, "sim", ["nav-pioneer-sim"], ROOT / "compose.yaml")
    old = os.environ.get("ASIBOT_ROUTER")
    os.environ["ASIBOT_ROUTER"] = s.endpoint       # the user's client finds this stack's router
    try:
        s.wait_alive("sim/pioneer-sim", "perception/pioneer-sim", "nav/pioneer-sim", timeout=90)
        s.truth = Truth(s.bus)
        s.events = Inbox()
        s.bus.subscribe(keys.events(ROBOT), m.Event, s.events)
        s.bumps = Inbox()
        s.bus.subscribe(keys.base_bumpers(ROBOT), m.Bumpers, s.bumps)
        s.base = NavClient(ROBOT, timeout=10.0)
        wait_until(lambda: s.base.status()["localised"], 30, interval=0.2, message="nav never localised")
        yield s
        s.base.close()
    finally:
        s.stop()
        if old is None:
            os.environ.pop("ASIBOT_ROUTER", None)
        else:
            os.environ["ASIBOT_ROUTER"] = old


def on_goal(pose, goal) -> tuple[bool, str]:
    d = math.hypot(pose[0] - goal[0], pose[1] - goal[1])
    a = abs(math.remainder(pose[2] - goal[2], 2 * math.pi))
    return d <= XY_TOL and a <= YAW_TOL, f"{d:.3f} m and {math.degrees(a):.1f} deg from the goal"


def bumped(stack) -> bool:
    return any(any(b.front) or any(b.rear) for b in stack.bumps.all())


def motion(stack, seconds: float = 0.5) -> tuple[float, float]:
    """How far the truth moved (m, rad) over the last `seconds` (20 Hz)."""
    t = stack.truth.since(max(0, stack.truth.mark() - int(seconds * 20)))
    if len(t) < 5:
        return math.inf, math.inf
    return float(max(np.ptp(t[:, 0]), np.ptp(t[:, 1]))), float(np.ptp(np.unwrap(t[:, 2])))


def standing_still(stack, seconds: float = 0.5) -> bool:
    """The truth moved less than 5 mm and 0.5 deg over the last `seconds`."""
    d, a = motion(stack, seconds)
    return d < 0.005 and a < 0.01


def where(stack) -> str:
    """What the sim and nav say now, and what nav said last: for a failure's message (a goal
    that fails in a loaded CI run is understood from this alone)."""
    try:
        believed, status = stack.base.pose(), stack.base.status()
        nav = f"nav believes ({believed[0]:.2f}, {believed[1]:.2f}, {believed[2]:.2f}), localised: {status['localised']}"
    except Exception as exc:          # a diagnosis must not hide the failure
        nav = f"nav did not answer ({exc})"
    x, y, th = stack.truth.pose
    events = "\n  ".join(f"{e.code}: {e.text}" for e in stack.events.all()[-8:])
    said = "\n  ".join(stack.truth.said[-20:])
    return (f"the sim says the robot is at ({x:.2f}, {y:.2f}, {th:.2f}); {nav}\n{stack.truth.drift()}\n"
            f"last events:\n  {events}\nnav said last:\n  {said}")


def reach(stack, gid: int, timeout: float = 150) -> dict:
    """The result of goal `gid` once it ended; a failure says where the robot was."""
    try:
        return stack.base.wait(gid, timeout=timeout)
    except RpcError as exc:          # Timeout too
        raise AssertionError(f"{exc}\n{where(stack)}") from None


def test_primitives_end_where_they_should(stack):
    """At the start, in the open: forward 1 m, left 90 deg, right 90 deg, back 0.5 m."""
    x0, y0, _ = stack.truth.pose
    stack.base.drive(1.0)
    assert stack.base.wait()["text"] == "forward: done"
    x1, y1, th1 = stack.truth.pose
    assert abs(math.hypot(x1 - x0, y1 - y0) - 1.0) < 0.05
    stack.base.turn(90)
    stack.base.wait()
    _, _, th2 = stack.truth.pose
    assert abs(math.degrees(math.remainder(th2 - th1, 2 * math.pi)) - 90) < 5
    stack.base.primitive("turn right 90")
    assert stack.base.wait()["text"] == "turn right 90: done"
    x3, y3, th3 = stack.truth.pose
    assert abs(math.degrees(math.remainder(th3 - th2, 2 * math.pi)) + 90) < 5
    stack.base.drive(-0.5)
    assert stack.base.wait()["text"] == "backward: done"
    x4, y4, _ = stack.truth.pose
    assert abs(math.hypot(x4 - x3, y4 - y3) - 0.5) < 0.05
    assert not bumped(stack)


@pytest.mark.timeout(300)
def test_goto_fridge_past_a_box_that_is_not_on_the_map(stack):
    stack.bus.call(keys.driver_rpc(ROBOT, "set_object_pose"), {"name": "box", "pos": [*BOX, BOX_HALF]}, timeout=5)
    fridge = stack.base.places()["fridge"]
    start = stack.truth.mark()
    gid = stack.base.goto("fridge")
    result = reach(stack, gid)
    assert result["state"] == "succeeded" and result["text"] == "arrived at fridge"
    ok, how = on_goal(stack.truth.pose, fridge)
    assert ok, how
    trace = stack.truth.since(start)
    # the robot's centre kept its half-width plus the box's half-size away from the box's centre
    gap = np.hypot(trace[:, 0] - BOX[0], trace[:, 1] - BOX[1]).min()
    assert gap > BOX_HALF + 0.25, f"passed {gap:.2f} m from the box's centre"
    moved = stack.bus.call(keys.driver_rpc(ROBOT, "object_pose"), {"name": "box"}, timeout=5)["pos"]
    assert math.hypot(moved[0] - BOX[0], moved[1] - BOX[1]) < 0.01, "the box was pushed"
    assert not bumped(stack)
    texts = [e.text for e in stack.events.all()]
    assert any(e.code == "obstacle" for e in stack.events.all()), texts          # warned about
    assert "Arrived at fridge" in texts


def still_since(stack, mark: int, samples: int = 10) -> bool:
    """Once `samples` truths came after `mark`: the robot moved less than 5 mm and 0.5 deg."""
    wait_until(lambda: len(stack.truth.since(mark)) >= samples, 5)
    t = stack.truth.since(mark)
    return max(np.ptp(t[:, 0]), np.ptp(t[:, 1])) < 0.005 and np.ptp(np.unwrap(t[:, 2])) < 0.01


def test_a_goal_inside_a_wall_is_refused_with_a_sentence(stack):
    wait_until(lambda: standing_still(stack), 5, interval=0.05)
    mark = stack.truth.mark()
    before = stack.base.status()
    with pytest.raises(RpcError) as err:
        stack.base.goto((5.0, 2.0, 0.0))          # the kitchen wall
    assert err.value.code == "unreachable" and "inside an obstacle" in err.value.message
    for bad, words in ((dict(place="../../etc/passwd"), "no place called"),
                       (dict(pose=[math.nan, 1.0, 0.0]), "finite"),
                       (dict(pose=[50.0, 1.0, 0.0]), "outside the map"),
                       (dict(place="fridge", pose=[1, 1, 0]), "not both"),
                       (dict(where="fridge"), "takes only")):
        with pytest.raises(RpcError, match=words):
            stack.bus.call(keys.nav_rpc(ROBOT, "goto"), bad, timeout=5)
    after = stack.base.status()
    assert (after["goal_id"], after["state"]) == (before["goal_id"], before["state"])
    assert still_since(stack, mark)


def test_a_new_goal_preempts_and_cancel_stops(stack):
    first = stack.base.goto("desk")
    wait_until(lambda: not standing_still(stack), 10, interval=0.1,
               message=lambda: f"the robot never started\n{where(stack)}")
    second = stack.base.goto("charging station")
    with pytest.raises(RpcError, match="replaced by a new goal") as err:
        stack.base.wait(first, timeout=5)
    assert err.value.code == "busy"
    wait_until(lambda: not standing_still(stack), 10, interval=0.1)
    stack.base.cancel()
    with pytest.raises(RpcError, match="canceled"):
        stack.base.wait(second, timeout=5)
    wait_until(lambda: standing_still(stack), 3, interval=0.05, message="the robot did not stop on cancel")


@pytest.mark.timeout(300)
def test_the_shelf_is_reached_round_the_sofa(stack):
    """The living room's way, round the sofa and the coffee table. Every named place is reached
    by the navigator itself (tests/nav/test_navigator.py); the fridge by the tests around this."""
    places = stack.base.places()
    for name in ("shelf",):
        result = reach(stack, stack.base.goto(name))
        assert result["text"] == f"arrived at {name}"
        ok, how = on_goal(stack.truth.pose, places[name])
        assert ok, f"{name}: {how}"
    assert not bumped(stack)


@pytest.mark.timeout(300)
def test_the_command_line_sends_the_robot_and_lists_places(stack):
    def nav(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "asibot.cli.main", "nav", *args], env=stack.env,
                              capture_output=True, text=True, timeout=120)
    out = nav("places")
    assert out.returncode == 0 and "fridge" in out.stdout and "charging station" in out.stdout
    out = nav("goto", "nowhere")
    assert out.returncode == 2 and "I know no place called 'nowhere'" in out.stderr
    out = nav("save-place", "by the station")
    assert out.returncode == 0, out.stderr
    out = nav("turn", "180")          # the station faces the wall
    assert out.returncode == 0 and "turn left: done" in out.stdout, out.stdout + out.stderr
    out = nav("drive", "0.5")
    assert out.returncode == 0 and "forward: done" in out.stdout, f"{out.stdout}{out.stderr}{where(stack)}"
    out = nav("goto", "by the station")
    assert out.returncode == 0 and "arrived at by the station" in out.stdout, out.stdout + out.stderr
    assert "by the station" in stack.base.places()
    stack.base.remove_place("by the station")


def test_estop_ends_a_goal_and_nothing_resumes(stack):
    client_bus = stack.base._connected()
    gid = stack.base.goto("fridge")
    wait_until(lambda: not standing_still(stack), 10, interval=0.1)
    stack.base.estop("test")
    with pytest.raises(RpcError, match="emergency stop") as err:
        stack.base.wait(gid, timeout=5)
    assert err.value.code == "estop"
    wait_until(lambda: standing_still(stack), 3, interval=0.05, message="the robot did not stop on the estop")
    with pytest.raises(RpcError, match="release it") as err:
        stack.base.goto("fridge")
    assert err.value.code == "estop"
    mark = stack.truth.mark()
    stack.base.release("test")
    assert stack.base.status()["state"] == "canceled"
    assert still_since(stack, mark, samples=20)       # a second after the release: nothing resumed
    assert client_bus is stack.base._connected()


def test_a_person_at_a_joystick_takes_the_base_from_a_goal_and_nav_drives_again_after(stack):
    """twist_mux's rule: a joystick program (a TELEOP controller) overtakes nav's goal with its
    first command; nav ends the goal with a sentence and refuses new ones while the person
    drives; once the joystick has been quiet for TAKEOVER_HOLD, nav drives again."""
    with Bus("a-joystick-program") as bus:
        joystick = ownership.announce(bus, ROBOT, "base", "joystick")
        to_base = bus.publisher(keys.base_cmd_vel(ROBOT), m.Twist)
        gid = stack.base.goto("desk")
        wait_until(lambda: not standing_still(stack), 10, interval=0.1, message="nav never set off")
        with Stream(lambda: joystick.put(to_base, m.Twist(vx=0.0, wz=0.4)), period=0.05):
            with pytest.raises(RpcError) as err:
                stack.base.wait(gid, timeout=5)
            assert err.value.code == "busy" and "took over the base (driven by hand)" in err.value.message
            # The event comes on its own key: it may arrive after the goal's answer (seen in CI).
            ended = wait_until(lambda: [e.text for e in stack.events.all() if "took over the base" in e.text], 5,
                               interval=0.05, message=lambda: f"no event said the goal ended; events: {stack.events.all()}")
            assert ended[-1].startswith("Stopped: joystick-"), ended
            # the sim obeys the joystick: a turn on the spot, not nav's way to the desk
            mark = stack.truth.mark()
            wait_until(lambda: len(stack.truth.since(mark)) > 30, 5)
            turned = stack.truth.since(mark)
            assert np.ptp(np.unwrap(turned[:, 2])) > 0.3 and max(np.ptp(turned[:, 0]), np.ptp(turned[:, 1])) < 0.1
            with pytest.raises(RpcError, match="by hand") as err:
                stack.base.goto("desk")
            assert err.value.code == "busy"
        wait_until(lambda: standing_still(stack), 5, interval=0.05, message="the base went on after the joystick let go")

        def accepted() -> int | None:
            try:
                return stack.base.goto("desk")
            except RpcError as exc:
                assert exc.code == "busy", exc
                return None
        again = wait_until(accepted, ownership.TAKEOVER_HOLD + 8, interval=0.5, message="nav never drove again")
        wait_until(lambda: not standing_still(stack), 10, interval=0.1, message="nav's new goal did not move the base")
        stack.base.cancel(again)
        wait_until(lambda: standing_still(stack), 5, interval=0.05)


@pytest.mark.timeout(400)
def test_a_kidnapped_robot_finds_itself_again(stack):
    office = (7.5, 6.0)
    # The robot has been in use: it drove (the tests before this one) and knows how well the
    # scans fit where it is; a turn where it stands refreshes that. (Carried off before its first
    # drive, its filter has only the start's wide cloud to compare with.)
    stack.base.turn(180)
    stack.base.wait(timeout=30)
    stack.bus.call(keys.driver_rpc(ROBOT, "set_robot_pose"), {"pose": [*office, 0.0]}, timeout=5)
    wait_until(lambda: math.dist(stack.truth.pose[:2], office) < 0.05, 5, message="the sim did not teleport the robot")
    assert math.dist(stack.base.pose()[:2], office) > 2.0, "nav knew of the kidnap before it could see"

    def found() -> bool:
        """Right and sure of it: the estimate near the truth and the filter's cluster tight.

        A standing robot's filter does not update (AMCL waits for motion), so a right
        estimate from a still-wide cloud stays unsure until the robot turns again."""
        x, y, _ = stack.base.pose()
        tx, ty, _ = stack.truth.pose
        return math.hypot(x - tx, y - ty) < 0.3 and stack.base.status()["localised"]

    for _ in range(8):      # look around: AMCL updates as the robot turns
        if found():
            break
        stack.base.turn(180)
        stack.base.wait(timeout=30)
    wait_until(found, 10, interval=0.2, message=lambda: f"nav believes {stack.base.pose()} "
               f"(localised: {stack.base.status()['localised']}), the sim says {stack.truth.pose}")
