"""Every request of every verb is checked by one table (issue 10, findings 5 and 6): any
wrong type, size or value is `bad_request` with a short sentence naming the field, never an
`internal` error, never the whole bad value echoed back, and the arm never moves for it."""

from __future__ import annotations

import gc
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from asibot import keys, messages
from asibot.bus import RPC_WORKERS
from asibot.errors import CODES, RpcError
from asibot.kinematics import requests
from asibot.kinematics.controller import NOT_CONTROLLING
from asibot.testing import wait_until

from .conftest import START, quiet

#: Verbs that move the arm when accepted.
MOTION = ("movj", "movl", "movv", "movjv", "relj", "home", "pointer", "jog")
#: Longest sentence a refusal may carry (the bus cuts at 400 characters plus "...").
MAX_REPLY_MESSAGE = 500
#: The reply may take this long at most (act waits for the fingers), s.
CALL_TIMEOUT = 10.0


def call(shared, verb: str, request: dict) -> dict:
    return shared.bus.call(keys.cart_rpc(shared.robot, verb), request, timeout=CALL_TIMEOUT)


def refusal(shared, verb: str, request: dict) -> RpcError:
    with pytest.raises(RpcError) as err:
        call(shared, verb, request)
    return err.value


def test_the_table_covers_every_cart_verb(server):
    assert set(server.verbs) == set(keys.RPC_VERBS_CART)


@pytest.mark.parametrize("verb,request_body,field", [
    # The reproducers: each was `internal` with a Python error.
    ("movl", {"point": [1e300, 0, 1, 0, 0]}, "point"),
    ("movl", {"point": [2**64 - 1, 0, 1, 0, 0]}, "point"),
    ("movj", {"point": [0, 0, 1.0, -1e300, 0]}, "point"),
    ("pointer", {"deadman": True, "direction": {"a": 1}}, "direction"),
    ("pointer", {"deadman": True, "direction": ["forward"]}, "direction"),
    ("act", {"action": np.array([1.0, 2.0])}, "action"),
    ("act", {"action": ["open"]}, "action"),
    ("tool", {"tool": [1e300, 0, 0, 0, 0, 0]}, "tool"),
    ("tool", {"tool": [1e200, 0, 0, 0, 0, 0]}, "tool"),
    ("tool", {"tool": [0, 0, 0, 0, 0, 1e300]}, "tool"),
    # Finite but absurd: refused with the field and its range.
    ("movl", {"point": [0.3, 0, 1.0, 0, 0], "duration": 1e300}, "duration"),
    ("movl", {"point": [0.3, 0, 1.0, 0, 0], "speed": 1e-300}, "speed"),
    ("movj", {"joints": [0, 0, 0, 0, 0], "speed": 1e-300}, "speed"),
    ("movj", {"joints": [0, 0, 0, 0, 0], "duration": 1e300}, "duration"),
    ("movv", {"velocity": [1e300, 0, 0, 0, 0]}, "velocity"),
    ("movjv", {"velocity": [0, 0, 1e300, 0, 0]}, "velocity"),
    ("fwd", {"joints": [1e300, 0, 0, 0, 0]}, "joints"),
    ("relj", {"joints": [0, 0, 0, 0, 2**64 - 1]}, "joints"),
    ("wait", {"timeout": 1e300}, "timeout"),
    ("pointer", {"deadman": True, "yaw": 1e300}, "yaw"),
    ("home", {"speed": -1}, "speed"),
])
def test_wrong_values_are_refused_with_the_field_and_its_range(client, shared, verb, request_body, field):
    err = refusal(shared, verb, request_body)
    assert err.code == "bad_request", err
    assert err.message.startswith(f"'{field}' must be")
    assert shared.server.ctl.state == NOT_CONTROLLING


def test_a_range_refusal_names_the_element_and_the_range(client, shared):
    err = refusal(shared, "movl", {"point": [0.3, 0, 1e300, 0, 0]})
    assert "z = 1e+300 is outside [-1e+06, 1e+06] m" in err.message
    err = refusal(shared, "movl", {"point": [0.3, 0, 1.0, 0, 0], "duration": 1e300})
    assert "(0, 600] s" in err.message


def test_unknown_fields_are_refused_but_a_stop_always_stops(client, shared):
    err = refusal(shared, "movl", {"point": [0.3, 0, 1.0, 0, 0], "sped": 0.1})
    assert err.code == "bad_request" and "'sped' is not one of them" in err.message
    client.movj(joints=[30, 0, 0, 0, 0], duration=4.0)
    assert call(shared, "stop", {"why": ["anything", 1e300]}) == {"ok": True}
    assert shared.server.ctl.state == NOT_CONTROLLING


def test_a_value_nested_too_deep_to_show_is_refused(client, shared):
    deep: list = []
    for _ in range(1000):
        deep = [deep]
    err = refusal(shared, "movl", {"point": deep})
    assert err.code == "bad_request" and "too deep" in err.message


def test_a_numeric_array_is_a_list_of_numbers(client, shared):
    assert call(shared, "fwd", {"joints": np.zeros(5)})["point"] == pytest.approx([0, 0, 1.4, 0, 0])
    assert refusal(shared, "fwd", {"joints": np.zeros((5, 1))}).code == "bad_request"


# --- the fuzzer -----------------------------------------------------------------------
FIELDS = sorted({name for verb in requests.verbs(5).values() for name in verb.fields})
WORDS = ["open", "close", "forward", "hold", "backward", "point", "", "nan"]
scalars = st.one_of(
    st.none(), st.booleans(),
    st.integers(min_value=-2**63, max_value=2**64 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([1e300, -1e300, 1e-300, 1e200, 2**64 - 1, -2**63, 0, 1, -1, 0.5, 0.05, 3.0]),
    st.text(max_size=12), st.sampled_from(WORDS), st.binary(max_size=12),
)
arrays = st.one_of(st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=7).map(np.array),
                   st.lists(st.booleans(), max_size=7).map(np.array),
                   st.lists(st.integers(-10, 10), min_size=1, max_size=12).map(lambda v: np.array(v).reshape(-1, 1)))
values = st.recursive(
    st.one_of(scalars, arrays),
    lambda inner: st.lists(inner, max_size=7)
    | st.dictionaries(st.one_of(st.text(max_size=6), st.integers(-5, 5)), inner, max_size=4),
    max_leaves=16)
#: Numbers plausible and not, and lists of them of about the sizes verbs expect.
numbers = st.one_of(st.floats(-2, 2), st.floats(-400, 400), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(min_value=-2**63, max_value=2**64 - 1),
                    st.sampled_from([1e300, -1e300, 1e-300, 1e200, 2**64 - 1, 0, 1e5, 0.5]))
vectors = st.sampled_from([5, 5, 6, 6, 4, 7]).flatmap(
    lambda n: st.one_of(st.lists(numbers, min_size=n, max_size=n),
                        st.lists(st.one_of(numbers, scalars), min_size=n, max_size=n)))
field_names = st.one_of(st.sampled_from(FIELDS), st.text(max_size=8), st.integers(-5, 5))
anything = st.one_of(vectors, vectors, numbers, st.sampled_from(WORDS), st.booleans(), values)


def shaped(check):
    """Values of the shape a validator expects, with numbers of any size in them."""
    if isinstance(check, requests.Numbers):
        return st.lists(numbers, min_size=len(check.names), max_size=len(check.names))
    if isinstance(check, requests.Number):
        return numbers
    if isinstance(check, requests.OneOf):
        return st.sampled_from(check.choices)
    if isinstance(check, requests.Whole):
        return st.integers(check.lo - 1, check.hi + 1)
    return st.booleans()


def fuzzed_requests(verb: str):
    """Maps of the verb's own fields with values of about their shape or anything, and maps
    of arbitrary names and values."""
    fields = requests.verbs(5)[verb].fields
    own = st.fixed_dictionaries({}, optional={name: st.one_of(shaped(f.check), shaped(f.check), anything)
                                              for name, f in fields.items()})
    names = st.one_of(st.sampled_from(sorted(fields) or FIELDS), field_names)
    return st.one_of(own, own, st.dictionaries(names, anything, max_size=4))


@pytest.fixture
def counted(client, shared):
    """The server's count of arm commands; the tool, object and controller reset after."""
    try:
        yield shared.server.cmd_pub
    finally:
        shared.server.model.set_tool(None)
        shared.driver.object_width = None
        quiet(shared)


def test_fuzzed_requests_get_ok_or_a_sentence_and_refusals_move_nothing(shared, counted):
    seen: dict[str, int] = {}

    @settings(derandomize=True, max_examples=400, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(data=st.data())
    def fuzz(data) -> None:
        verb = data.draw(st.sampled_from(sorted(keys.RPC_VERBS_CART)), label="verb")
        request = data.draw(fuzzed_requests(verb), label="request")
        ctl = shared.server.ctl
        assert ctl.state == NOT_CONTROLLING
        before = counted.count
        try:
            call(shared, verb, request)
        except RpcError as exc:
            seen[exc.code] = seen.get(exc.code, 0) + 1
            assert exc.code in CODES and exc.code != "internal", (verb, exc)
            assert len(exc.message) < MAX_REPLY_MESSAGE, (verb, len(exc.message))
            assert exc.code != "timeout", (verb, exc)
            assert ctl.state == NOT_CONTROLLING and counted.count == before, (verb, "moved on a refusal")
        else:
            seen["ok"] = seen.get("ok", 0) + 1
            if verb in MOTION or verb == "stop":
                quiet(shared)
                shared.driver.set_joints(START)
                wait_until(lambda: np.allclose(ctl.q, START, atol=1e-9), timeout=2.0)

    fuzz()
    assert seen.get("bad_request", 0) > 100 and seen.get("ok", 0) > 5, seen


# --- memory ---------------------------------------------------------------------------
def refused(shared, verb: str, body: dict) -> tuple[str, str]:
    """The refusal's code and sentence only: the exception's frames hold our own request."""
    try:
        call(shared, verb, body)
    except RpcError as exc:
        return exc.code, exc.message
    return "ok", ""


def test_memory_stays_flat_after_big_bad_points(client, shared):
    """Requests of about 800 KB (just under the bus's 1 MiB request limit): each is refused
    with a short sentence, and nothing of them stays. Allocations made by the kinematics
    service's code are followed to the line; the process as a whole may keep the last
    request of each of the bus's RPC worker threads (a worker's local until its next
    request), never one per request."""
    big = [0.123456789] * 88_000   # ~790 KB of msgpack floats
    text, blob = "x" * 800_000, b"\0" * 800_000
    bodies = [("movl", {"point": big}), ("movj", {"joints": text}), ("tool", {"tool": blob}),
              ("movv", {"velocity": [0, 0, 0, 0, text]}), ("movl", {"point": [0.3, 0, 1.0, 0, big]}),
              ("pointer", {"deadman": True, "yaw": blob}), ("act", {"action": text}), ("wait", {text: 1})]
    for verb, body in bodies:      # warm every path once
        assert refused(shared, verb, body)[0] == "bad_request"
    gc.collect()
    tracemalloc.start(12)
    try:
        before = tracemalloc.take_snapshot()
        for verb, body in bodies:
            code, message = refused(shared, verb, body)
            assert code == "bad_request" and len(message) < MAX_REPLY_MESSAGE, (verb, code, message)
        gc.collect()
        ours = tracemalloc.Filter(True, "*/services/kinematics/*", all_frames=True)
        growth = tracemalloc.take_snapshot().filter_traces([ours]).compare_to(
            before.filter_traces([ours]), "filename")
        # One key, many requests: at most one kept per worker thread, whatever their number.
        base = tracemalloc.get_traced_memory()[0]
        for _ in range(3 * RPC_WORKERS):
            assert refused(shared, "inv", {"point": text})[0] == "bad_request"
        gc.collect()
        kept = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    server_kept = sum(stat.size_diff for stat in growth)
    assert server_kept < 64 * 1024, f"the kinematics service kept {server_kept / 1024:.0f} KiB: {growth[:3]}"
    payload = len(messages.pack({"point": text}))
    assert kept < RPC_WORKERS * payload + 256 * 1024, \
        f"{kept / 1024:.0f} KiB kept after {3 * RPC_WORKERS} requests of {payload / 1024:.0f} KiB"
