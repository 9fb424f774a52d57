"""asibot.safety.arming: after a recovery, only a stream that began after it moves the robot."""

from asibot.safety.arming import Arming, NotReady

W = 0.2   # the watchdog period of these tests


def stream(arming: Arming, sender: str, start: float, end: float, period: float = 0.05) -> list[bool]:
    """What `admit` answers to a stream of `sender` from `start` to `end`."""
    n = int(round((end - start) / period))
    return [arming.admit(sender, start + i * period) for i in range(n + 1)]


def test_a_driver_starts_armed_and_a_stream_through_a_recovery_waits_for_a_pause():
    a = Arming(watchdog=W)
    assert all(stream(a, "k", 0.0, 1.0))            # armed from the start: no stream before it is known
    a.disarm("the emergency stop was released")
    assert not any(stream(a, "k", 1.05, 2.0))       # the same stream goes on: nothing moves
    assert not a.admit("k", 2.0 + W * 0.9)          # a pause shorter than a watchdog period
    assert a.admit("k", 2.0 + W * 0.9 + W)          # a pause of one: a new request arms
    assert a.armed and a.admit("k", 2.0 + W * 2)


def test_a_sender_never_heard_begins_a_new_stream_but_a_heard_one_does_not():
    a = Arming(watchdog=W)
    for i in range(10):                             # the next holder's stream, refused meanwhile
        a.heard("b", i * 0.05)
    a.disarm("controller 'b' took hold of it")
    assert not a.admit("b", 0.5)                    # b's stream from before does not move it
    a.disarm("controller 'c' took hold of it")
    assert a.admit("c", 0.55)                       # a controller that was silent moves it at once


def test_a_restarted_controller_counts_its_start_as_a_running_stream():
    a = Arming(since=10.0, watchdog=W)
    assert not a.armed and not a.admit("stream", 10.05)   # within a watchdog period of the start
    assert not a.admit("stream", 10.1)
    assert a.admit("stream", 10.4)                        # after a pause


def test_the_sentences_say_what_happened_and_what_to_do():
    a = Arming(watchdog=W)
    a.disarm("the fault was reset")
    refusal = a.refusal("the arm")
    assert isinstance(refusal, NotReady) and refusal.reason == "not_ready" and refusal.level == "warning"
    assert str(refusal) == ("the arm was re-armed after the fault was reset, and this command continues a stream "
                            "that was running before; pause it for 200 ms (or restart it) to move the arm again")
    assert a.ready_text("The arm").startswith("The arm is ready again after the fault was reset: it moves on "
                                              "the next motion request")


def test_memory_stays_bounded_with_many_senders():
    a = Arming(watchdog=W)
    for i in range(1000):
        a.heard(f"s{i}", i * 0.001)
    assert len(a._last) <= 64
