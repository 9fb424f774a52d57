"""The bus's semantics, the same on both backends: Zenoh through a real router, and memory.

The multi-process behaviour (kills, router restarts) is in test_bus.py; here every test runs
twice, so the in-memory bus that service unit tests use is held to what Zenoh does.
"""

import threading
import time

import msgpack
import pytest

from asibot import keys, messages as m
from asibot.bus import Bus
from asibot.bus.memory import intersects
from asibot.errors import RpcError
from asibot.testing import wait_until


@pytest.fixture
def pair(endpoint):
    """Two services on the same bus."""
    a, b = Bus("a", endpoint), Bus("b", endpoint)
    yield a, b
    a.close()
    b.close()


def test_the_endpoint_chooses_the_backend(endpoint):
    with Bus("x", endpoint) as bus:
        assert isinstance(bus, Bus)
        assert type(bus).__name__ == ("MemoryBus" if endpoint.startswith("mem://") else "ZenohBus")


def test_messages_arrive_in_order_and_wildcards_carry_the_key(pair):
    a, b = pair
    got, keyed = [], []
    b.subscribe(keys.arm_state("r1"), m.ArmState, got.append)
    b.subscribe("rb/*/arm/state", m.ArmState, lambda k, msg: keyed.append(k), with_key=True)
    pub = a.publisher(keys.arm_state("r1"), m.ArmState)
    assert pub.wait_for_subscribers(5)
    for i in range(50):
        pub.put(m.ArmState(names=["q1"], positions=[float(i)], velocities=[0.0]))
    wait_until(lambda: len(got) == 50 and len(keyed) == 50, 5)
    assert [g.positions[0] for g in got] == list(range(50))
    assert set(keyed) == {keys.arm_state("r1")}


def test_bad_messages_are_counted_and_handed_to_on_reject(pair):
    a, b = pair
    got, refused = [], []
    key = keys.base_cmd_vel("r2")
    b.subscribe(key, m.Twist, got.append, on_reject=lambda k, exc: refused.append((k, str(exc))))
    pub = a.publisher(key, m.Twist)
    assert pub.wait_for_subscribers(5)
    for payload in (b"\xc1", msgpack.packb({"vx": "fast", "wz": 0.0}), msgpack.packb([1, 2])):
        a.put_raw(key, payload)
    pub.put(m.Twist(vx=0.1, wz=0.0))
    wait_until(lambda: got and len(refused) == 3, 5)
    assert b.rejected == 3 and all(k == key for k, _ in refused)
    assert "Twist.vx" in refused[1][1]


def test_a_failing_callback_does_not_end_the_subscription(pair):
    a, b = pair
    got = []

    def callback(msg):
        got.append(msg)
        raise RuntimeError("a bug in a service")
    b.subscribe(keys.base_battery("r3"), m.Battery, callback)
    pub = a.publisher(keys.base_battery("r3"), m.Battery)
    assert pub.wait_for_subscribers(5)
    pub.put(m.Battery(volts=12.0))
    pub.put(m.Battery(volts=11.0))
    wait_until(lambda: len(got) == 2, 5)


def test_rpc_replies_are_built_by_the_bus(pair):
    a, b = pair
    key = keys.cart_rpc("r4", "stat")

    def handler(req):
        if req.get("refuse"):
            raise RpcError("joint_limit", "Joint 2 would pass its limit of 135 degrees.")
        if req.get("crash"):
            return 1 / 0
        if req.get("nothing"):
            return None
        if req.get("not_a_dict"):
            return [1, 2]
        return {"echo": req}
    b.serve(key, handler)
    assert a.wait_for(key, 5)
    assert a.call(key, {"x": 1}) == {"ok": True, "echo": {"x": 1}}
    assert a.call(key, {"nothing": True}) == {"ok": True}
    with pytest.raises(RpcError) as err:
        a.call(key, {"refuse": True})
    assert err.value.code == "joint_limit" and "135 degrees" in err.value.message
    for bad in ({"crash": True}, {"not_a_dict": True}):
        with pytest.raises(RpcError) as err:
            a.call(key, bad)
        assert err.value.code == "internal"
    assert a.call(key, {})["ok"], "the server survives its own bugs"


def test_a_request_that_is_not_a_map_is_a_bad_request(pair):
    a, b = pair
    key = keys.cart_rpc("r5", "stat")
    b.serve(key, lambda req: {})
    assert a.wait_for(key, 5)
    answers = a._get(key, msgpack.packb([1, 2]), 2.0)
    reply = msgpack.unpackb(answers[0][1])
    assert reply["ok"] is False and reply["error"] == "bad_request"


def test_rpc_timeout_and_nobody_home(pair):
    a, b = pair
    key = keys.cart_rpc("r6", "wait")
    assert not a.wait_for(key, 0.1)
    b.serve(key, lambda req: time.sleep(req["sleep"]) or {})
    assert a.wait_for(key, 5)
    with pytest.raises(RpcError) as err:
        a.call(key, {"sleep": 1.0}, timeout=0.2)
    assert err.value.code == "timeout"
    with pytest.raises(RpcError) as err:
        a.call(keys.cart_rpc("nobody", "stat"), timeout=2)
    assert err.value.code == "unavailable"


def test_a_wildcard_server_answers_in_the_concrete_name(pair):
    a, b = pair
    b.serve("rb/*/cart/rpc/stat", lambda req: {"hello": True})
    assert a.wait_for(keys.cart_rpc("r7", "stat"), 5)
    answers = a._get(keys.cart_rpc("r7", "stat"), msgpack.packb({}), 2.0)
    assert answers[0][0] == keys.cart_rpc("r7", "stat")


def test_latched_values_reach_late_joiners_and_the_newest_wins(endpoint):
    with Bus("web", endpoint) as web, Bus("panel", endpoint) as panel, Bus("late", endpoint) as late:
        web.latch(keys.estop("r8"), m.EStop(engaged=True, reason="web"))
        time.sleep(0.01)
        # Plain latches: the bus's own rule (the newest stamp wins), not the estop's
        # (asibot.safety.estop), whose followers would keep their own copies.
        panel.latch(keys.estop("r8"), m.EStop(engaged=False, reason="released at the panel"))
        wait_until(lambda: len([x for x in late._get(keys.estop("r8"), b"", 0.5) if x]) == 2, 3)
        got = []
        late.subscribe(keys.estop("r8"), m.EStop, got.append, latest=True)
        wait_until(lambda: got, 3)
        assert got[0].reason == "released at the panel"
        panel.latch(keys.estop("r8"), m.EStop(engaged=True, reason="again"))
        wait_until(lambda: got[-1].reason == "again", 3)


def test_liveliness_appears_and_vanishes_with_its_bus(endpoint):
    with Bus("watcher", endpoint) as watcher:
        changes = []
        svc = Bus("svc", endpoint)
        svc.announce(keys.service("demo", "one"))
        watcher.watch(keys.ALL_SERVICES, lambda k, alive: changes.append((k, alive)))
        wait_until(lambda: (keys.service("demo", "one"), True) in changes, 3)
        # a snapshot is a query with its own timeout: on a loaded machine one may come back empty
        wait_until(lambda: keys.service("demo", "one") in watcher.alive(), 5)
        svc.close()
        wait_until(lambda: (keys.service("demo", "one"), False) in changes, 3)
        wait_until(lambda: keys.service("demo", "one") not in watcher.alive(), 3)


def test_a_slow_subscription_keeps_the_newest_and_never_holds_up_the_sender(endpoint):
    with Bus("cam", endpoint) as cam, Bus("slow", endpoint) as slow:
        release = threading.Event()
        got = []

        def callback(msg):
            release.wait(5)
            got.append(msg.volts)
        slow.subscribe(keys.base_battery("r9"), m.Battery, callback, maxsize=2)
        pub = cam.publisher(keys.base_battery("r9"), m.Battery, block=True)
        assert pub.wait_for_subscribers(5)
        sent = threading.Thread(target=lambda: [pub.put(m.Battery(volts=float(v))) for v in range(100)])
        sent.start()
        sent.join(5)
        assert not sent.is_alive(), "a slow subscription held up the sender"
        time.sleep(0.5)  # let every sample reach the subscription before the callback wakes up
        release.set()
        wait_until(lambda: got and got[-1] == 99.0, 5)
        assert len(got) <= 1 + 2, f"kept more than the newest 2: {got}"


@pytest.mark.parametrize("a, b, meet", [
    ("rb/r1/arm/state", "rb/r1/arm/state", True),
    ("rb/*/arm/state", "rb/r1/arm/state", True),
    ("rb/**", "rb/r1/arm/state", True),
    ("**", "rb/r1", True),
    ("rb/**/state", "rb/r1/arm/state", True),
    ("rb/**/state", "rb/state", True),
    ("rb/*/arm/state", "rb/r1/base/odom", False),
    ("rb/*", "rb/r1/arm", False),
    ("svc/**", "rb/r1/arm", False),
    ("rb/*/arm/**", "rb/**/state", True),
])
def test_key_expressions_intersect_like_zenohs(a, b, meet):
    assert intersects(a, b) is meet and intersects(b, a) is meet


def test_a_memory_endpoint_must_name_its_network():
    with pytest.raises(ValueError, match="mem://NAME"):
        Bus("x", "mem://")


def test_huge_requests_and_huge_refusals_stay_small(pair):
    a, b = pair
    key = keys.cart_rpc("r10", "movl")
    calls = []

    def handler(req):
        calls.append(1)
        raise RpcError("bad_request", f"'point' must be 5 numbers; got {req['point']!r}.")
    b.serve(key, handler)
    assert a.wait_for(key, 5)
    with pytest.raises(RpcError) as err:
        a.call(key, {"point": [1.0] * 400_000}, timeout=5)  # 3.6 MB
    assert err.value.code == "bad_request" and "limited to" in err.value.message and not calls
    with pytest.raises(RpcError) as err:
        a.call(key, {"point": [1.0] * 50_000}, timeout=5)  # under the limit, echoed by the handler
    assert calls and len(err.value.message) < 500


def test_every_bus_of_a_memory_bus_block_joins_its_own_network():
    """`testing.memory_bus(NAME)` isolates a test: a Bus() without an endpoint joins mem://NAME
    (it joined mem://default, shared by every test, so a declaration one test left behind
    answered in the next)."""
    from asibot import testing
    with testing.memory_bus("isolated-1"):
        with Bus("a") as a:
            assert a.endpoint == "mem://isolated-1"
            a.announce(keys.driver_alive("r11"))
            with testing.memory_bus("isolated-2"), Bus("b") as b:
                assert b.endpoint == "mem://isolated-2" and b.alive(keys.ALL_DRIVERS) == []
